"""Guided-filter image fusion (thesis 3.1, after Li, Kang & Hu 2013): exposure or focus stacks -> one image.

Each source is split into a base layer (31 x 31 mean) and detail; the thesis's 3-level
variant splits the detail again at 15 x 15.  Per source, saliency = Gaussian(|Laplacian|)
(11 x 11, sigma 5, on the luminance); the initial weight map P_n is 1 where source n is the
most salient.  P_n is refined per layer by a guided filter with the source as guide (large
r, eps for the smooth base weights; small for the sharp detail weights), the weights are
normalised to sum to 1 per pixel, and the layers are recombined.

Levels (window, r / eps per layer, images in [0, 1]):
- 2: B = Z31(I), D = I - B; (45, 0.3) for B, (7, 1e-6) for D (Li et al.'s settings).
- 3: B = Z31(I), D1 = Z15(I) - B, D2 = I - Z15(I); (45, 0.3), (20, 0.1), (7, 1e-6).
"""

from __future__ import annotations

import cv2
import numpy as np

from fusion.errors import FusionError
from fusion.image.guided_filter import box_mean, guided_filter

__all__ = ["ImageFusionError", "LEVELS", "saliency", "fusion_weights", "fuse_images", "luminance"]

LEVELS = {
    2: {"windows": (31,), "gf": ((45, 0.3), (7, 1e-6))},
    3: {"windows": (31, 15), "gf": ((45, 0.3), (20, 0.1), (7, 1e-6))},
}
SALIENCY_SIGMA = 5.0
SALIENCY_RADIUS = 5


class ImageFusionError(FusionError):
    """Bad fusion inputs (names what is wrong)."""


def luminance(img: np.ndarray) -> np.ndarray:
    """(H, W) Rec. 601 luma of an (H, W, 3) RGB image; grey images pass through."""
    a = np.asarray(img, dtype=np.float64)
    return a if a.ndim == 2 else a @ np.array([0.299, 0.587, 0.114])


def saliency(img: np.ndarray) -> np.ndarray:
    """Gaussian(|Laplacian 3x3|) of the luminance: local contrast, i.e. what is in focus / well exposed."""
    h = np.abs(cv2.Laplacian(luminance(img), cv2.CV_64F, ksize=1, borderType=cv2.BORDER_REFLECT))
    k = 2 * SALIENCY_RADIUS + 1
    return cv2.GaussianBlur(h, (k, k), SALIENCY_SIGMA, borderType=cv2.BORDER_REFLECT)


def _check(images: list[np.ndarray]) -> list[np.ndarray]:
    if len(images) < 2:
        raise ImageFusionError(f"fusion needs at least 2 images, got {len(images)}")
    out = [np.asarray(a, dtype=np.float64) for a in images]
    for k, a in enumerate(out):
        if a.shape != out[0].shape:
            raise ImageFusionError(f"image {k + 1} has shape {a.shape}, image 1 has {out[0].shape}: sizes must match")
        if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] != 3):
            raise ImageFusionError(f"image {k + 1} must be grey (H, W) or colour (H, W, 3), got {a.shape}")
    return out


def _layers(img: np.ndarray, windows: tuple[int, ...]) -> list[np.ndarray]:
    """[base, coarse detail, ..., fine detail] that sum to the image."""
    smooth = [box_mean(img, w // 2) for w in windows]  # 31 then 15: coarse to fine
    layers = [smooth[0]]
    for k in range(1, len(smooth)):
        layers.append(smooth[k] - smooth[k - 1])
    layers.append(img - smooth[-1])
    return layers


def fusion_weights(images: list[np.ndarray], levels: int = 2) -> list[np.ndarray]:
    """Per layer, the (N, H, W) normalised weights of the N sources (see module doc)."""
    if levels not in LEVELS:
        raise ImageFusionError(f"levels must be 2 or 3, got {levels!r}")
    imgs = _check(images)
    sal = np.stack([saliency(a) for a in imgs])
    best = np.argmax(sal, axis=0)
    P = [(best == n).astype(np.float64) for n in range(len(imgs))]
    out = []
    for r, eps in LEVELS[levels]["gf"]:
        w = np.stack([guided_filter(imgs[n], P[n], r, eps) for n in range(len(imgs))])
        w = np.clip(w, 0.0, None)
        s = w.sum(axis=0)
        w = np.where(s > 1e-12, w / np.where(s > 1e-12, s, 1.0), 1.0 / len(imgs))
        out.append(w)
    return out


def fuse_images(images: list[np.ndarray], levels: int = 2) -> np.ndarray:
    """Fused image (float64, same shape as the inputs) of N registered images in [0, 1]."""
    imgs = _check(images)
    weights = fusion_weights(imgs, levels)
    layers = [_layers(a, LEVELS[levels]["windows"]) for a in imgs]
    fused = np.zeros_like(imgs[0])
    for k, w in enumerate(weights):
        for n in range(len(imgs)):
            wk = w[n][..., None] if imgs[n].ndim == 3 else w[n]
            fused += wk * layers[n][k]
    return np.clip(fused, 0.0, 1.0)
