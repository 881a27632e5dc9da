"""Guided filter (He et al. 2010/2013), box-filter form: edge-preserving smoothing of p guided by I.

Per (2r+1)^2 window: q = a I + b with a = cov(I, p) / (var(I) + eps), b = mean(p) - a mean(I),
then a and b are averaged over the windows covering each pixel.  A colour guide (H, W, 3)
uses the 3x3 covariance of its channels.  OpenCV's ``cv2.ximgproc.guidedFilter`` is the same
filter but only ships with opencv-contrib, so the O(1)-per-pixel box form is written here
with ``cv2.boxFilter`` (normalised means, reflected borders: windows shrink to the image's
own content at the edges, like the reference implementation's N-normalised box sums).
"""

from __future__ import annotations

import cv2
import numpy as np

from fusion.errors import FusionError

__all__ = ["GuidedFilterError", "box_mean", "guided_filter"]


class GuidedFilterError(FusionError):
    """Bad guided-filter arguments (names the argument)."""


def box_mean(a: np.ndarray, r: int) -> np.ndarray:
    """Mean over the (2r+1)^2 window around each pixel, counting only pixels inside the image."""
    a = np.asarray(a, dtype=np.float64)
    k = (2 * int(r) + 1,) * 2
    s = cv2.boxFilter(a, -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
    n = cv2.boxFilter(np.ones(a.shape[:2]), -1, k, normalize=False, borderType=cv2.BORDER_CONSTANT)
    return s / (n[..., None] if a.ndim == 3 else n)


def guided_filter(guide: np.ndarray, p: np.ndarray, r: int, eps: float) -> np.ndarray:
    """Filter ``p`` (H, W) guided by ``guide`` (H, W) or (H, W, 3), window radius ``r``, regulariser ``eps``."""
    I = np.asarray(guide, dtype=np.float64)
    p = np.asarray(p, dtype=np.float64)
    if p.ndim != 2:
        raise GuidedFilterError(f"p must be a 2-D map, got shape {p.shape}")
    if I.shape[:2] != p.shape or I.ndim not in (2, 3) or (I.ndim == 3 and I.shape[2] != 3):
        raise GuidedFilterError(f"guide must be (H, W) or (H, W, 3) matching p {p.shape}, got {I.shape}")
    if int(r) != r or r < 1:
        raise GuidedFilterError(f"r must be an integer >= 1, got {r!r}")
    if not (np.isfinite(eps) and eps > 0):
        raise GuidedFilterError(f"eps must be > 0, got {eps!r}")
    mp = box_mean(p, r)
    if I.ndim == 2:
        mi = box_mean(I, r)
        var = box_mean(I * I, r) - mi * mi
        cov = box_mean(I * p, r) - mi * mp
        a = cov / (var + eps)
        b = mp - a * mi
        return box_mean(a, r) * I + box_mean(b, r)
    mi = box_mean(I, r)  # (H, W, 3)
    cov = box_mean(I * p[..., None], r) - mi * mp[..., None]
    sigma = np.empty(p.shape + (3, 3))
    for i in range(3):
        for j in range(i, 3):
            sigma[..., i, j] = sigma[..., j, i] = box_mean(I[..., i] * I[..., j], r) - mi[..., i] * mi[..., j]
    a = np.linalg.solve(sigma + eps * np.eye(3), cov[..., None])[..., 0]
    b = mp - (a * mi).sum(axis=-1)
    return (box_mean(a, r) * I).sum(axis=-1) + box_mean(b, r)
