"""Depth channel handling shared by synthetic shards and real RGB-D folders.

Why one module: the network must see depth normalised *the same way* whatever
its source, otherwise a model trained on synthetic depth reads real depth on a
different scale.

Conventions (see DESIGN.md): depth is planar z in metres, float32, and ``-1``
means "no value" in every depth/disparity map. Real maps also use 0, ``inf`` or
NaN for "no value"; :func:`valid_mask` treats all of these as invalid.

Pipeline for a real map:

1. ``disparity_to_depth``: ``Z = f * B / d`` with ``f`` in pixels of the map the
   disparity was measured in and ``B`` in metres (``d <= 0`` or non-finite ->
   invalid). Depth maps stored as integers are scaled by ``depth_scale`` (e.g.
   0.001 for 16-bit millimetre PNGs).
2. ``align_to_rgb``: resize (nearest neighbour, aspect kept, fit inside) and
   centre-pad with -1 to the RGB size, so invalid pixels never bleed into valid
   ones and no depth value is invented by interpolation.
3. ``normalise_depth``: returns the two network channels

   * depth: ``clip((Z - near) / (far - near), 0, 1)`` on valid pixels, **0 on
     invalid pixels** (``mode="fixed"``, default near=0.2 m, far=5.0 m), or the
     per-image min..max of the valid pixels (``mode="minmax"``) when the metric
     scale of a sensor is unknown;
   * or local relief (``mode="relief"``, see :func:`relief_mm`): height above
     the local surface in millimetres, ``clip(mm / range_mm, -1, 1)`` (default
     +-20 mm), 0 on invalid pixels. A 10 mm deep crack reads -0.5 here but only
     0.002 in ``fixed`` mode, where the 4-15 mm relief is 0.1-0.3% of 0.2-5 m;
   * valid: 1 where the sensor measured something, else 0. With 5-channel
     models this lets the network tell "near" (0) from "no measurement" (0).
"""
from __future__ import annotations

import cv2
import numpy as np

from trainer.core.errors import TrainerInputError

DEFAULT_NEAR_M = 0.2
DEFAULT_FAR_M = 5.0
DEPTH_NORMS = ("fixed", "minmax", "relief")
RELIEF_METHODS = ("lowpass", "plane")
DEFAULT_RELIEF = "lowpass"
DEFAULT_RELIEF_RANGE_MM = 20.0
DEFAULT_RELIEF_SIGMA = 0.05  # low-pass sigma as a fraction of the shorter image side
_MIN_NOISE_M = 0.5e-3  # robust passes never call residuals under 0.5 mm outliers


def valid_mask(depth: np.ndarray) -> np.ndarray:
    """True where a depth/disparity value is a real measurement (> 0 and finite)."""
    return np.isfinite(depth) & (depth > 0)


def disparity_to_depth(disp: np.ndarray, focal_px: float, baseline_m: float) -> np.ndarray:
    """Z = f*B/d in metres; invalid disparities (<= 0, inf, NaN) become -1."""
    if focal_px <= 0 or baseline_m <= 0:
        raise TrainerInputError(f"focal_px ({focal_px}) and baseline_m ({baseline_m}) must be > 0")
    disp = np.asarray(disp, dtype=np.float32)
    ok = valid_mask(disp)
    out = np.full(disp.shape, -1.0, dtype=np.float32)
    out[ok] = (focal_px * baseline_m) / disp[ok]
    return out


def scaled_depth(raw: np.ndarray, depth_scale: float) -> np.ndarray:
    """Raw depth counts * scale -> metres; 0/negative/non-finite become -1."""
    raw = np.asarray(raw, dtype=np.float32)
    ok = valid_mask(raw)
    out = np.full(raw.shape, -1.0, dtype=np.float32)
    out[ok] = raw[ok] * np.float32(depth_scale)
    return out


def align_to_rgb(depth: np.ndarray, rgb_hw: tuple[int, int]) -> np.ndarray:
    """Nearest-neighbour resize (aspect kept, fit inside) + centre pad with -1.

    Invalid pixels stay -1 and never mix with valid ones, because nearest
    neighbour copies values instead of averaging them.
    """
    H, W = rgb_hw
    h, w = depth.shape
    if (h, w) == (H, W):
        return depth.astype(np.float32, copy=False)
    s = min(H / h, W / w)
    nh, nw = max(1, min(H, round(h * s))), max(1, min(W, round(w * s)))
    resized = cv2.resize(depth.astype(np.float32), (nw, nh), interpolation=cv2.INTER_NEAREST)
    out = np.full((H, W), -1.0, dtype=np.float32)
    top, left = (H - nh) // 2, (W - nw) // 2
    out[top:top + nh, left:left + nw] = resized
    return out


def _inliers(resid: np.ndarray, ok: np.ndarray, k: float = 3.0) -> np.ndarray:
    """Valid pixels whose residual is within k robust sigmas (MAD), never tighter than 0.5 mm."""
    r = resid[ok]
    sigma = 1.4826 * float(np.median(np.abs(r - np.median(r)))) if r.size else 0.0
    return ok & (np.abs(resid) <= k * max(sigma, _MIN_NOISE_M))


def _plane_reference(depth: np.ndarray, ok: np.ndarray, passes: int = 2) -> np.ndarray:
    """Depth of the best plane, fitted as 1/Z = a*u + b*v + c on valid pixels.

    Why inverse depth: a world plane seen by a pinhole camera has 1/Z exactly
    linear in the pixel coordinates (Z itself is not, once the plane is
    tilted), so no intrinsics are needed. Each extra pass refits on the
    inliers of the previous one, so cracks and clutter do not pull the plane.
    """
    H, W = depth.shape
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    u, v = (u - W / 2) / max(H, W), (v - H / 2) / max(H, W)
    A = np.stack([u, v, np.ones_like(u)], -1)
    inv = np.where(ok, 1.0 / np.where(ok, depth, 1.0), 0.0)
    use = ok
    ref = np.full(depth.shape, float(np.median(depth[ok])))
    for _ in range(passes + 1):
        if use.sum() < 3:
            break
        coef, *_ = np.linalg.lstsq(A[use], inv[use], rcond=None)
        plane_inv = A @ coef
        if not np.all(plane_inv[ok] > 0):
            break  # degenerate fit (e.g. a few collinear points): keep the last good reference
        ref = 1.0 / np.where(plane_inv > 0, plane_inv, np.inf)
        use = _inliers(depth - ref, ok)
    return ref


def _lowpass_reference(depth: np.ndarray, ok: np.ndarray, sigma_frac: float, passes: int = 2) -> np.ndarray:
    """Local plane per pixel by first-order Gaussian normalised convolution (Knutsson & Westin).

    Each pixel gets a weighted least-squares plane in inverse depth, the
    weights being a Gaussian window times validity; outside the image and on
    holes the weight is 0. So holes and sparse samples (ToF, LiDAR) never count
    as zero depth, a tilted plane is reproduced exactly (even at the borders,
    where a plain blur is biased), and only curvature on the scale of the
    window remains. Each extra pass drops the outliers of the last one (the
    crack itself), so a wide crack is not half-absorbed into its own reference.
    """
    H, W = depth.shape
    sigma = max(2.0, sigma_frac * min(H, W))
    v, u = np.mgrid[0:H, 0:W].astype(np.float64)
    u, v = (u - W / 2) / sigma, (v - H / 2) / sigma
    inv = np.where(ok, 1.0 / np.where(ok, depth, 1.0), 0.0)

    # Blurring at 1/f resolution (box-average down, bilinear up) keeps large windows cheap; every
    # moment below is linear in the same weights, so a plane is still reproduced exactly.
    f = max(1, int(sigma // 4))
    small = (max(1, W // f), max(1, H // f))

    def blur(a: np.ndarray) -> np.ndarray:
        if f == 1:
            return cv2.GaussianBlur(a, (0, 0), sigma, borderType=cv2.BORDER_CONSTANT)
        lo = cv2.resize(a, small, interpolation=cv2.INTER_AREA)
        lo = cv2.GaussianBlur(lo, (0, 0), sigma / f, borderType=cv2.BORDER_CONSTANT)
        return cv2.resize(lo, (W, H), interpolation=cv2.INTER_LINEAR)

    use = ok
    ref = np.full(depth.shape, float(np.median(depth[ok])))
    for _ in range(passes + 1):
        w = use.astype(np.float64)
        if not w.any():
            break
        s1, su, sv = blur(w), blur(w * u), blur(w * v)
        suu, suv, svv = blur(w * u * u), blur(w * u * v), blur(w * v * v)
        sz, szu, szv = blur(w * inv), blur(w * inv * u), blur(w * inv * v)
        # solve [[suu suv su] [suv svv sv] [su sv s1]] (a, b, c) = (szu, szv, sz) per pixel (Cramer)
        c00, c01, c02 = svv * s1 - sv * sv, sv * su - suv * s1, suv * sv - svv * su
        det = suu * c00 + suv * c01 + su * c02
        # where the window holds too few (or collinear) samples for a plane, use the weighted mean
        good = det > 1e-9 * np.maximum(s1, 1e-300) ** 3
        d = np.where(good, det, 1.0)
        a = (szu * c00 + szv * c01 + sz * c02) / d
        b = (szu * (sv * su - suv * s1) + szv * (suu * s1 - su * su) + sz * (suv * su - suu * sv)) / d
        c = (szu * (suv * sv - svv * su) + szv * (su * suv - suu * sv) + sz * (suu * svv - suv * suv)) / d
        plane = a * u + b * v + c
        mean = sz / np.where(s1 > 0, s1, 1.0)
        plane = np.where(good, plane, mean)
        covered = (s1 > 1e-12) & (plane > 0)
        ref = np.where(covered, 1.0 / np.where(covered, plane, 1.0), ref)
        use = _inliers(depth - ref, ok)
    return ref


def relief_mm(depth: np.ndarray, method: str = DEFAULT_RELIEF, sigma_frac: float = DEFAULT_RELIEF_SIGMA
              ) -> tuple[np.ndarray, np.ndarray]:
    """(height above the local surface in mm, valid mask); 0 on invalid pixels.

    Positive is toward the camera, so a crack is negative. ``method``:

    * ``lowpass`` (default): reference = robust Gaussian normalised
      convolution (``sigma_frac`` x shorter side). Follows curved or warped
      surfaces (columns, tunnel linings, bowed slabs) as well as tilted ones;
    * ``plane``: reference = robust plane in inverse depth. Exact for flat
      surfaces at any tilt, but leaves a curved surface's sag in the relief,
      which on a 1 m wide view of a gentle curve already exceeds +-20 mm.
    """
    if method not in RELIEF_METHODS:
        raise TrainerInputError(f"relief method must be one of {RELIEF_METHODS}, got {method!r}")
    depth = np.asarray(depth, dtype=np.float32)
    ok = valid_mask(depth)
    out = np.zeros(depth.shape, dtype=np.float32)
    if not ok.any():
        return out, ok
    ref = _plane_reference(depth, ok) if method == "plane" else _lowpass_reference(depth, ok, sigma_frac)
    out[ok] = ((ref[ok] - depth[ok]) * 1000.0).astype(np.float32)
    return out, ok


def normalise_depth(
    depth: np.ndarray,
    near_m: float = DEFAULT_NEAR_M,
    far_m: float = DEFAULT_FAR_M,
    mode: str = "fixed",
    relief: str = DEFAULT_RELIEF,
    relief_range_mm: float = DEFAULT_RELIEF_RANGE_MM,
    relief_sigma: float = DEFAULT_RELIEF_SIGMA,
) -> tuple[np.ndarray, np.ndarray]:
    """Depth in metres (-1 = none) -> (depth channel, valid channel 0/1).

    The depth channel is in [0,1] for ``fixed``/``minmax`` and in [-1,1] for
    ``relief``; it is 0 on invalid pixels in every mode.
    """
    if mode not in DEPTH_NORMS:
        raise TrainerInputError(f"depth normalisation mode must be one of {DEPTH_NORMS}, got {mode!r}")
    depth = np.asarray(depth, dtype=np.float32)
    if mode == "relief":
        if not relief_range_mm > 0:
            raise TrainerInputError(f"relief range must be > 0 mm, got {relief_range_mm}")
        mm, ok = relief_mm(depth, relief, relief_sigma)
        return np.clip(mm / np.float32(relief_range_mm), -1.0, 1.0).astype(np.float32), ok.astype(np.float32)
    ok = valid_mask(depth)
    if mode == "minmax" and ok.any():
        near_m, far_m = float(depth[ok].min()), float(depth[ok].max())
    if not far_m > near_m:
        far_m = near_m + 1e-6
    norm = np.zeros(depth.shape, dtype=np.float32)
    norm[ok] = np.clip((depth[ok] - near_m) / (far_m - near_m), 0.0, 1.0)
    return norm, ok.astype(np.float32)
