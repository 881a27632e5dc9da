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
   * valid: 1 where the sensor measured something, else 0. With 5-channel
     models this lets the network tell "near" (0) from "no measurement" (0).
"""
from __future__ import annotations

import cv2
import numpy as np

from trainer.errors import TrainerInputError

DEFAULT_NEAR_M = 0.2
DEFAULT_FAR_M = 5.0


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


def normalise_depth(
    depth: np.ndarray,
    near_m: float = DEFAULT_NEAR_M,
    far_m: float = DEFAULT_FAR_M,
    mode: str = "fixed",
) -> tuple[np.ndarray, np.ndarray]:
    """Depth in metres (-1 = none) -> (depth channel in [0,1], valid channel 0/1)."""
    if mode not in ("fixed", "minmax"):
        raise TrainerInputError(f"depth normalisation mode must be 'fixed' or 'minmax', got {mode!r}")
    depth = np.asarray(depth, dtype=np.float32)
    ok = valid_mask(depth)
    if mode == "minmax" and ok.any():
        near_m, far_m = float(depth[ok].min()), float(depth[ok].max())
    if not far_m > near_m:
        far_m = near_m + 1e-6
    norm = np.zeros(depth.shape, dtype=np.float32)
    norm[ok] = np.clip((depth[ok] - near_m) / (far_m - near_m), 0.0, 1.0)
    return norm, ok.astype(np.float32)
