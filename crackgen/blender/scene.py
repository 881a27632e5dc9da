"""LiveScene: the worker's one Blender scene, built once and updated per sample.

Why: a factory reset, node-tree build or datablock creation per sample costs time
and leaks memory over thousands of samples. The scene is reset once at build; each
``update`` only writes vertex positions, image pixels, light/camera/occluder
parameters and render settings, so ``bpy.data`` counts and RSS stay flat.
"""
from __future__ import annotations

import time
from collections.abc import Hashable
from dataclasses import dataclass, field

import bpy
import numpy as np

from crackgen.blender.camera import apply_camera
from crackgen.blender.lights import LightPool, Sky
from crackgen.blender.render import (
    Renderer,
    RenderSettings,
    apply_settings,
    configure_scene,
    linear_to_srgb8,
    select_device,
)
from crackgen.blender.shadow import ShadowOccluder
from crackgen.blender.surface import LiveSurface, MapsLike
from crackgen.config.spec import SampleSpec
from crackgen.errors import CrackgenError
from crackgen.sim.rig import Rig


class SceneUpdateError(CrackgenError, ValueError):
    """A sample that does not fit the live scene (names the field)."""


@dataclass
class RenderOutput:
    rgb: np.ndarray  # (H,W,3) uint8 sRGB, row 0 = top
    depth: np.ndarray  # (H,W) float32 planar z (m), -1 = background; one jittered sample per pixel
    right_rgb: np.ndarray | None = None
    right_depth: np.ndarray | None = None
    rgb_linear: np.ndarray | None = None  # (H,W,3) float32 scene-linear, before the sRGB curve
    meta: dict = field(default_factory=dict)  # device, light colours, occluder pose, timings (s)


class LiveScene:
    """Headless Cycles scene: surface, lights, sky, shadow occluder, RGB (+ right) camera."""

    def __init__(
        self,
        grid_px: int,
        texture_px: int,
        width: int,
        height: int,
        stereo: bool = False,
        threads: int = 0,
        device: str = "cpu",
        samples: int = 16,
        denoise: bool = True,
        max_bounces: int = 4,
        max_lights: int = 8,
        shadow_px: int = 256,
        filter_width_px: float = 1.5,
        persistent_data: bool = False,
    ):
        bpy.ops.wm.read_factory_settings(use_empty=True)
        self.scene = bpy.context.scene
        self.persistent_data = bool(persistent_data)  # images then swap between two datablocks
        configure_scene(self.scene, width, height, self.persistent_data)
        self.device = select_device(self.scene, device)
        self.defaults = RenderSettings(samples=samples, denoise=denoise, threads=threads, device=device,
                                       max_bounces=max_bounces, seed=0, filter_width_px=filter_width_px,
                                       persistent_data=self.persistent_data)
        self.filter_width_px = float(filter_width_px)  # Cycles pixel filter; public, applied at the next update()
        self.surface = LiveSurface(self.scene, grid_px, texture_px, swap_images=self.persistent_data)
        self.lights = LightPool(self.scene, max_lights)
        self.sky = Sky(self.scene)
        self.occluder = ShadowOccluder(self.scene, shadow_px, swap_images=self.persistent_data)
        self.camera = self._camera("crackgen_rgb")
        self.right = self._camera("crackgen_right") if stereo else None
        self.renderer = Renderer(self.scene)
        self._has_right = False  # whether the last update posed the right camera
        self._surface_key: Hashable | None = None  # the surface the scene holds (update(surface_key=...))
        self.scene.camera = self.camera
        apply_settings(self.scene, self.defaults)

    def _camera(self, name: str) -> bpy.types.Object:
        data = bpy.data.cameras.new(name)
        data.clip_start = 0.001
        data.clip_end = 10000.0
        obj = bpy.data.objects.new(name, data)
        self.scene.collection.objects.link(obj)
        return obj

    @property
    def shadow_px(self) -> int:
        return self.occluder.px

    def datablock_counts(self) -> dict[str, int]:
        """Sizes of the bpy.data collections a leak would grow (checked by the tests)."""
        d = bpy.data
        return {k: len(getattr(d, k)) for k in ("objects", "meshes", "materials", "images", "lights", "cameras", "worlds", "node_groups")}

    def update(self, spec: SampleSpec, rig: Rig, vertices: np.ndarray, maps: MapsLike, shadow_alpha: np.ndarray | None,
               surface_key: Hashable | None = None) -> dict:
        """Write one sample into the scene; returns metadata (light colours, occluder pose).

        ``surface_key``: names the surface (vertices + maps) for reuse; when it equals the last update's key the
        mesh and textures Blender holds are kept as they are (another view of the same scene), and the
        persistent-data render keeps their BVH. None always writes them.

        ``vertices``: (grid_px^2, 3) from ``crackgen.procedural.surface.surface_vertices``; ``maps``: the
        sample's ``MaterialMaps``; ``shadow_alpha``: (shadow_px, shadow_px) from
        ``crackgen.procedural.shadow_pattern.shadow_alpha`` (ignored when ``spec.shadow.enabled`` is False).
        Render settings (samples, denoise, threads, bounces, Cycles seed, speed knobs) come from
        ``spec.render``; the device and persistent data were chosen once at build.
        """
        sc = self.scene
        c = spec.camera
        out = rig.output_camera(rig.rgb)  # with a lens the scene renders the larger pinhole canvas (rig.rgb)
        if (out.width, out.height) != (c.width_px, c.height_px):
            raise SceneUpdateError(f"rig.rgb is {out.width}x{out.height} but camera spec is {c.width_px}x{c.height_px}")
        sc.render.resolution_x, sc.render.resolution_y = int(rig.rgb.width), int(rig.rgb.height)
        if surface_key is None or surface_key != self._surface_key:
            self.surface.update(vertices, maps)
        self._surface_key = surface_key
        light_meta = self.lights.update(spec.lights, sun_scale=1.0 - spec.sky.overcast if spec.sky.enabled else 1.0)
        self.sky.update(spec.ambient, spec.sky)
        occ = self.occluder.update(spec.shadow, spec.lights, shadow_alpha)
        apply_camera(self.camera, rig.rgb)
        if rig.right is not None:
            if self.right is None:
                raise SceneUpdateError("rig has a right camera but the LiveScene was built with stereo=False")
            apply_camera(self.right, rig.right)
        r = spec.render
        if bool(getattr(r, "persistent_data", False)) != self.persistent_data:
            raise SceneUpdateError(f"spec.render.persistent_data is {r.persistent_data} but the LiveScene was built "
                                   f"with persistent_data={self.persistent_data}")
        apply_settings(sc, RenderSettings.from_spec(r, self.filter_width_px))
        self._has_right = rig.right is not None
        return {"device": self.device, "lights": light_meta, "occluder_matrix": None if occ is None else occ.tolist()}

    def render(self, linear: bool = False) -> RenderOutput:
        """Render the RGB view (and the right view when the last update had one)."""
        t0 = time.perf_counter()
        lin, depth = self.renderer.render(self.camera)
        out = RenderOutput(rgb=linear_to_srgb8(lin), depth=depth, rgb_linear=lin if linear else None)
        out.meta.update(self.renderer.last_times)
        out.meta["render_s"] = time.perf_counter() - t0
        if self._has_right:
            t1 = time.perf_counter()
            lin_r, depth_r = self.renderer.render(self.right)
            out.right_rgb, out.right_depth = linear_to_srgb8(lin_r), depth_r
            out.meta["render_right_s"] = time.perf_counter() - t1
            self.scene.camera = self.camera
        out.meta["device"] = self.device
        return out

    def close(self) -> None:
        self.renderer.close()
