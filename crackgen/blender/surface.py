"""The cracked surface in Blender: one mesh (fixed grid topology) and one PBR material.

Why built once: the grid's triangles and UVs never change for a given ``grid_px``,
so only vertex positions (``foreach_set('co')``) and texture pixels
(``image.pixels.foreach_set``) are written per sample. The mesh is made from
``crackgen.procedural.surface``'s own triangles, so Cycles renders exactly the geometry the ray
caster sees (passing quads would let Blender pick other diagonals).

Colour spaces: the material maps are linear floats, so albedo is tagged
``Linear Rec.709`` (Blender's scene-linear, no transfer function applied twice);
roughness and the tangent-space normal map are ``Non-Color``.
"""
from __future__ import annotations

from typing import Protocol

import bpy
import numpy as np

from crackgen.blender.images import ImageSlot
from crackgen.errors import CrackgenError
from crackgen.procedural.surface import surface_faces, surface_uvs


class SurfaceUpdateError(CrackgenError, ValueError):
    """Arrays that do not fit the live surface (names the array and the expected shape)."""


class MapsLike(Protocol):
    albedo: np.ndarray  # (T,T,3) float32 linear RGB, row 0 = v = 0
    roughness: np.ndarray  # (T,T) float32
    normal: np.ndarray  # (T,T,3) float32 encoded (n + 1) / 2, OpenGL tangent space


class LiveSurface:
    """Surface mesh object + Principled BSDF driven by three float images."""

    def __init__(self, scene: bpy.types.Scene, grid_px: int, texture_px: int, swap_images: bool = False):
        self.grid_px = int(grid_px)
        self.texture_px = int(texture_px)
        faces = np.asarray(surface_faces(self.grid_px))
        uvs = np.asarray(surface_uvs(self.grid_px), dtype=np.float32)
        g = self.grid_px
        t = np.linspace(-0.5, 0.5, g, dtype=np.float32)
        flat = np.stack([np.tile(t, g), np.repeat(t, g), np.zeros(g * g, np.float32)], 1)

        mesh = bpy.data.meshes.new("crackgen_surface")
        mesh.vertices.add(len(flat))
        mesh.vertices.foreach_set("co", flat.ravel())
        mesh.loops.add(faces.size)
        mesh.loops.foreach_set("vertex_index", faces.ravel().astype(np.int32))
        mesh.polygons.add(len(faces))
        mesh.polygons.foreach_set("loop_start", np.arange(0, faces.size, 3, dtype=np.int32))
        uv = mesh.uv_layers.new(name="UVMap")
        uv.data.foreach_set("uv", uvs[faces.ravel()].ravel())
        mesh.update(calc_edges=True)
        mesh.validate(verbose=False)
        mesh.shade_smooth()
        self.mesh = mesh
        self.n_vertices = len(flat)

        T = self.texture_px
        # swap_images: two images per map, for persistent data (see crackgen.blender.images)
        self.albedo = ImageSlot("crackgen_albedo", T, "Linear Rec.709", swap_images)
        self.roughness = ImageSlot("crackgen_roughness", T, "Non-Color", swap_images)
        self.normal = ImageSlot("crackgen_normal", T, "Non-Color", swap_images)
        self._buf = np.ones((T * T, 4), np.float32)
        self.material = self._material()
        mesh.materials.append(self.material)
        obj = bpy.data.objects.new("crackgen_surface", mesh)
        scene.collection.objects.link(obj)
        self.object = obj

    def _material(self) -> bpy.types.Material:
        mat = bpy.data.materials.new("crackgen_surface")
        mat.use_nodes = True
        nt = mat.node_tree
        nt.nodes.clear()
        out = nt.nodes.new("ShaderNodeOutputMaterial")
        bsdf = nt.nodes.new("ShaderNodeBsdfPrincipled")
        texs = {}
        for key, img in (("albedo", self.albedo), ("roughness", self.roughness), ("normal", self.normal)):
            tex = nt.nodes.new("ShaderNodeTexImage")
            img.attach(tex)
            tex.interpolation = "Linear"
            tex.extension = "EXTEND"
            texs[key] = tex
        nmap = nt.nodes.new("ShaderNodeNormalMap")
        nmap.space = "TANGENT"
        nmap.uv_map = "UVMap"
        nt.links.new(texs["albedo"].outputs["Color"], bsdf.inputs["Base Color"])
        nt.links.new(texs["roughness"].outputs["Color"], bsdf.inputs["Roughness"])
        nt.links.new(texs["normal"].outputs["Color"], nmap.inputs["Color"])
        nt.links.new(nmap.outputs["Normal"], bsdf.inputs["Normal"])
        nt.links.new(bsdf.outputs["BSDF"], out.inputs["Surface"])
        return mat

    def _set_image(self, img: ImageSlot, name: str, arr: np.ndarray, channels: int) -> None:
        T = self.texture_px
        a = np.asarray(arr, dtype=np.float32)
        want = (T, T) if channels == 1 else (T, T, channels)
        if a.shape != want:
            raise SurfaceUpdateError(f"material map {name!r} must have shape {want}, got {a.shape}")
        # Blender images are stored bottom row first, like our maps (row 0 = v = 0): no flip.
        self._buf[:, :3] = a.reshape(T * T, -1)
        img.write(self._buf.ravel())

    def update(self, vertices: np.ndarray, maps: MapsLike) -> None:
        v = np.asarray(vertices, dtype=np.float32)
        if v.shape != (self.n_vertices, 3):
            raise SurfaceUpdateError(f"vertices must have shape ({self.n_vertices}, 3) for grid_px={self.grid_px}, got {v.shape}")
        self.mesh.vertices.foreach_set("co", v.ravel())
        self.mesh.update()
        self._set_image(self.albedo, "albedo", maps.albedo, 3)
        self._set_image(self.roughness, "roughness", maps.roughness, 1)
        self._set_image(self.normal, "normal", maps.normal, 3)
