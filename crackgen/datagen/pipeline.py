"""The per-sample pipeline a worker runs: spec -> geometry -> render -> sensors -> members.

One ``SampleProducer`` lives per worker process. It builds the Blender scene the first
time it renders (so importing this module never imports bpy) and then only updates
it per sample. Every stage is timed (``perf_counter``); the timings stay on the
``Sample`` (``crackgen bench`` reads them there, ``generate`` sums them per shard into
the manifest) and never go into the sample's JSON, so two runs of one recipe write
byte-identical shards.

Where GT comes from: the GT mask and ``depth.exr`` are ray cast at pixel centres on
the very mesh Blender renders (``groundtruth.view_ground_truth``), not taken from
Blender's Depth pass: Cycles writes that pass from one jittered sample inside the
pixel-filter footprint, so at crack walls it is not the pixel-centre depth, and the
mask would otherwise need a second render. The Blender depth pass is still compared
with the ray-cast depth per sample and its agreement (median |difference|) is stored
in the metadata as a cheap, always-on check that renderer and ray caster agree.
``mask.png`` is the ``[label]`` policy's label (visible crack by default; the thesis
mask then goes to ``mask_thesis.png``), checked against the clean render.
"""
from __future__ import annotations

import dataclasses
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from importlib.metadata import PackageNotFoundError, version
from typing import Any, Iterator

import numpy as np

import crackgen
from crackgen.config.recipe import Recipe
from crackgen.config.spec import SampleSpec, crack_pixel_m, make_spec, scene_of
from crackgen.datagen.heap import configure_heap, release_free_heap
from crackgen.datagen.lens_stage import canvas_coverage, lens_maps, warp_view_members
from crackgen.errors import CrackgenError
from crackgen.postrender.stage import adapt_members, camera_effects_members
from crackgen.postrender.targets import TargetPhotos
from crackgen.procedural.crackmap import crack_map
from crackgen.procedural.materials import brick_joints, material_maps
from crackgen.procedural.shadow_pattern import shadow_alpha
from crackgen.procedural.surface import (
    mesh_depth_map,
    surface_faces,
    surface_uvs,
    surface_vertices,
    with_relief,
    with_steps,
)
from crackgen.sim.groundtruth import label_texels, view_ground_truth, view_label
from crackgen.sim.raycast import MeshRaycaster
from crackgen.sim.rig import make_rig
from crackgen.sim.sensors import sensor_rng
from crackgen.sim.sensors.lidar import simulate_lidar
from crackgen.sim.sensors.stereo import simulate_stereo
from crackgen.sim.sensors.tof import albedo_from_map, simulate_tof
from crackgen.sim.visible_gt import visible_ground_truth
from fusion.geometry.lens import warp

STAGES = ("spec", "crackmap", "surface", "materials", "shadow", "scene_update", "render",
          "raycast", "groundtruth", "tof", "lidar", "stereo", "lens", "camera_effects", "adapt")
SHADOW_PX = 256  # occluder alpha resolution (px per side)


class PipelineError(CrackgenError, RuntimeError):
    """A stage failed for a sample; the message names the sample index and the stage."""


@dataclass
class Sample:
    """Everything one sample produced, before encoding."""

    index: int
    members: dict[str, Any]  # member name (``rgb.png``...) -> array / dict of arrays
    meta: dict[str, Any]  # KEY.json: a function of (recipe, index) only, nothing run-dependent
    timings: dict[str, float] = field(default_factory=dict)  # per-stage seconds, never written to the shard
    rgb_linear: np.ndarray | None = None  # (H,W,3) float32 scene-linear render, only with keep_linear (bench)


class _Timer:
    def __init__(self, index: int):
        self.index = index
        self.t: dict[str, float] = {}

    @contextmanager
    def stage(self, name: str) -> Iterator[None]:
        t0 = time.perf_counter()
        try:
            yield
        except PipelineError:
            raise
        except Exception as exc:
            msg = str(exc).strip().splitlines()
            raise PipelineError(f"sample {self.index}: {name}: {type(exc).__name__}: {msg[0] if msg else ''}") from exc
        finally:
            self.t[name] = self.t.get(name, 0.0) + time.perf_counter() - t0


@dataclass
class SceneBuild:
    """What every view of one scene shares (``[camera] views_per_scene``): the crack map, the surface mesh, the
    material maps and the ray caster, built once per (scene, redraw attempt)."""

    key: tuple[int, int]
    cm: Any  # CrackMap
    vertices: np.ndarray  # the crack relief alone (what mesh_depth_map measures)
    world: np.ndarray  # + height steps and joint relief: what cameras and sensors see
    maps: Any  # MaterialMaps
    caster: MeshRaycaster
    label_texels: np.ndarray  # crack-map texels labelled crack (``label_texels``): every view looks its pixels up


def crack_pixel_fraction(mask: np.ndarray) -> float:
    return float(np.count_nonzero(mask)) / float(mask.size)


def fill_ratio(depth: np.ndarray) -> float:
    """Fraction of pixels with a value (> 0) in a sparse/dense depth map (-1 = none)."""
    return float(np.count_nonzero(depth > 0)) / float(depth.size)


class SampleProducer:
    """Turns sample indices of one recipe into shard members; one per worker process."""

    def __init__(self, recipe: Recipe, threads: int = 0, keep_linear: bool = False):
        configure_heap()  # CRACKGEN_MMAP_THRESHOLD, when set: fixed glibc thresholds (crackgen/datagen/heap.py)
        self.recipe = recipe
        self.threads = int(threads)
        self.keep_linear = bool(keep_linear)  # keep the scene-linear render on the Sample (crackgen bench --sweep)
        self._scene = None
        self._targets: TargetPhotos | None = None
        self._build: SceneBuild | None = None  # the last scene, kept for its next view (views_per_scene > 1)

    @property
    def targets(self) -> TargetPhotos | None:
        """The [adapt] target photos, listed once per worker (the driver checked them before rendering)."""
        if self._targets is None and self.recipe.adapt.enabled:
            self._targets = TargetPhotos(self.recipe.adapt.target, check=False)
        return self._targets

    # ---- Blender (lazy: bpy is imported by the first render only)
    @property
    def scene(self):
        if self._scene is None:
            from crackgen.blender.scene import LiveScene

            r = self.recipe
            self._scene = LiveScene(
                grid_px=r.surface.grid_px,
                texture_px=r.material.texture_px,
                width=r.camera.width_px,
                height=r.camera.height_px,
                stereo=r.stereo.enabled,
                threads=self.threads,
                device=r.render.device,
                samples=r.render.samples,
                denoise=r.render.denoise,
                max_bounces=r.render.max_bounces,
                persistent_data=r.render.persistent_data,
                max_lights=int(max(v for v in r.lights.count.support())),
                shadow_px=SHADOW_PX,
            )
        return self._scene

    def close(self) -> None:
        if self._scene is not None and hasattr(self._scene, "close"):
            self._scene.close()
        self._scene = None
        self._build = None

    def _scene_build(self, spec: SampleSpec, attempt: int, tm: _Timer) -> SceneBuild:
        """The shared part of sample ``spec.index``: reused when the previous sample was a view of the same
        scene, else built (a pure function of the recipe, the scene and the attempt, so reuse changes nothing)."""
        key = (scene_of(self.recipe, spec.index), int(attempt))
        if self._build is not None and self._build.key == key:
            return self._build
        self._build = None  # the last scene's arrays go before the next one's are made
        with tm.stage("crackmap"):
            cm = crack_map(
                spec.crack,
                size_px=spec.surface.crackmap_px,
                size_m=spec.surface.size_m,
                pixel_m=crack_pixel_m(self.recipe, spec),
                joints=brick_joints(spec.material) if spec.crack.shape == "stairstep" else None,
            )
        with tm.stage("surface"):
            g = spec.surface.grid_px
            vertices = surface_vertices(cm, g)  # the crack relief alone: what mesh_depth_map measures
        with tm.stage("materials"):
            # the normal map carries only the crack depth the mesh cannot hold: the slope counts once
            maps = material_maps(spec.material, cm, mesh_depth_map(vertices, g, spec.material.texture_px))
        with tm.stage("surface"):
            # + height steps and recessed joints: what cameras and sensors see
            world = with_relief(with_steps(vertices, spec.surface.steps), maps.relief_m)
        with tm.stage("raycast"):
            caster = MeshRaycaster(world, np.asarray(surface_faces(g)), np.asarray(surface_uvs(g)))
        with tm.stage("groundtruth"):
            # the visible label follows the groove the mesh renders, not only the crack map's mask
            label_depth = mesh_depth_map(vertices, g, cm.size_px) if self.recipe.label.policy == "visible" else None
            texels = label_texels(self.recipe.label, cm, label_depth)
        build = SceneBuild(key, cm, vertices, world, maps, caster, texels)
        if self.recipe.camera.views_per_scene > 1:
            self._build = build
        return build

    # ---- one sample
    def make(self, index: int) -> Sample:
        """Run every stage for sample ``index``; raises ``PipelineError`` naming the stage.

        With ``[label] invisible = "redraw"``, a sample whose crack does not show is made again
        with a new crack (``make_spec(..., attempt)``), at most ``max_redraws`` times."""
        tm = _Timer(index)
        attempt = 0
        while True:
            sample = self._make(index, attempt, tm)
            release_free_heap()  # this try's temporaries are gone: keep the worker's RSS flat
            if sample is not None:
                return sample
            attempt += 1

    def _make(self, index: int, attempt: int, tm: _Timer) -> Sample | None:
        """One try at sample ``index``; None when its crack does not show and is to be redrawn."""
        with tm.stage("spec"):
            spec: SampleSpec = make_spec(self.recipe, index, attempt)
            rig = make_rig(spec)
        build = self._scene_build(spec, attempt, tm)
        cm, maps, caster = build.cm, build.maps, build.caster
        with tm.stage("shadow"):
            alpha = shadow_alpha(spec.shadow, SHADOW_PX) if spec.shadow.enabled else None
        scene = self.scene
        with tm.stage("scene_update"):
            # The worker's share of the cores goes to Cycles only; the spec written to the
            # metadata keeps the recipe's value so content does not depend on the worker count.
            run_spec = spec
            if self.threads > 0:
                run_spec = dataclasses.replace(spec, render=dataclasses.replace(spec.render, threads=self.threads))
            # the same scene's next view: the mesh and textures Blender holds are this build's already (with
            # persistent data Cycles keeps its copies too; a worker starting inside a scene uploads them fresh and
            # renders the same pixels: tests/datagen/test_persistent_data.py)
            reuse = self.recipe.camera.views_per_scene > 1
            same = build.key if reuse else None
            scene_meta = scene.update(run_spec, rig, build.world, maps, alpha, surface_key=same)
        with tm.stage("render"):
            out = scene.render(linear=self.keep_linear)
        with tm.stage("groundtruth"):
            gt = view_ground_truth(rig.rgb, caster, cm.mask)
            label = view_label(self.recipe.label, cm, gt, out.rgb, attempt, texels=build.label_texels)
        if label.redraw:
            return None
        lens_map = None
        if rig.lens is not None:
            with tm.stage("lens"):
                lens_map = lens_maps(rig)
        with tm.stage("groundtruth"):
            uv = gt.uv  # with a lens: only the canvas pixels the distorted frame shows
            if lens_map is not None:
                uv = np.where(canvas_coverage(lens_map, uv.shape[:2])[..., None], uv, np.nan)
            visible = visible_ground_truth(cm, rig.rgb, uv)
        members: dict[str, Any] = {
            "rgb.png": out.rgb,
            "mask.png": label.mask,
            "depth.exr": gt.depth,
            "crackmap.exr": cm.depth_m,
        }
        if self.recipe.label.policy != "thesis":  # both labels on the same render, to compare
            members["mask_thesis.png"] = label.thesis
        sensors, camera_views, camera_effects_meta = _simulate_sensors(spec, rig, caster, maps, out, gt, tm, members)
        rgb_linear = out.rgb_linear
        if lens_map is not None:  # the lens, before the camera's effects: every RGB-view member, one map
            with tm.stage("lens"):
                members = warp_view_members(members, lens_map)
                if rgb_linear is not None:  # the bench's copy too: it is compared with the (distorted) label
                    rgb_linear = warp(rgb_linear, lens_map, nearest=False)
                if camera_views is not None:  # SGBM matched effect-applied canvas views (sgbm_input = "camera")
                    camera_views = warp_view_members(camera_views, lens_map)
        # post-render image stages: RGB views only, after every sensor has read the clean render
        # (except SGBM with sgbm_input = "camera": the same effects, applied once, above)
        if camera_views is None:
            with tm.stage("camera_effects"):
                members, camera_effects_meta = camera_effects_members(spec.camera_effects, members)
        else:
            members.update(camera_views)
        with tm.stage("adapt"):
            members, adapt_meta = adapt_members(spec.adapt, members, self.targets if spec.adapt.enabled else None)

        valid = (gt.depth > 0) & (out.depth > 0)
        render_vs_raycast = float(np.median(np.abs(out.depth[valid] - gt.depth[valid]))) if valid.any() else None
        meta = {
            "index": int(index),
            "spec": spec.to_dict(),
            "cameras": rig.to_meta(),
            "seeds": _seeds_meta(spec, index),
            **_scene_meta(spec, cm, maps, members["mask.png"]),  # crack, material, lights, sky, shadow
            "label": label.meta,
            "visible": visible,
            "depth": {
                "source": "raycast",
                "fill": fill_ratio(gt.depth),
                "render_vs_raycast_median_abs_m": render_vs_raycast,
            },
            "sensors": sensors,
            "adapt": adapt_meta,
            "camera_effects": camera_effects_meta,
            "render": {"device": scene_meta.get("device"), "lights": scene_meta.get("lights")},
            **_views_meta(self.recipe, index),
            "recipe_hash": self.recipe.hash,
            "versions": {"crackgen": crackgen.__version__, "spec": spec.version, **_blender_version()},
        }
        return Sample(index=int(index), members=members, meta=meta, timings=tm.t, rgb_linear=rgb_linear)

    def produce(self, index: int) -> tuple[dict[str, Any], dict[str, Any]]:
        """(members, meta) of sample ``index``: what a shard holds for it (``json`` = meta)."""
        s = self.make(index)
        return s.members, s.meta


def _simulate_sensors(spec: SampleSpec, rig, caster, maps, out, gt, tm: _Timer,
                      members: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any] | None, dict[str, Any] | None]:
    """ToF, LiDAR and stereo on the clean render, their members added to ``members``.

    Returns the sensors' metadata and, when SGBM is to match the camera's views
    (``sgbm_input = "camera"``), those views and the camera effects' record (else None, None).
    """
    sensors: dict[str, Any] = {}
    tof = lidar = None
    if spec.tof.enabled:
        with tm.stage("tof"):
            tof = simulate_tof(spec.tof, rig, caster, albedo_from_map(maps.albedo), sensor_rng(spec.tof.seed))
        members["tof.exr"] = tof.depth_rgb
        # native sensor image: Z = measured radial range (m, -1 none), A = amplitude
        members["tofraw.exr"] = {"Z": tof.range_m, "A": tof.amplitude}
        sensors["tof"] = {"fill_rgb": fill_ratio(tof.depth_rgb), "valid": float(tof.valid.mean()),
                          "mixed": int(tof.mixed.sum())}
    if spec.lidar.enabled:
        with tm.stage("lidar"):
            lidar = simulate_lidar(spec.lidar, rig, caster, sensor_rng(spec.lidar.seed))
        members["lidar.exr"] = lidar.depth_rgb
        sensors["lidar"] = {"fill_rgb": fill_ratio(lidar.depth_rgb), "points": int(len(lidar.points_world))}
    camera_views = camera_effects_meta = None  # the RGB views after the camera, when SGBM is to match those
    if rig.right is not None and spec.stereo.sgbm_input == "camera":
        with tm.stage("camera_effects"):
            camera_views, camera_effects_meta = camera_effects_members(
                spec.camera_effects, {"rgb.png": out.rgb, "right.png": out.right_rgb})
    if rig.right is not None:
        left, right = ((out.rgb, out.right_rgb) if camera_views is None
                       else (camera_views["rgb.png"], camera_views["right.png"]))
        with tm.stage("stereo"):
            st = simulate_stereo(spec.stereo, rig, left, right, gt.depth, tof,
                                 None if lidar is None else lidar.depth_rgb)
        members["right.png"] = out.right_rgb
        members["disp_sgm.exr"] = st.disp_sgm
        members["disp_gt.exr"] = st.disp_gt
        if st.disp_tof is not None:  # SYNTH3-style fusion inputs in the left view
            members["disp_tof.exr"] = st.disp_tof
            members["tofamp.exr"] = st.tof_amplitude
        if st.disp_lidar is not None:  # the 3-channel LiDAR/stereo variant's input
            members["disp_lidar.exr"] = st.disp_lidar
        sensors["stereo"] = {"fill_sgm": fill_ratio(st.disp_sgm), "fill_gt": fill_ratio(st.disp_gt),
                             "sgbm_input": spec.stereo.sgbm_input}
    return sensors, camera_views, camera_effects_meta


def _scene_meta(spec: SampleSpec, cm, maps, mask: np.ndarray) -> dict[str, Any]:
    """What the scene held: crack, material, lights, sky and shadow (shards store JSON with sorted keys)."""
    return {
        "crack": {
            "shape": spec.crack.shape,
            "present": bool(spec.crack.present),
            "length_m": None if not np.isfinite(cm.length_m) else float(cm.length_m),
            "surface_coverage": cm.coverage,
            "pixel_fraction": crack_pixel_fraction(mask),
        },
        "material": {"family": spec.material.family, "distractors": [d.kind for d in spec.material.distractors],
                     "clutter": [c.kind for c in spec.material.clutter], "photo": maps.photo},
        "lights": [{"kind": L.kind, "elevation_deg": float(np.degrees(L.elevation_rad))} for L in spec.lights],
        **({"sky": {"turbidity": spec.sky.turbidity, "overcast": spec.sky.overcast,
                    "sun_elevation_deg": float(np.degrees(spec.sky.sun_elevation_rad))}} if spec.sky.enabled else {}),
        "shadow": {"enabled": spec.shadow.enabled, "pattern": spec.shadow.pattern},
    }


def _views_meta(recipe: Recipe, index: int) -> dict[str, Any]:
    """Which scene a sample is a view of (only with ``views_per_scene`` > 1: one view per scene adds nothing)."""
    k = recipe.camera.views_per_scene
    if k == 1:
        return {}
    return {"scene": {"index": scene_of(recipe, index), "view": int(index) % k, "views_per_scene": k}}


def _seeds_meta(spec: SampleSpec, index: int) -> dict[str, Any]:
    """The seeds a sample was drawn from, so any single stage can be replayed."""
    return {
        "recipe_seed": spec.recipe_seed,
        "seed_sequence": [spec.recipe_seed, int(index)],
        "crack_noise": spec.crack.noise_seed,
        "material": spec.material.seed,
        "shadow": spec.shadow.seed,
        "render": spec.render.seed,
        "tof": spec.tof.seed,
        "lidar": spec.lidar.seed,
    }


_BLENDER_VERSION: dict[str, str] | None = None


def _blender_version() -> dict[str, str]:
    global _BLENDER_VERSION
    if _BLENDER_VERSION is None:
        try:
            _BLENDER_VERSION = {"bpy": version("bpy")}
        except PackageNotFoundError:
            _BLENDER_VERSION = {}
    return _BLENDER_VERSION
