"""Points -> sparse depth map in a camera, with a z-buffer (thesis eq. 5.7-5.9).

P_C = [R|t] P_W, depth = Z_C; (u', v', w) = K P_C; pixel = round(u'/w, v'/w).
Pixel centres are integer coordinates (OpenCV), so "round to nearest" is
``floor(x + 0.5)``. Empty pixels are -1; where several points land on one
pixel the smallest depth wins. Values carried with the points (amplitude,
ring index, ...) are taken from the winning point, so every splatted channel
agrees with the depth channel.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from fusion.errors import FusionError
from fusion.geometry.camera import Camera


class ProjectionError(FusionError):
    """Inputs to a projection have the wrong shape."""


@dataclass
class SparseProjection:
    depth: np.ndarray  # (H,W) float32 planar depth, -1 where no point landed
    index: np.ndarray  # (H,W) int64 index of the winning input point, -1 where none
    values: dict[str, np.ndarray] = field(default_factory=dict)  # (H,W) float32 per channel, fill where none

    @property
    def filled(self) -> np.ndarray:
        return self.index >= 0


def pixel_indices(camera: Camera, points_world: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Flat pixel index (-1 when outside the image or behind the camera), row, col and depth per point."""
    uv, z = camera.project(points_world)
    finite = np.isfinite(uv).all(axis=1) & np.isfinite(z) & (z > 0)
    col = np.full(len(z), -1, dtype=np.int64)
    row = np.full(len(z), -1, dtype=np.int64)
    col[finite] = np.floor(uv[finite, 0] + 0.5).astype(np.int64)
    row[finite] = np.floor(uv[finite, 1] + 0.5).astype(np.int64)
    inside = finite & (col >= 0) & (col < camera.width) & (row >= 0) & (row < camera.height)
    flat = np.where(inside, row * camera.width + col, -1)
    return flat, row, z


def project_points(
    camera: Camera,
    points_world: np.ndarray,
    values: dict[str, np.ndarray] | None = None,
    fill: float = -1.0,
) -> SparseProjection:
    """Z-buffered splat of world points (NaN rows are ignored) into ``camera``."""
    pts = np.asarray(points_world, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3:
        raise ProjectionError(f"points_world must be (N,3), got {pts.shape}")
    values = values or {}
    for name, v in values.items():
        if len(v) != len(pts):
            raise ProjectionError(f"values[{name!r}] has {len(v)} entries for {len(pts)} points")
    flat, _, z = pixel_indices(camera, pts)
    keep = np.flatnonzero(flat >= 0)
    n_pix = camera.width * camera.height
    zbuf = np.full(n_pix, np.inf)
    np.minimum.at(zbuf, flat[keep], z[keep])
    # Winner per pixel: the kept point whose depth equals the buffer (first one on exact ties).
    win = keep[z[keep] == zbuf[flat[keep]]]
    index = np.full(n_pix, -1, dtype=np.int64)
    index[flat[win][::-1]] = win[::-1]  # reversed so the first tied point is written last
    filled = index >= 0
    depth = np.full(n_pix, -1.0, dtype=np.float32)
    depth[filled] = zbuf[filled]
    shape = (camera.height, camera.width)
    out_vals = {}
    for name, v in values.items():
        img = np.full(n_pix, fill, dtype=np.float32)
        img[filled] = np.asarray(v)[index[filled]]
        out_vals[name] = img.reshape(shape)
    return SparseProjection(depth=depth.reshape(shape), index=index.reshape(shape), values=out_vals)


def project_depth(camera: Camera, points_world: np.ndarray) -> np.ndarray:
    """(H,W) float32 sparse planar depth in ``camera``: smallest depth per pixel, -1 elsewhere."""
    return project_points(camera, points_world).depth


def reproject_depth(src: Camera, depth: np.ndarray, dst: Camera) -> np.ndarray:
    """Depth map of ``src`` (-1/0/inf = none) -> sparse depth in ``dst`` (back-project, then splat)."""
    if depth.shape != (src.height, src.width):
        raise ProjectionError(f"depth is {depth.shape}, camera expects {(src.height, src.width)}")
    pts = src.backproject(depth).reshape(-1, 3)
    pts = pts[np.isfinite(pts).all(axis=1)]
    return project_depth(dst, pts)
