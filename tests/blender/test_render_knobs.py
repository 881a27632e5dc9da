"""[render] speed knobs: defaults leave Blender's factory Cycles settings (= old renders) untouched,
every knob reaches its Cycles property, persistent data gives fresh textures, GPU selection order."""
from __future__ import annotations

import dataclasses
import logging
from types import SimpleNamespace

import numpy as np
import pytest

bpy = pytest.importorskip("bpy")

from crackgen.blender import render as brender  # noqa: E402
from crackgen.blender.render import RenderSettings, apply_settings, configure_scene  # noqa: E402
from crackgen.blender.scene import LiveScene, SceneUpdateError  # noqa: E402
from crackgen.config.recipe import Recipe  # noqa: E402
from crackgen.config.spec import RENDER_KNOBS, make_spec  # noqa: E402
from crackgen.datagen.heap import heap_info  # noqa: E402
from crackgen.procedural.crackmap import crack_map  # noqa: E402
from crackgen.procedural.materials import material_maps  # noqa: E402
from crackgen.procedural.surface import surface_vertices  # noqa: E402
from crackgen.sim.rig import make_rig  # noqa: E402

pytestmark = pytest.mark.blender

# knob -> Cycles property it sets (persistent_data is a render property, set at build)
CYCLES_PROPERTY = {
    "adaptive_sampling": "use_adaptive_sampling", "adaptive_threshold": "adaptive_threshold",
    "adaptive_min_samples": "adaptive_min_samples", "denoise_prefilter": "denoising_prefilter",
    "denoise_passes": "denoising_input_passes", "denoise_quality": "denoising_quality",
    "diffuse_bounces": "diffuse_bounces", "glossy_bounces": "glossy_bounces",
    "transmission_bounces": "transmission_bounces", "transparent_bounces": "transparent_max_bounces",
    "caustics_reflective": "caustics_reflective", "caustics_refractive": "caustics_refractive",
    "light_tree": "use_light_tree", "fast_gi": "use_fast_gi", "ao_bounces": "ao_bounces_render",
    "clamp_direct": "sample_clamp_direct", "clamp_indirect": "sample_clamp_indirect",
}
NON_DEFAULT = {
    "adaptive_sampling": False, "adaptive_threshold": 0.05, "adaptive_min_samples": 4, "denoise_prefilter": "fast",
    "denoise_passes": "rgb_albedo", "denoise_quality": "balanced", "diffuse_bounces": 2, "glossy_bounces": 1,
    "transmission_bounces": 0, "transparent_bounces": 2, "caustics_reflective": False, "caustics_refractive": False,
    "light_tree": False, "fast_gi": True, "ao_bounces": 2, "clamp_direct": 5.0, "clamp_indirect": 3.0,
}


def _cycles_values(scene) -> dict:
    return {p: getattr(scene.cycles, p) for p in CYCLES_PROPERTY.values()}


def test_every_knob_has_a_cycles_property_and_a_test_value():
    assert set(CYCLES_PROPERTY) | {"persistent_data"} == set(RENDER_KNOBS)
    assert set(NON_DEFAULT) == set(CYCLES_PROPERTY)


def test_default_knobs_leave_the_factory_cycles_settings_unchanged():
    """Before the knobs existed the code never wrote these properties: renders used the factory values."""
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    configure_scene(scene, 32, 24)
    factory = _cycles_values(scene)
    spec = make_spec(Recipe(), 0)
    apply_settings(scene, RenderSettings.from_spec(spec.render, 1.5))
    assert _cycles_values(scene) == factory
    assert scene.render.use_persistent_data is False
    apply_settings(scene, RenderSettings())
    assert _cycles_values(scene) == factory


def test_every_knob_reaches_its_cycles_property():
    bpy.ops.wm.read_factory_settings(use_empty=True)
    scene = bpy.context.scene
    configure_scene(scene, 32, 24)
    before = _cycles_values(scene)
    apply_settings(scene, RenderSettings(**NON_DEFAULT))
    after = _cycles_values(scene)
    for knob, prop in CYCLES_PROPERTY.items():
        want = NON_DEFAULT[knob]
        if isinstance(want, str):
            want = want.upper()
        assert after[prop] == pytest.approx(want), knob
        assert after[prop] != before[prop], knob


@pytest.mark.parametrize("field,value", [("denoise_prefilter", "slow"), ("denoise_passes", "albedo"),
                                         ("diffuse_bounces", -1), ("clamp_indirect", -2.0)])
def test_bad_knob_values_are_refused_with_the_field_name(field, value):
    bpy.ops.wm.read_factory_settings(use_empty=True)
    with pytest.raises(brender.RenderError, match=f"render.{field}"):
        apply_settings(bpy.context.scene, RenderSettings(**{field: value}))


# ---- persistent data: textures must change between samples --------------------------------------
GRID, TEX, W, H = 24, 32, 32, 24


def _recipe(persistent: bool) -> Recipe:
    return Recipe.model_validate({
        "camera": {"width_px": W, "height_px": H, "distance_m": 0.8, "tilt_deg": 0},
        "surface": {"size_m": 1.5, "grid_px": GRID, "crackmap_px": 64},
        "material": {"texture_px": TEX, "family": "concrete"},
        "render": {"samples": 2, "denoise": False, "threads": 1, "max_bounces": 1, "persistent_data": persistent},
        "lights": {"kind": "sun", "count": 1},
        "shadow": {"probability": 1.0},
    })


def _renders(persistent: bool) -> list[np.ndarray]:
    """Two samples of one scene: same geometry and camera, albedo scaled x1 then x0.25 (and a new shadow)."""
    recipe = _recipe(persistent)
    live = LiveScene(GRID, TEX, W, H, threads=1, samples=2, denoise=False, max_bounces=1, max_lights=2,
                     shadow_px=32, persistent_data=persistent)
    spec = make_spec(recipe, 0)
    cm = crack_map(spec.crack, 64, spec.surface.size_m, measure=False)
    verts, maps, rig = surface_vertices(cm, GRID), material_maps(spec.material, cm), make_rig(spec)
    rng = np.random.default_rng(0)
    out = []
    try:
        for scale in (1.0, 0.25):
            dark = dataclasses.replace(maps, albedo=(maps.albedo * scale).astype(np.float32))
            live.update(spec, rig, verts, dark, rng.random((32, 32), dtype=np.float32))
            out.append(live.render(linear=True).rgb_linear)
    finally:
        live.close()
    return out


def test_persistent_data_renders_fresh_textures_equal_to_non_persistent():
    on = _renders(True)
    off = _renders(False)
    assert on[1].mean() < 0.6 * on[0].mean()  # the darker albedo shows up: pixels are not stale
    for a, b in zip(on, off):
        np.testing.assert_allclose(a, b, atol=1e-5)


def test_persistent_data_mismatch_between_spec_and_scene_is_refused():
    live = LiveScene(GRID, TEX, W, H, threads=1, samples=1, denoise=False, max_lights=2, shadow_px=32)
    spec = make_spec(_recipe(True), 0)
    cm = crack_map(spec.crack, 64, spec.surface.size_m, measure=False)
    try:
        with pytest.raises(SceneUpdateError, match="persistent_data"):
            live.update(spec, make_rig(spec), surface_vertices(cm, GRID), material_maps(spec.material, cm), None)
    finally:
        live.close()


def test_persistent_scene_keeps_datablock_counts_flat():
    live = LiveScene(GRID, TEX, W, H, threads=1, samples=1, denoise=False, max_lights=2, shadow_px=32,
                     persistent_data=True)
    spec = make_spec(_recipe(True), 0)
    cm = crack_map(spec.crack, 64, spec.surface.size_m, measure=False)
    args = (spec, make_rig(spec), surface_vertices(cm, GRID), material_maps(spec.material, cm), np.ones((32, 32), np.float32))
    try:
        live.update(*args)
        counts = live.datablock_counts()
        for _ in range(5):
            live.update(*args)
        assert live.datablock_counts() == counts
        assert counts["images"] == 8  # albedo, roughness, normal, occluder alpha: two each
    finally:
        live.close()


# ---- GPU selection with a mocked Cycles device list ----------------------------------------------
class _Prefs:
    """Cycles add-on preferences: compute_device_type is an enum (TypeError for a type this build lacks)."""

    def __init__(self, devices: list[tuple[str, str]], known=("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL")):
        self._all = [SimpleNamespace(type=t, name=n, use=False) for t, n in devices]
        self._known = known
        self.devices = []
        self._type = "NONE"
        self.refreshed = 0

    @property
    def compute_device_type(self):
        return self._type

    @compute_device_type.setter
    def compute_device_type(self, value):
        if value not in self._known:
            raise TypeError(f"enum {value!r} not found")
        self._type = value

    def get_devices(self):
        self.refreshed += 1
        self.devices = list(self._all)


def _mock_bpy(monkeypatch, prefs):
    fake = SimpleNamespace(context=SimpleNamespace(preferences=SimpleNamespace(addons={"cycles": SimpleNamespace(preferences=prefs)})))
    monkeypatch.setattr(brender, "bpy", fake)
    monkeypatch.setattr(brender, "_GPU_WARNED", False)
    return SimpleNamespace(cycles=SimpleNamespace(device="CPU"))


@pytest.mark.parametrize("devices,kind", [
    ([("CPU", "cpu"), ("CUDA", "RTX A"), ("OPTIX", "RTX A")], "OPTIX"),  # both: OptiX first
    ([("CPU", "cpu"), ("CUDA", "GTX B")], "CUDA"),  # no OptiX device: CUDA
])
def test_gpu_device_prefers_optix_then_cuda(monkeypatch, devices, kind):
    prefs = _Prefs(devices)
    scene = _mock_bpy(monkeypatch, prefs)
    assert brender.select_device(scene, "gpu") == "gpu"
    assert scene.cycles.device == "GPU"
    assert prefs.compute_device_type == kind
    assert [d.type for d in prefs.devices if d.use] == [kind]


def test_gpu_device_skips_types_this_build_lacks(monkeypatch):
    prefs = _Prefs([("CPU", "cpu"), ("CUDA", "GTX B")], known=("CUDA", "HIP"))  # a build without OptiX
    scene = _mock_bpy(monkeypatch, prefs)
    assert brender.select_device(scene, "gpu") == "gpu"
    assert prefs.compute_device_type == "CUDA"


def test_gpu_without_devices_falls_back_to_cpu_with_one_warning(monkeypatch, caplog):
    scene = _mock_bpy(monkeypatch, _Prefs([("CPU", "cpu")]))
    with caplog.at_level(logging.WARNING, logger="crackgen.blender.render"):
        assert brender.select_device(scene, "gpu") == "cpu"
        assert brender.select_device(scene, "gpu") == "cpu"
    assert scene.cycles.device == "CPU"
    assert len(caplog.records) == 1


def test_real_build_behaves_like_the_mock():
    """This bpy knows OptiX and CUDA, refuses an unknown type with TypeError (what the mock does), lists only the CPU."""
    prefs = bpy.context.preferences.addons["cycles"].preferences
    kinds = {t[0] for t in prefs.get_device_types(bpy.context)}
    assert {"OPTIX", "CUDA"} <= kinds
    before = prefs.compute_device_type
    try:
        with pytest.raises(TypeError):
            prefs.compute_device_type = "NO_SUCH_BACKEND"
        prefs.compute_device_type = "OPTIX"
        prefs.get_devices()
        assert all(d.type in ("CPU", "OPTIX") for d in prefs.devices)
    finally:
        prefs.compute_device_type = before


def _malloc_mb() -> float:
    """Bytes the C heap holds in use (arena + mmapped chunks), glibc only."""
    info = heap_info()
    if info is None:
        pytest.skip("needs glibc's mallinfo2")
    return (info["uordblks"] + info["hblkhd"]) / 2**20


@pytest.mark.slow
def test_swapped_images_are_allocated_when_the_scene_is_built():
    """With persistent data the second sample must not allocate the other image set (was +3 x 4 MB at 512 px)."""
    tex = 512  # 4 MB per RGBA float map, well above the heap's noise
    live = LiveScene(GRID, tex, W, H, threads=1, samples=1, denoise=False, max_lights=2, shadow_px=32,
                     persistent_data=True)
    recipe = _recipe(True)
    recipe.material.texture_px = tex
    spec = make_spec(recipe, 0)
    cm = crack_map(spec.crack, 64, spec.surface.size_m, measure=False)
    args = (spec, make_rig(spec), surface_vertices(cm, GRID), material_maps(spec.material, cm), None)
    try:
        live.update(*args)
        after_first = _malloc_mb()
        live.update(*args)  # writes into the other image of every slot
        live.update(*args)
        assert _malloc_mb() - after_first < 2.0
    finally:
        live.close()
