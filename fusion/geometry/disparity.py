"""Depth <-> disparity for a rectified pair: d = f*B/Z (pixels), Z = f*B/d (metres).

Invalid stays invalid both ways: a non-positive or non-finite input, or a
non-positive result, becomes -1 in the output (the project's "no value").
``doffs_px`` is the Middlebury/ETH3D principal-point offset cx1 - cx0 of the
pair: Z = f*B/(d + doffs). Our own rigs have doffs = 0.
"""
from __future__ import annotations

import numpy as np

from fusion.errors import FusionError


class DisparityError(FusionError):
    """Bad focal length / baseline for a depth-disparity conversion."""


def _check(focal_px: float, baseline_m: float) -> None:
    if not (np.isfinite(focal_px) and focal_px > 0 and np.isfinite(baseline_m) and baseline_m > 0):
        raise DisparityError(f"focal_px ({focal_px}) and baseline_m ({baseline_m}) must be finite and > 0")


def depth_to_disparity(depth: np.ndarray, focal_px: float, baseline_m: float, doffs_px: float = 0.0) -> np.ndarray:
    """Planar depth (m) -> disparity (px), d = f*B/Z - doffs; float32, -1 invalid."""
    _check(focal_px, baseline_m)
    z = np.asarray(depth, dtype=np.float64)
    ok = np.isfinite(z) & (z > 0)
    out = np.full(z.shape, -1.0, dtype=np.float64)
    out[ok] = focal_px * baseline_m / z[ok] - doffs_px
    out[out <= 0] = -1.0
    return out.astype(np.float32)


def disparity_to_depth(disp: np.ndarray, focal_px: float, baseline_m: float, doffs_px: float = 0.0) -> np.ndarray:
    """Disparity (px) -> planar depth (m), Z = f*B/(d + doffs); float32, -1 invalid."""
    _check(focal_px, baseline_m)
    d = np.asarray(disp, dtype=np.float64)
    den = np.where(np.isfinite(d) & (d > 0), d + doffs_px, 0.0)
    ok = den > 0
    out = np.full(d.shape, -1.0, dtype=np.float64)
    out[ok] = focal_px * baseline_m / den[ok]
    return out.astype(np.float32)


def valid_values(a: np.ndarray) -> np.ndarray:
    """True where a depth/disparity map holds a measurement (finite and > 0; -1/0/inf/NaN are none)."""
    a = np.asarray(a)
    return np.isfinite(a) & (a > 0)
