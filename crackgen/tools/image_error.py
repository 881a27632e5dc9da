"""Image error of a render against a high-sample reference of the same sample.

Why these three: PSNR on linear RGB is the path tracer's own noise measure; SSIM on the
sRGB image is what a network sees; and cracks are a few % of the pixels, small and dark,
so a setting can keep the whole-image figures and still blur or lose the cracks: the
error inside the (dilated) GT crack mask is reported on its own. Linear values are
clipped to [0, 1] (the sRGB output clips there too), so PSNR uses a data range of 1.
"""
from __future__ import annotations

import math

import cv2
import numpy as np
from skimage.metrics import peak_signal_noise_ratio, structural_similarity

from crackgen.postrender.camera_effects import linear_to_srgb, quantise


def _checked(img: np.ndarray, ref: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    a, b = np.asarray(img, np.float32), np.asarray(ref, np.float32)
    if a.shape != b.shape or a.ndim != 3 or a.shape[2] != 3:
        raise ValueError(f"image error: render {a.shape} and reference {b.shape} must both be (H, W, 3)")
    return np.clip(a, 0.0, 1.0), np.clip(b, 0.0, 1.0)


def psnr_linear(img: np.ndarray, ref: np.ndarray) -> float:
    """PSNR (dB) on clipped linear RGB; inf for identical images."""
    a, b = _checked(img, ref)
    if np.array_equal(a, b):
        return math.inf
    return float(peak_signal_noise_ratio(b, a, data_range=1.0))


def ssim_srgb(img: np.ndarray, ref: np.ndarray) -> float:
    """SSIM of the 8-bit sRGB images (skimage, 7x7 window, per channel, averaged)."""
    a, b = _checked(img, ref)
    return float(structural_similarity(quantise(linear_to_srgb(b)), quantise(linear_to_srgb(a)),
                                       channel_axis=2, data_range=255))


def crack_region(mask: np.ndarray, dilate_px: int) -> np.ndarray:
    """The GT crack mask (nonzero = crack) grown by ``dilate_px`` pixels (square kernel), as bool."""
    m = (np.asarray(mask) > 0).astype(np.uint8)
    if dilate_px > 0:
        m = cv2.dilate(m, np.ones((2 * dilate_px + 1, 2 * dilate_px + 1), np.uint8))
    return m.astype(bool)


def crack_error(img: np.ndarray, ref: np.ndarray, region: np.ndarray) -> dict[str, float]:
    """MAE and PSNR of clipped linear RGB inside ``region``; NaN when the region is empty (no crack)."""
    a, b = _checked(img, ref)
    if region.shape != a.shape[:2]:
        raise ValueError(f"image error: crack region {region.shape} does not match the image {a.shape[:2]}")
    if not region.any():
        return {"crack_mae": math.nan, "crack_psnr": math.nan, "crack_px": 0}
    d = a[region] - b[region]
    mse = float(np.mean(d * d))
    return {"crack_mae": float(np.mean(np.abs(d))), "crack_psnr": math.inf if mse == 0 else 10 * math.log10(1.0 / mse),
            "crack_px": int(region.sum())}


def image_error(img: np.ndarray, ref: np.ndarray, mask: np.ndarray, dilate_px: int = 3) -> dict[str, float]:
    """All figures of one render against its reference."""
    return {"psnr": psnr_linear(img, ref), "ssim": ssim_srgb(img, ref),
            **crack_error(img, ref, crack_region(mask, dilate_px))}
