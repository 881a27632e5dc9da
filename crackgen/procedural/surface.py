"""Displaced quad-grid surface mesh: the one geometry the renderer and the ray caster share.

A regular ``g x g`` vertex grid spans [-size/2, size/2]^2 in the z = 0 plane; each vertex
is pushed along -z (into the surface) by the crack depth (m) sampled bilinearly from the
crack map at its UV.  Vertex (i, j) has index ``j*g + i`` and UV (i/(g-1), j/(g-1)), with the
same u (= +x) / v (= +y) axes as the crack map.  Faces wind counter-clockwise seen from +z,
so normals point up towards the cameras.

Topology (faces, UVs) is constant per grid size and cached; only the vertices change per
sample, which is what the Blender worker ``foreach_set``s.
"""

from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import numpy as np

from crackgen.errors import CrackgenError
from crackgen.procedural.crackmap import CrackMap, depth_at_uv

__all__ = [
    "SurfaceError",
    "surface_uvs",
    "surface_faces",
    "surface_vertices",
    "surface_mesh",
    "export_mesh",
    "EXPORT_FORMATS",
]

EXPORT_FORMATS = (".ply", ".glb")


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


def surface_vertices(cm: CrackMap, grid_px: int) -> np.ndarray:
    """(g*g, 3) float32 world-space vertices of the displaced grid for crack map ``cm``."""
    uv = surface_uvs(grid_px).astype(np.float64)
    out = np.empty((uv.shape[0], 3), dtype=np.float32)
    out[:, 0] = (uv[:, 0] - 0.5) * cm.size_m
    out[:, 1] = (uv[:, 1] - 0.5) * cm.size_m
    out[:, 2] = 0.0 - depth_at_uv(cm, uv[:, 0], uv[:, 1])  # 0 - d: no -0.0 on the flat part
    return out


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
