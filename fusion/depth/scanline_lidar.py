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

from fusion.depth.densify import valid_values


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


def random_scanline_lidar(gt_disp: np.ndarray, rng: np.random.Generator, spacing_px: tuple[float, float] = (4.0, 20.0),
                          sigma_px: tuple[float, float] = (0.05, 1.0), dropout: tuple[float, float] = (0.0, 0.3)
                          ) -> tuple[np.ndarray, dict[str, float]]:
    """``scanline_lidar`` with its quality drawn at random: line spacing (rows) uniform, noise
    log-uniform, dropout uniform. Returns the sparse map and the drawn parameters.

    Why: a rendered rig has one LiDAR, so a confidence CNN trained on it learns how
    good *that* LiDAR is relative to stereo instead of reading the images; drawing
    the density and noise per training scene makes the LiDAR's quality something to
    read from the evidence (the LiDAR-warped grey difference).
    """
    h = np.asarray(gt_disp).shape[0]
    spacing = float(rng.uniform(*spacing_px))
    sigma = float(np.exp(rng.uniform(np.log(sigma_px[0]), np.log(sigma_px[1]))))
    drop = float(rng.uniform(*dropout))
    lines = max(2, int(round(h / spacing)))
    return scanline_lidar(gt_disp, lines, rng, sigma, drop), {"lines": lines, "sigma_px": sigma, "dropout": drop}
