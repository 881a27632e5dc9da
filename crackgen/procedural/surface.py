"""Displaced quad-grid surface mesh: the one geometry the renderer and the ray caster share.

A regular ``g x g`` vertex grid spans [-size/2, size/2]^2 in the z = 0 plane; each vertex
is pushed along -z (into the surface) by the crack depth (m) of the crack map at its UV.

Why the depth is the *maximum over the vertex's footprint* (``sampling="footprint"``, the
default) and not a point sample: a crack narrower than the vertex spacing (384 vertices
over a 1024-texel map: 2.7 texels) falls between vertices, and bilinear point samples on
both sides keep only part of its depth (median 59% at the centreline, measured with
``centreline_depth_kept``), so deep narrow cracks rendered grey. Taking the max over the
square of one vertex spacing centred on each vertex puts the full depth on the vertex
nearest the centreline; the groove widens by at most half a spacing, and the part of the
crack slope the mesh still cannot hold goes to the normal map (``mesh_depth_map``).
``sampling="point"`` is the bilinear sample (the thesis mesh).  Vertex (i, j) has index ``j*g + i`` and UV (i/(g-1), j/(g-1)), with the
same u (= +x) / v (= +y) axes as the crack map.  Faces wind counter-clockwise seen from +z,
so normals point up towards the cameras.

Topology (faces, UVs) is constant per grid size and cached; only the vertices change per
sample, which is what the Blender worker ``foreach_set``s.
"""

from __future__ import annotations

import math
from functools import lru_cache
from pathlib import Path

import numpy as np
from numba import njit, prange
from scipy import ndimage

from crackgen.errors import CrackgenError
from crackgen.procedural.crackmap import CrackMap, depth_at_uv

__all__ = [
    "SurfaceError",
    "surface_uvs",
    "surface_faces",
    "surface_vertices",
    "with_steps",
    "with_relief",
    "mesh_depth_at_uv",
    "mesh_depth_map",
    "centreline_depth_kept",
    "SAMPLINGS",
    "surface_mesh",
    "export_mesh",
    "EXPORT_FORMATS",
]

EXPORT_FORMATS = (".ply", ".glb")
SAMPLINGS = ("footprint", "point")


class SurfaceError(CrackgenError, ValueError):
    """Bad surface-mesh arguments (names the field or file)."""


def _check_grid(grid_px: int) -> int:
    if int(grid_px) != grid_px or grid_px < 2:
        raise SurfaceError(f"surface.grid_px must be an integer >= 2, got {grid_px!r}")
    return int(grid_px)


@lru_cache(maxsize=8)
def surface_uvs(grid_px: int) -> np.ndarray:
    """(g*g, 2) float32 UVs, vertex (i, j) -> (i/(g-1), j/(g-1)); read-only, cached."""
    g = _check_grid(grid_px)
    t = np.linspace(0.0, 1.0, g)
    uu, vv = np.meshgrid(t, t)  # [j, i]
    uv = np.stack([uu.ravel(), vv.ravel()], axis=1).astype(np.float32)
    uv.setflags(write=False)
    return uv


@lru_cache(maxsize=8)
def surface_faces(grid_px: int) -> np.ndarray:
    """((g-1)^2 * 2, 3) int32 triangles, CCW seen from +z (normals +z); read-only, cached."""
    g = _check_grid(grid_px)
    j, i = np.mgrid[0 : g - 1, 0 : g - 1]
    v00 = (j * g + i).ravel()
    v10 = v00 + 1  # +x
    v01 = v00 + g  # +y
    v11 = v01 + 1
    tri = np.concatenate([np.stack([v00, v10, v11], 1), np.stack([v00, v11, v01], 1)], axis=0)
    faces = tri.astype(np.int32)
    faces.setflags(write=False)
    return faces


def _footprint_depth(cm: CrackMap, grid_px: int) -> CrackMap:
    """``cm`` with depth_m max-filtered over one vertex spacing (odd box of texels)."""
    spacing = cm.size_px / max(grid_px - 1, 1)  # texels between neighbouring vertices
    r = int(round(spacing / 2.0))
    if r < 1:
        return cm
    deep = ndimage.maximum_filter(cm.depth_m, size=2 * r + 1, mode="nearest")
    return _with_depth(cm, deep)


def _with_depth(cm: CrackMap, depth: np.ndarray) -> CrackMap:
    import dataclasses

    return dataclasses.replace(cm, depth_m=depth.astype(np.float32))


def surface_vertices(cm: CrackMap, grid_px: int, sampling: str = "footprint") -> np.ndarray:
    """(g*g, 3) float32 world-space vertices of the displaced grid for crack map ``cm`` (see module doc)."""
    if sampling not in SAMPLINGS:
        raise SurfaceError(f"surface sampling must be one of {', '.join(SAMPLINGS)}, got {sampling!r}")
    uv = surface_uvs(grid_px).astype(np.float64)
    src = _footprint_depth(cm, grid_px) if sampling == "footprint" else cm
    out = np.empty((uv.shape[0], 3), dtype=np.float32)
    out[:, 0] = (uv[:, 0] - 0.5) * cm.size_m
    out[:, 1] = (uv[:, 1] - 0.5) * cm.size_m
    out[:, 2] = 0.0 - depth_at_uv(src, uv[:, 0], uv[:, 1])  # 0 - d: no -0.0 on the flat part
    return out


def with_steps(vertices: np.ndarray, steps) -> np.ndarray:
    """``vertices`` (a ``surface_vertices`` grid) with each ``StepSpec``'s far side raised by its height
    (+z): kerbs and faulted slab edges. Between the levels the height ramps linearly over one vertex
    spacing centred on the step line, so the wall is a straight band along the line, not a staircase
    of grid cells (a hard per-vertex cut zigzags diagonal steps). The crack depths are those of
    ``vertices``: pass the step-free vertices to ``mesh_depth_map``, these to the renderer and ray
    caster. Without steps ``vertices`` itself is returned (no copy)."""
    if not steps:
        return vertices
    g = _check_grid(int(round(np.sqrt(len(vertices)))))
    if g * g != len(vertices):
        raise SurfaceError(f"with_steps: {len(vertices)} vertices are not a square grid")
    out = np.array(vertices, dtype=np.float32, copy=True)
    spacing = float(out[:, 0].max() - out[:, 0].min()) / (g - 1)
    for st in steps:
        dist = out[:, 0] * np.cos(st.angle_rad) + out[:, 1] * np.sin(st.angle_rad) - st.offset_m
        out[:, 2] += (st.height_m * np.clip(dist / spacing + 0.5, 0.0, 1.0)).astype(np.float32)
    return out


def with_relief(vertices: np.ndarray, relief_m: np.ndarray | None) -> np.ndarray:
    """``vertices`` with a texture-space relief map (``MaterialMaps.relief_m``, m, +z up) added at each vertex's UV:
    recessed mortar joints, whose edges then cast real shadows. The map is sampled bilinearly at texel centres
    (``[j, i]``, row j along v), like every map of the patch. Without a map ``vertices`` itself is returned."""
    if relief_m is None:
        return vertices
    g = _check_grid(int(round(np.sqrt(len(vertices)))))
    relief = np.asarray(relief_m, dtype=np.float32)
    if g * g != len(vertices) or relief.ndim != 2 or relief.shape[0] != relief.shape[1]:
        raise SurfaceError(f"with_relief: needs a square vertex grid and a square map, got {len(vertices)} "
                           f"vertices and a {relief.shape} map")
    t = np.arange(g, dtype=np.float64) / (g - 1) * relief.shape[0] - 0.5  # vertex UV in texel coordinates
    jj, ii = np.meshgrid(t, t, indexing="ij")
    dz = ndimage.map_coordinates(relief, [jj.ravel(), ii.ravel()], order=1, mode="nearest")
    out = np.array(vertices, dtype=np.float32, copy=True)
    out[:, 2] += dz.astype(np.float32)
    return out


def mesh_depth_at_uv(vertices: np.ndarray, grid_px: int, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Depth (m, >= 0 into the surface) of the rendered triangles at UVs: exact, on ``surface_faces``' split.

    Cell (i, j) holds triangles (v00, v10, v11) where a >= b and (v00, v11, v01) where b > a, with
    (a, b) the position inside the cell along u and v. (A compiled loop: a scene samples 3.4 M texels.)"""
    g = _check_grid(grid_px)
    z = np.ascontiguousarray(-np.asarray(vertices, dtype=np.float64)[:, 2].reshape(g, g))  # [j, i]
    u64, v64 = np.broadcast_arrays(np.asarray(u, dtype=np.float64), np.asarray(v, dtype=np.float64))
    out = _mesh_depth_kernel(z, np.ascontiguousarray(u64).ravel(), np.ascontiguousarray(v64).ravel())
    return out.reshape(u64.shape)


@njit(cache=True, parallel=True)
def _mesh_depth_kernel(z, u, v):  # pragma: no cover  (numba; same float64 operations, in the same order, as numpy)
    g = z.shape[0]
    out = np.empty(u.size, np.float32)
    for k in prange(u.size):
        x = min(max(u[k] * (g - 1), 0.0), g - 1.0)
        y = min(max(v[k] * (g - 1), 0.0), g - 1.0)
        i = min(int(math.floor(x)), g - 2)
        j = min(int(math.floor(y)), g - 2)
        a, b = x - i, y - j
        z00, z10, z01, z11 = z[j, i], z[j, i + 1], z[j + 1, i], z[j + 1, i + 1]
        if a >= b:
            out[k] = z00 + a * (z10 - z00) + b * (z11 - z10)
        else:
            out[k] = z00 + b * (z01 - z00) + a * (z11 - z01)
    return out


def mesh_depth_map(vertices: np.ndarray, grid_px: int, px: int) -> np.ndarray:
    """(px, px) float32 mesh depth (m) at texel centres of a px-texel map: what the mesh holds."""
    t = (np.arange(int(px), dtype=np.float64) + 0.5) / int(px)
    uu, vv = np.meshgrid(t, t)  # [j, i]
    return mesh_depth_at_uv(vertices, grid_px, uu, vv)


def centreline_depth_kept(cm: CrackMap, vertices: np.ndarray, grid_px: int) -> np.ndarray:
    """Mesh depth / crack-map depth at the crack map's skeleton texels (1 = all kept), for reports."""
    skel = cm.skeleton
    if skel is None:
        from fusion.measure.crack_length import skeleton

        skel = skeleton(cm.mask)
    jj, ii = np.nonzero(np.asarray(skel, bool) & (cm.depth_m > 0))
    n = cm.size_px
    held = mesh_depth_at_uv(vertices, grid_px, (ii + 0.5) / n, (jj + 0.5) / n)
    return (held / cm.depth_m[jj, ii]).astype(np.float64)


def surface_mesh(cm: CrackMap, grid_px: int):
    """trimesh.Trimesh of the displaced grid with UVs (TextureVisuals) and vertex normals."""
    import trimesh

    mesh = trimesh.Trimesh(
        vertices=surface_vertices(cm, grid_px),
        faces=np.asarray(surface_faces(grid_px)),
        visual=trimesh.visual.TextureVisuals(uv=np.array(surface_uvs(grid_px))),
        process=False,  # keep the vertex order: index j*g + i is part of the contract
    )
    _ = mesh.vertex_normals  # computed now so callers (and exports) get them
    return mesh


def export_mesh(mesh, path: str | Path) -> Path:
    """Write ``mesh`` to .ply or .glb (chosen by extension); returns the path."""
    p = Path(path)
    ext = p.suffix.lower()
    if ext not in EXPORT_FORMATS:
        raise SurfaceError(f"cannot export mesh to {p.name!r}: extension must be one of {', '.join(EXPORT_FORMATS)}")
    if not p.parent.exists():
        raise SurfaceError(f"cannot export mesh to {str(p)!r}: folder {str(p.parent)!r} does not exist")
    mesh.export(p, file_type=ext[1:])
    return p
