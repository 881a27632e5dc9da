"""Cycles settings, device choice and reading a render back as numpy arrays.

Why an EXR round trip: in headless bpy 4.5 the 'Render Result' image has no
readable pixels, so the reliable way out is ``render(write_still=True)`` to one
uncompressed multilayer float32 OpenEXR (Combined + Depth) in a RAM-backed temp
folder, read with the OpenEXR module. The colour is scene-linear; with the view
transform 'Standard' Blender's own sRGB output is the IEC 61966-2-1 curve of it,
which we apply in numpy (and quantise by rounding, no dither) to get uint8 sRGB.

Depth: Cycles' Depth pass is planar camera z (metres), written from one camera
sample per pixel (not averaged). Measured against the pixel-centre ray cast
(tests/test_blender_render.py): max 8 um at the default 1.5 px filter, 0.2 um at
0.01 px, crack walls included, so that sample sits practically at the pixel centre.
Background (no hit, ~1e10) becomes -1.
"""
from __future__ import annotations

import atexit
import contextlib
import logging
import os
import sys
import tempfile
import time
from dataclasses import dataclass, fields
from typing import Any

import bpy
import numpy as np
import OpenEXR

from crackgen.config.spec import RenderKnobs
from crackgen.errors import CrackgenError

log = logging.getLogger(__name__)
DEPTH_BACKGROUND_M = 1e8  # Cycles writes ~1e10 where a camera ray hits nothing
_GPU_WARNED = False


class RenderError(CrackgenError, RuntimeError):
    """A render that did not produce the expected output (names the file/pass)."""


@dataclass(kw_only=True)
class RenderSettings(RenderKnobs):
    samples: int = 16
    denoise: bool = True
    threads: int = 0  # 0 = Cycles decides (AUTO)
    device: str = "cpu"  # cpu | gpu
    max_bounces: int = 4
    seed: int = 0
    filter_width_px: float = 1.5  # Blackman-Harris pixel filter width (Blender default)

    @classmethod
    def from_spec(cls, r: Any, filter_width_px: float, **override: Any) -> "RenderSettings":
        """Settings from a ``RenderSpec`` (or anything with its attribute names)."""
        names = [f.name for f in fields(cls) if f.name != "filter_width_px" and hasattr(r, f.name)]
        return cls(**{**{n: getattr(r, n) for n in names}, "filter_width_px": filter_width_px, **override})


# recipe value -> Cycles enum identifier (checked against bpy 4.5's enum items in the tests)
PREFILTERS = {"none": "NONE", "fast": "FAST", "accurate": "ACCURATE"}
DENOISE_PASSES = {"rgb": "RGB", "rgb_albedo": "RGB_ALBEDO", "rgb_albedo_normal": "RGB_ALBEDO_NORMAL"}
DENOISE_QUALITY = {"high": "HIGH", "balanced": "BALANCED", "fast": "FAST"}


def _enable_gpu() -> bool:
    """Try OptiX then CUDA (then HIP/oneAPI/Metal); True when a GPU device is enabled."""
    try:
        prefs = bpy.context.preferences.addons["cycles"].preferences
    except KeyError:
        return False
    for kind in ("OPTIX", "CUDA", "HIP", "ONEAPI", "METAL"):
        try:
            prefs.compute_device_type = kind
        except TypeError:
            continue
        prefs.get_devices()
        gpus = [d for d in prefs.devices if d.type == kind]
        if gpus:
            for d in prefs.devices:
                d.use = d.type == kind
            log.info("Cycles uses %s: %s", kind, ", ".join(d.name for d in gpus))
            return True
    return False


def select_device(scene: bpy.types.Scene, device: str) -> str:
    """Set the Cycles device; 'gpu' falls back to 'cpu' with one warning per process."""
    global _GPU_WARNED
    if device not in ("cpu", "gpu"):
        raise RenderError(f"render.device must be 'cpu' or 'gpu', got {device!r}")
    if device == "gpu" and _enable_gpu():
        scene.cycles.device = "GPU"
        return "gpu"
    if device == "gpu" and not _GPU_WARNED:
        log.warning("render.device = 'gpu' but no OptiX/CUDA/HIP device is available: rendering on the CPU")
        _GPU_WARNED = True
    scene.cycles.device = "CPU"
    return "cpu"


def set_multilayer_exr(settings: Any) -> None:
    """Blender 5.0 chooses multilayer output by media type (file formats follow); 4.5 by file format."""
    if "media_type" in settings.bl_rna.properties:
        settings.media_type = "MULTI_LAYER_IMAGE"
    settings.file_format = "OPEN_EXR_MULTILAYER"


def configure_scene(scene: bpy.types.Scene, width: int, height: int, persistent_data: bool = False) -> None:
    """Once per worker: Cycles, passes, colour management, output file format."""
    scene.render.engine = "CYCLES"
    scene.render.resolution_x = int(width)
    scene.render.resolution_y = int(height)
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    # Off by default: with persistent data Cycles keeps the previously uploaded pixels of an
    # image after image.pixels.foreach_set (measured again for issue 12: update(), update_tag(),
    # pack() do not help, reload() blanks a generated image). What works is pointing the image
    # node at another image datablock: ``blender.images.ImageSlot`` swaps between two, so
    # persistent_data = true is correct; whether it saves time is `crackgen bench --sweep`'s call.
    scene.render.use_persistent_data = bool(persistent_data)
    scene.render.film_transparent = False
    scene.cycles.use_animated_seed = False
    scene.cycles.denoiser = "OPENIMAGEDENOISE"
    scene.cycles.pixel_filter_type = "BLACKMAN_HARRIS"
    scene.display_settings.display_device = "sRGB"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    vl = scene.view_layers[0]
    vl.use_pass_combined = True
    vl.use_pass_z = True
    s = scene.render.image_settings
    set_multilayer_exr(s)
    s.color_depth = "32"
    s.exr_codec = "NONE"
    s.color_mode = "RGBA"


def _choice(table: dict[str, str], name: str, value: str) -> str:
    if value not in table:
        raise RenderError(f"render.{name} must be one of {', '.join(table)}, got {value!r}")
    return table[value]


def apply_settings(scene: bpy.types.Scene, rs: RenderSettings) -> None:
    """Per sample (cheap property writes): samples, denoiser, threads, bounces, seed, speed knobs.

    ``persistent_data`` is not written here: the scene's images must be built for it
    (``LiveScene(persistent_data=...)``), so it is set once in ``configure_scene``."""
    if rs.samples < 1:
        raise RenderError(f"render.samples must be >= 1, got {rs.samples!r}")
    for name in ("adaptive_min_samples", "diffuse_bounces", "glossy_bounces", "transmission_bounces",
                 "transparent_bounces", "ao_bounces", "adaptive_threshold", "clamp_direct", "clamp_indirect"):
        if getattr(rs, name) < 0:
            raise RenderError(f"render.{name} must be >= 0, got {getattr(rs, name)!r}")
    c = scene.cycles
    c.samples = int(rs.samples)
    c.use_denoising = bool(rs.denoise)
    c.denoising_prefilter = _choice(PREFILTERS, "denoise_prefilter", rs.denoise_prefilter)
    c.denoising_input_passes = _choice(DENOISE_PASSES, "denoise_passes", rs.denoise_passes)
    c.denoising_quality = _choice(DENOISE_QUALITY, "denoise_quality", rs.denoise_quality)
    c.use_adaptive_sampling = bool(rs.adaptive_sampling)
    c.adaptive_threshold = float(rs.adaptive_threshold)
    c.adaptive_min_samples = int(rs.adaptive_min_samples)
    c.max_bounces = int(rs.max_bounces)
    c.diffuse_bounces = int(rs.diffuse_bounces)
    c.glossy_bounces = int(rs.glossy_bounces)
    c.transmission_bounces = int(rs.transmission_bounces)
    c.transparent_max_bounces = int(rs.transparent_bounces)
    c.caustics_reflective = bool(rs.caustics_reflective)
    c.caustics_refractive = bool(rs.caustics_refractive)
    c.use_light_tree = bool(rs.light_tree)
    c.use_fast_gi = bool(rs.fast_gi)
    c.ao_bounces_render = int(rs.ao_bounces)
    c.sample_clamp_direct = float(rs.clamp_direct)
    c.sample_clamp_indirect = float(rs.clamp_indirect)
    c.seed = int(rs.seed) % (2**31 - 1)
    c.filter_width = float(rs.filter_width_px)
    if rs.threads > 0:
        scene.render.threads_mode = "FIXED"
        scene.render.threads = int(rs.threads)
    else:
        scene.render.threads_mode = "AUTO"


def linear_to_srgb8(rgb: np.ndarray) -> np.ndarray:
    """Scene-linear float RGB -> uint8 sRGB (IEC 61966-2-1), clipped, rounded."""
    x = np.clip(rgb, 0.0, 1.0)
    s = np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
    return np.round(s * 255.0).astype(np.uint8)


BPY_WRITES_NO_PASSES = bpy.app.version >= (5, 0, 0)  # bpy 5.0.1 as a module saves only Combined (measured)


def read_render_exr(path: str, depth_optional: bool = BPY_WRITES_NO_PASSES) -> tuple[np.ndarray, np.ndarray]:
    """Blender multilayer EXR -> (linear RGB (H,W,3) float32, depth (H,W) float32, -1 = none), top row first.

    ``depth_optional``: a file without a Depth pass gives an all -1 depth instead of an error;
    the ray-cast depth is the depth member, the render's is only a cross-check.
    """
    try:
        with OpenEXR.File(path, separate_channels=True) as f:
            ch = f.channels()
            names = list(ch)

            def get(suffix: str, optional: bool = False) -> np.ndarray | None:
                hit = [n for n in names if n.endswith(suffix)]
                if not hit:
                    if optional:
                        return None
                    raise RenderError(f"{path}: render has no channel '*{suffix}' (channels: {names})")
                return np.asarray(ch[hit[0]].pixels, dtype=np.float32)

            rgb = np.stack([get("Combined.R"), get("Combined.G"), get("Combined.B")], axis=-1)
            depth = get("Depth.Z", optional=depth_optional)
            if depth is None:
                depth = np.full(rgb.shape[:2], -1.0, dtype=np.float32)
    except RenderError:
        raise
    except Exception as exc:  # OpenEXR raises bare RuntimeErrors
        raise RenderError(f"{path}: cannot read the rendered EXR: {exc}") from None
    # OpenEXR stores scanlines top-down already (increasing y = image down): no flip needed here.
    depth = np.where(np.isfinite(depth) & (depth < DEPTH_BACKGROUND_M) & (depth > 0), depth, -1.0).astype(np.float32)
    return rgb, depth


@contextlib.contextmanager
def quiet_stdout():
    """Silence Blender's C-level 'Fra:/Saved:/Time:' prints (fd 1) during a render."""
    fd = 1  # Blender writes to the process's fd 1, whatever sys.stdout is (pytest swaps it)
    try:
        sys.stdout.flush()
    except (AttributeError, OSError, ValueError):
        pass
    saved = os.dup(fd)
    devnull = os.open(os.devnull, os.O_WRONLY)
    try:
        os.dup2(devnull, fd)
        yield
    finally:
        os.dup2(saved, fd)
        os.close(saved)
        os.close(devnull)


class Renderer:
    """Renders the scene's active camera into a private RAM-backed temp file and reads it back."""

    def __init__(self, scene: bpy.types.Scene):
        self.scene = scene
        base = "/dev/shm" if os.path.isdir("/dev/shm") and os.access("/dev/shm", os.W_OK) else None
        self._tmp = tempfile.TemporaryDirectory(prefix="crackgen_render_", dir=base)
        self.path = os.path.join(self._tmp.name, "render.exr")
        self.last_times: dict[str, float] = {}
        atexit.register(self._tmp.cleanup)  # bpy's exit can skip TemporaryDirectory's finalizer

    def render(self, camera_obj: bpy.types.Object) -> tuple[np.ndarray, np.ndarray]:
        """(linear RGB float32 (H,W,3), depth float32 (H,W)) of ``camera_obj``, row 0 = top.

        ``last_times`` gets the Blender render (sync + path tracing + denoise + EXR write)
        and the read-back times, in seconds."""
        t0 = time.perf_counter()
        self.scene.camera = camera_obj
        self.scene.render.filepath = self.path
        if os.path.exists(self.path):
            os.remove(self.path)
        with quiet_stdout():
            bpy.ops.render.render(write_still=True, scene=self.scene.name)
        if not os.path.exists(self.path):
            raise RenderError(f"{self.path}: Blender wrote no render output")
        t1 = time.perf_counter()
        out = read_render_exr(self.path)
        self.last_times = {"blender_s": t1 - t0, "readback_s": time.perf_counter() - t1}
        return out

    def close(self) -> None:
        self._tmp.cleanup()
