"""Exact GT depth and crack mask in a camera view, by ray casting its pixel centres.

Why a ray cast and not a rasterised emission pass (the thesis's choice): the
lookup happens at the exact pixel-centre ray, so anti-aliasing cannot smear the
mask, and depth/mask/ToF share one code path on one mesh. A pixel is crack iff
the visible surface point's UV lies in a crack texel of the crack map.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from crackgen.procedural.crackmap import nearest_texel
from crackgen.sim.raycast import MeshRaycaster, RayHits
from fusion.camera import Camera


@dataclass
class ViewGroundTruth:
    depth: np.ndarray  # (H,W) float32 planar z, -1 where the ray misses the surface
    mask: np.ndarray  # (H,W) uint8 0/255
    uv: np.ndarray  # (H,W,2) hit UV, NaN on miss
    hits: RayHits


def mask_lookup(crack_mask: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Nearest-texel crack mask at UVs (crack-map convention: [j, i], i along u, row 0 at v = 0)."""
    ok = np.isfinite(uv).all(axis=-1)
    uv = np.nan_to_num(uv)
    return nearest_texel(crack_mask, uv[..., 0], uv[..., 1]) & ok


def view_ground_truth(camera: Camera, caster: MeshRaycaster, crack_mask: np.ndarray) -> ViewGroundTruth:
    origins, dirs, z_per_t = camera.pixel_rays()
    hits = caster.cast(origins, dirs)
    depth = np.where(hits.hit, hits.t * z_per_t, -1.0).astype(np.float32)
    shape = (camera.height, camera.width)
    uv = hits.uv.reshape(*shape, 2)
    mask = (mask_lookup(crack_mask, uv) * 255).astype(np.uint8)
    return ViewGroundTruth(depth=depth.reshape(shape), mask=mask, uv=uv, hits=hits)
