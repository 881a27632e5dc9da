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
from dataclasses import dataclass

import bpy
import numpy as np
import OpenEXR

from crackgen.errors import CrackgenError

log = logging.getLogger(__name__)
DEPTH_BACKGROUND_M = 1e8  # Cycles writes ~1e10 where a camera ray hits nothing
_GPU_WARNED = False


class RenderError(CrackgenError, RuntimeError):
    """A render that did not produce the expected output (names the file/pass)."""


@dataclass
class RenderSettings:
    samples: int = 16
    denoise: bool = True
    threads: int = 0  # 0 = Cycles decides (AUTO)
    device: str = "cpu"  # cpu | gpu
    max_bounces: int = 4
    seed: int = 0
    filter_width_px: float = 1.5  # Blackman-Harris pixel filter width (Blender default)


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


def configure_scene(scene: bpy.types.Scene, width: int, height: int) -> None:
    """Once per worker: Cycles, passes, colour management, output file format."""
    scene.render.engine = "CYCLES"
    scene.render.resolution_x = int(width)
    scene.render.resolution_y = int(height)
    scene.render.resolution_percentage = 100
    scene.render.pixel_aspect_x = scene.render.pixel_aspect_y = 1.0
    scene.render.use_compositing = False
    scene.render.use_sequencer = False
    # Off on purpose: with persistent data Cycles keeps the previously uploaded image
    # pixels after image.pixels.foreach_set (measured; update()/update_tag() do not help),
    # and at 512 px / 16 spp it saved nothing measurable (mesh changes rebuild the BVH anyway).
    scene.render.use_persistent_data = False
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
    s.file_format = "OPEN_EXR_MULTILAYER"
    s.color_depth = "32"
    s.exr_codec = "NONE"
    s.color_mode = "RGBA"


def apply_settings(scene: bpy.types.Scene, rs: RenderSettings) -> None:
    """Per sample (cheap property writes): samples, denoiser, threads, bounces, seed."""
    if rs.samples < 1:
        raise RenderError(f"render.samples must be >= 1, got {rs.samples!r}")
    c = scene.cycles
    c.samples = int(rs.samples)
    c.use_denoising = bool(rs.denoise)
    c.max_bounces = int(rs.max_bounces)
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


def read_render_exr(path: str) -> tuple[np.ndarray, np.ndarray]:
    """Blender multilayer EXR -> (linear RGB (H,W,3) float32, depth (H,W) float32, -1 = none), top row first."""
    try:
        with OpenEXR.File(path, separate_channels=True) as f:
            ch = f.channels()
            names = list(ch)

            def get(suffix: str) -> np.ndarray:
                hit = [n for n in names if n.endswith(suffix)]
                if not hit:
                    raise RenderError(f"{path}: render has no channel '*{suffix}' (channels: {names})")
                return np.asarray(ch[hit[0]].pixels, dtype=np.float32)

            rgb = np.stack([get("Combined.R"), get("Combined.G"), get("Combined.B")], axis=-1)
            depth = get("Depth.Z")
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
