"""Sparse LiDAR from a dense GT disparity: the real-data check of the LiDAR/stereo fusion.

Real stereo sets (Middlebury, ETH3D) have GT disparity but no LiDAR. As the
issue asks, a LiDAR is simulated by sampling the GT along ``lines``
horizontal scan lines, evenly spaced over the rows, one return per column
with a random ``dropout``, plus Gaussian range noise expressed in disparity
pixels. Rows between the lines stay -1, as in a real 16-64-beam scan
projected into a camera. All draws come from the passed Generator.
"""
from __future__ import annotations

import numpy as np

from fusion.densify import valid_values


def scanline_lidar(gt_disp: np.ndarray, lines: int, rng: np.random.Generator, sigma_px: float = 0.25,
                   dropout: float = 0.1) -> np.ndarray:
    """(H,W) float32 sparse disparity: GT + N(0, sigma) on ``lines`` rows, -1 elsewhere / where GT has none."""
    gt = np.asarray(gt_disp, dtype=np.float32)
    if gt.ndim != 2 or lines < 1 or not 0 <= dropout < 1 or sigma_px < 0:
        raise ValueError(f"scanline_lidar: need a 2-D map, lines >= 1, 0 <= dropout < 1, sigma >= 0 "
                         f"(got shape {gt.shape}, lines {lines}, dropout {dropout}, sigma {sigma_px})")
    h, w = gt.shape
    rows = np.unique(np.linspace(0, h - 1, lines).round().astype(int))
    out = np.full((h, w), -1.0, dtype=np.float32)
    hit = valid_values(gt[rows]) & (rng.random((len(rows), w)) >= dropout)
    noisy = gt[rows] + rng.normal(0.0, sigma_px, (len(rows), w)).astype(np.float32)
    out[rows] = np.where(hit & (noisy > 0), noisy, -1.0)
    return out
