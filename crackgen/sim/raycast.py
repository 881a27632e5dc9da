"""Vectorised ray casting on the sample's surface mesh (open3d RaycastingScene).

The renderer draws this very mesh, so GT depth, the GT mask and every depth
sensor come from the same geometry the camera sees. open3d is imported lazily:
the trainer never needs it.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class RayHits:
    hit: np.ndarray  # (N,) bool
    t: np.ndarray  # (N,) float64 distance along the unit ray (inf on miss)
    points: np.ndarray  # (N,3) world hit points (NaN on miss)
    normals: np.ndarray  # (N,3) geometric triangle normals (NaN on miss)
    uv: np.ndarray  # (N,2) interpolated texture UV at the hit (NaN on miss)
    triangle: np.ndarray  # (N,) int64 triangle index (-1 on miss)


class MeshRaycaster:
    """Ray caster over one triangle mesh with per-vertex UVs."""

    def __init__(self, vertices: np.ndarray, faces: np.ndarray, uvs: np.ndarray):
        import open3d as o3d

        self._o3d = o3d
        self.vertices = np.ascontiguousarray(vertices, dtype=np.float32)
        self.faces = np.ascontiguousarray(faces, dtype=np.uint32)
        self.uvs = np.asarray(uvs, dtype=np.float64)
        if self.vertices.ndim != 2 or self.vertices.shape[1] != 3:
            raise ValueError(f"vertices must be (N,3), got {self.vertices.shape}")
        if self.uvs.shape != (len(self.vertices), 2):
            raise ValueError(f"uvs must be ({len(self.vertices)},2), got {self.uvs.shape}")
        self.scene = o3d.t.geometry.RaycastingScene()
        self.scene.add_triangles(o3d.core.Tensor(self.vertices), o3d.core.Tensor(self.faces))

    def cast(self, origins: np.ndarray, directions: np.ndarray) -> RayHits:
        """Cast rays with unit ``directions``; returns first hits."""
        o3d = self._o3d
        rays = np.concatenate([origins, directions], axis=1).astype(np.float32)
        ans = self.scene.cast_rays(o3d.core.Tensor(rays))
        t = ans["t_hit"].numpy().astype(np.float64)
        hit = np.isfinite(t)
        tri = ans["primitive_ids"].numpy().astype(np.int64)
        bary = ans["primitive_uvs"].numpy().astype(np.float64)
        normals = ans["primitive_normals"].numpy().astype(np.float64)
        # Gather over all rays (misses use triangle 0, then get NaN): no boolean-mask copies
        # in the common case where every ray hits, which is ~2x faster for large batches.
        f = self.faces[np.where(hit, tri, 0)]
        w = np.stack([1.0 - bary[:, 0] - bary[:, 1], bary[:, 0], bary[:, 1]], axis=1)
        uv = np.einsum("nk,nkc->nc", w, self.uvs[f])
        with np.errstate(invalid="ignore"):
            points = origins + directions * t[:, None]
        if not hit.all():
            miss = ~hit
            tri[miss] = -1
            points[miss] = np.nan
            uv[miss] = np.nan
            normals[miss] = np.nan
        return RayHits(hit=hit, t=t, points=points, normals=normals, uv=uv, triangle=tri)
