"""Sparse disparity/depth -> dense map by interpolation (the default LiDAR and ToF densifier).

``normconv`` (default): multi-scale normalised convolution (Knutsson & Westin
1993): at Gaussian scales 1, 2, 4, ... 64 px, a hole takes the Gaussian-weighted
mean of the measured pixels at the smallest scale where they weigh at least
5%. It is a few OpenCV blurs per map, so scenes are prepared in milliseconds.

Delaunay-linear interpolation (scipy) was tried and dropped: measured pixels
lie on the integer grid, the triangulation is full of degenerate triangles,
and point location took 5-100 s per 256x192 map here.

Why densify: the confidence CNN and the fusion rules compare two candidate values at
every pixel, but LiDAR (a few % of pixels) and a reprojected low-resolution
ToF leave holes; ``nearest`` (distance transform) is the cheapest fill and
also the fallback where no scale reaches a hole. A stronger completion (e.g. PENet) plugs in instead by
passing its dense map from a file (see ``trainer.depthfusion.data``).
"""
from __future__ import annotations

import cv2
import numpy as np
from scipy.ndimage import distance_transform_edt

from fusion.errors import FusionError
from fusion.geometry.disparity import valid_values

METHODS = ("normconv", "nearest")
NORMCONV_SIGMAS_PX = (1.0, 2.0, 4.0, 8.0, 16.0, 32.0, 64.0)
NORMCONV_MIN_SUPPORT = 0.05  # Gaussian-weighted fraction of measured pixels a scale needs to fill a pixel


class DensifyError(FusionError):
    """Unknown interpolation method or a map that is not 2-D."""


def fill_nearest(a: np.ndarray, valid: np.ndarray | None = None) -> np.ndarray:
    """Every invalid pixel takes the value of its nearest valid pixel (float32); all -1 if none is valid."""
    a = np.asarray(a, dtype=np.float32)
    ok = valid_values(a) if valid is None else valid
    if not ok.any():
        return np.full(a.shape, -1.0, dtype=np.float32)
    if ok.all():
        return a.copy()
    _, (rows, cols) = distance_transform_edt(~ok, return_indices=True)
    return a[rows, cols].astype(np.float32)


def normalized_convolution(a: np.ndarray, ok: np.ndarray) -> np.ndarray:
    """Multi-scale normalised convolution fill of the pixels where ``ok`` is False (float32)."""
    v = np.where(ok, a, 0.0).astype(np.float32)
    w = ok.astype(np.float32)
    out = np.where(ok, a, 0.0).astype(np.float32)
    todo = ~ok
    for sigma in NORMCONV_SIGMAS_PX:
        if not todo.any():
            break
        k = int(2 * round(3 * sigma) + 1)
        num = cv2.GaussianBlur(v, (k, k), sigma, borderType=cv2.BORDER_CONSTANT)
        den = cv2.GaussianBlur(w, (k, k), sigma, borderType=cv2.BORDER_CONSTANT)
        take = todo & (den >= NORMCONV_MIN_SUPPORT)
        out[take] = num[take] / den[take]
        todo &= ~take
    if todo.any():
        out[todo] = fill_nearest(a, ok)[todo]
    return out


def interpolate_sparse(sparse: np.ndarray, method: str = "normconv") -> np.ndarray:
    """Dense float32 map from a sparse one (``normconv`` or ``nearest``). Measured pixels keep
    their values. All -1 if nothing is measured."""
    if method not in METHODS:
        raise DensifyError(f"unknown densify method {method!r}; choose from {', '.join(METHODS)}")
    a = np.asarray(sparse, dtype=np.float32)
    if a.ndim != 2:
        raise DensifyError(f"expected a 2-D map, got shape {a.shape}")
    ok = valid_values(a)
    if method == "nearest" or ok.sum() < 3 or ok.all():
        return fill_nearest(a, ok)
    return normalized_convolution(a, ok)
