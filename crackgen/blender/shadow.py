"""Shadow occluder (thesis 5.2.5): a textured plane between one light and the surface.

Why a real plane and not a light gobo: it works for every light kind (sun, area,
spot, point), and Cycles then produces physically right penumbrae from the light's
size. The plane is invisible to camera and glossy rays, so it never appears in the
image or in reflections, only in the shadows it casts. Its opacity comes from an
alpha image (``crackgen.procedural.shadow_pattern``) mixing a black diffuse BSDF with a
Transparent BSDF, which Cycles treats as a transparent shadow.
Built once; per sample only its pose, pixels and visibility change.

Why, with persistent data, a sample without a shadow parks the plane instead of hiding it: Cycles then kept
the alpha image it had uploaded before the plane was hidden, so a shadow drawn after a hidden sample could
render with an earlier sample's pattern, and a sample's image depended on what its worker had rendered
before (found on the tiny test recipe: 3 of 10 samples differed from a fresh worker's). Parked (shrunk to a
point 1 km below the surface, where no ray meets it) and written every sample like the surface's images, the
plane stays in Cycles' scene and every sample matches a fresh worker's; a parked plane renders exactly as a
hidden one. Without persistent data nothing is kept between renders, and the plane is hidden as before.
"""
from __future__ import annotations

import bpy
import numpy as np
from mathutils import Matrix

from crackgen.blender.images import ImageSlot
from crackgen.blender.lights import frame_facing, light_direction
from crackgen.config.spec import LightSpec, ShadowSpec
from crackgen.errors import CrackgenError

PARKED = np.diag([1e-6, 1e-6, 1e-6, 1.0])  # where a persistent-data scene keeps the plane without a shadow
PARKED[2, 3] = -1000.0


class ShadowError(CrackgenError, ValueError):
    """A shadow spec that does not fit the scene (names the field)."""


def occluder_matrix(shadow: ShadowSpec, light: LightSpec) -> np.ndarray:
    """4x4 world pose of the occluder (unit plane scaled to ``size_m``).

    Centre: ``height_m`` along the ray from the surface centre to the light, moved by
    ``offset_x_m``/``offset_y_m`` across that ray (local x horizontal); the plane faces
    the light (local +z toward it).
    """
    # Every light sits on this ray from the surface centre (lights.light_matrix), sun included.
    d = light_direction(light.elevation_rad, light.azimuth_rad)
    R = frame_facing(d)
    M = np.eye(4)
    M[:3, :3] = R * float(shadow.size_m)
    M[:3, 3] = shadow.height_m * d + shadow.offset_x_m * R[:, 0] + shadow.offset_y_m * R[:, 1]
    return M


class ShadowOccluder:
    """The occluder plane, its alpha image and material, created once."""

    def __init__(self, scene: bpy.types.Scene, pattern_px: int = 256, swap_images: bool = False):
        self.px = int(pattern_px)
        mesh = bpy.data.meshes.new("crackgen_occluder")
        verts = [(-0.5, -0.5, 0.0), (0.5, -0.5, 0.0), (0.5, 0.5, 0.0), (-0.5, 0.5, 0.0)]
        mesh.from_pydata(verts, [], [(0, 1, 2, 3)])
        uv = mesh.uv_layers.new(name="UVMap")
        uv.data.foreach_set("uv", [0.0, 0.0, 1.0, 0.0, 1.0, 1.0, 0.0, 1.0])
        mesh.update()
        # swap_images: two alternating images, for persistent data (see crackgen.blender.images)
        self.alpha = ImageSlot("crackgen_occluder_alpha", self.px, "Non-Color", swap_images)
        self._buf = np.ones((self.px * self.px, 4), np.float32)
        mesh.materials.append(self._material())
        obj = bpy.data.objects.new("crackgen_occluder", mesh)
        obj.visible_camera = False
        obj.visible_glossy = False
        obj.visible_transmission = False
        obj.visible_volume_scatter = False
        obj.visible_shadow = True
        obj.hide_render = True
        scene.collection.objects.link(obj)
        self.object = obj
        self.park = bool(swap_images)  # persistent data: park instead of hiding (module doc)
        if self.park:
            self._park()

    def _park(self) -> None:
        """No shadow, with persistent data: the plane shrunk to a point far below the surface, its image
        written (the swap every sample, as the surface's images do)."""
        self.alpha.write(self._buf.ravel())
        self.object.matrix_world = Matrix(PARKED.tolist())
        self.object.hide_render = False

    def _material(self) -> bpy.types.Material:
        mat = bpy.data.materials.new("crackgen_occluder")
        mat.use_nodes = True
        nt = mat.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        tex = nt.nodes.new("ShaderNodeTexImage")
        self.alpha.attach(tex)
        tex.extension = "CLIP"  # outside the pattern nothing blocks
        tex.interpolation = "Linear"
        clear = nt.nodes.new("ShaderNodeBsdfTransparent")
        block = nt.nodes.new("ShaderNodeBsdfDiffuse")
        block.inputs["Color"].default_value = (0.0, 0.0, 0.0, 1.0)
        mix = nt.nodes.new("ShaderNodeMixShader")
        nt.links.new(tex.outputs["Color"], mix.inputs["Fac"])
        nt.links.new(clear.outputs["BSDF"], mix.inputs[1])
        nt.links.new(block.outputs["BSDF"], mix.inputs[2])
        nt.links.new(mix.outputs["Shader"], out.inputs["Surface"])
        return mat

    def update(self, shadow: ShadowSpec, lights: list[LightSpec], alpha: np.ndarray | None) -> np.ndarray | None:
        """Show the occluder for this sample (or hide it); returns its world matrix when shown."""
        if not shadow.enabled or alpha is None:
            if self.park:
                self._park()
            else:
                self.object.hide_render = True
            return None
        if not 0 <= shadow.light_index < len(lights):
            raise ShadowError(f"shadow.light_index {shadow.light_index} is out of range for {len(lights)} lights")
        a = np.asarray(alpha, dtype=np.float32)
        if a.shape != (self.px, self.px):
            raise ShadowError(f"shadow alpha must be ({self.px}, {self.px}), got {a.shape}")
        self._buf[:, :3] = a.reshape(-1, 1)
        self.alpha.write(self._buf.ravel())
        M = occluder_matrix(shadow, lights[shadow.light_index])
        self.object.matrix_world = Matrix(M.tolist())
        self.object.hide_render = False
        return M
