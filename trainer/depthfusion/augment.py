"""Stereo-failure augmentation for the LiDAR/stereo confidence CNN.

Why: the renders are flat, textured crack surfaces, where SGBM is right almost
everywhere and fails only at scattered pixels. Real scenes have occlusions,
depth edges and textureless areas where SGBM fails over whole regions (on
Middlebury Cones and ETH3D it is worse than an interpolated LiDAR on 56-70% of
pixels). A CNN trained on the renders alone learns a prior ("stereo is right")
instead of reading the evidence, and picks stereo on 86-92% of real pixels.

So, with probability ``p`` per training patch, a few random elliptic regions of
the *stereo* channel get one of SGBM's region failures:

* ``offset``: a constant wrong disparity step (foreground fattening at an
  occlusion, a repeated-texture mismatch), 1-8 px either way;
* ``flat``: a fronto-parallel fill (what hole filling does across a textureless
  area): the region's median plus up to +-2 px;
* ``speckle``: per-pixel noise, sigma 0.5-3 px (weak texture).

The target C* = exp(-|D - D_GT|) is computed from the corrupted map, so the
labels stay exact. The lidar variant's grey difference warps by the LiDAR
disparity and does not depend on stereo, so a patch is corrupted after it is
cut (``corrupt_stereo``). The lidar4 variant also carries the difference warped
by the stereo disparity: there the failure is pasted into the whole scene's
stereo map inside the patch window before the patch is cut, and that channel
is recomputed from the corrupted map (``corrupt_scene_stereo``), so the
photometric evidence of the failure is what a real SGBM failure would show.
The ToF variant is not allowed: its only grey difference warps by stereo and
its recipe's ToF is not the failure case this targets.
"""
from __future__ import annotations

import cv2
import numpy as np

from fusion.geometry.stereo import left_right_difference

FAILURE_KINDS = ("offset", "flat", "speckle")


def failure_mask(size: int, rng: np.random.Generator) -> np.ndarray:
    """(size,size) bool: 1-3 random filled ellipses, semi-axes 2 px to size/3."""
    m = np.zeros((size, size), np.uint8)
    for _ in range(int(rng.integers(1, 4))):
        centre = (int(rng.integers(0, size)), int(rng.integers(0, size)))
        axes = tuple(int(a) for a in rng.uniform(2, max(size / 3, 3), 2))
        cv2.ellipse(m, centre, axes, float(rng.uniform(0, 180)), 0, 360, 1, thickness=-1)
    return m.astype(bool)


def corrupt_stereo(x: np.ndarray, rng: np.random.Generator, p: float) -> tuple[np.ndarray, dict]:
    """(patch with channel 0 corrupted in random regions, {kind, pixels}); ``x`` is (P,P,C), untouched.

    With probability 1 - p the patch comes back unchanged (kind ``none``).
    Values stay positive: a disparity <= 0 would read as "no value".
    """
    if not 0.0 <= p <= 1.0:
        raise ValueError(f"stereo failure probability must be in [0, 1], got {p}")
    if rng.random() >= p:
        return x, {"kind": "none", "pixels": 0}
    size = x.shape[0]
    region = failure_mask(size, rng) & np.isfinite(x[..., 0]) & (x[..., 0] > 0)
    kind = FAILURE_KINDS[int(rng.integers(len(FAILURE_KINDS)))]
    if not region.any():
        return x, {"kind": "none", "pixels": 0}
    out = x.astype(np.float32, copy=True)
    d = out[..., 0]
    if kind == "offset":
        d[region] += np.float32(rng.choice([-1.0, 1.0]) * rng.uniform(1.0, 8.0))
    elif kind == "flat":
        d[region] = np.float32(np.median(d[region]) + rng.uniform(-2.0, 2.0))
    else:
        d[region] += rng.normal(0.0, rng.uniform(0.5, 3.0), int(region.sum())).astype(np.float32)
    d[region] = np.maximum(d[region], np.float32(0.1))
    return out, {"kind": kind, "pixels": int(region.sum())}



def corrupt_scene_stereo(x: np.ndarray, grey: tuple[np.ndarray, np.ndarray], x0: int, y0: int, size: int,
                         rng: np.random.Generator, p: float) -> tuple[np.ndarray, dict]:
    """lidar4: (scene stack with a stereo failure pasted inside the ``size`` window at (x0, y0)
    and channel 3, the stereo-warped grey difference, recomputed from the corrupted map, {kind,
    pixels}); ``x`` is (H,W,4) and untouched. The draws are those of ``corrupt_stereo``."""
    window, info = corrupt_stereo(x[y0:y0 + size, x0:x0 + size], rng, p)
    if info["kind"] == "none":
        return x, info
    out = x.copy()
    out[y0:y0 + size, x0:x0 + size, 0] = window[..., 0]
    out[..., 3] = left_right_difference(grey[0], grey[1], out[..., 0])
    return out, info
