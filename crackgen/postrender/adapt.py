"""Label-free appearance adaptation of rendered RGB toward real target photos.

Why: a model trained on renders fails on real photos mostly because exposure, white
balance, contrast and low-frequency texture differ, not because the cracks are wrong.
Each method here changes only the RGB views, so mask, depth and sensor members stay
exact. Every transform is *fitted once* (from the left view and one target photo) and
then *applied* to each view, so the left and right views of a stereo pair get the very
same transform.

Methods:
- ``fourier`` (Yang & Soatto 2020, FDA): the centred low-frequency square of the
  amplitude spectrum is replaced by the target's; the phase (structure) is kept.
- ``reinhard`` (Reinhard et al. 2001): per-channel mean and standard deviation in CIE
  Lab moved to the target's.
- ``histogram``: per-channel CDF matching of 8-bit RGB (a 256-entry lookup table).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from crackgen.errors import CrackgenError

METHODS = ("fourier", "reinhard", "histogram")


class AdaptError(CrackgenError, ValueError):
    """An image cannot be adapted (shape, dtype, unknown method)."""


def _check_rgb(img: np.ndarray, what: str) -> None:
    if img.dtype != np.uint8 or img.ndim != 3 or img.shape[2] != 3:
        raise AdaptError(f"{what}: expected uint8 HxWx3 RGB, got {img.dtype} {img.shape}")


def _to_uint8(x: np.ndarray) -> np.ndarray:
    return np.clip(np.rint(x), 0, 255).astype(np.uint8)


# ---------------------------------------------------------------- Fourier (FDA)

def band_halfwidth(shape: tuple[int, ...], band: float) -> int:
    """Half-width b (px) of the swapped low-frequency square: floor(band * min(H, W)).

    The square spans frequencies -b..b on each axis around DC (FDA's ``L`` parameter)."""
    return int(np.floor(float(band) * min(shape[0], shape[1])))


def low_frequency_window(shape: tuple[int, ...], b: int) -> tuple[slice, slice]:
    """Index of the (2b+1)^2 square around DC in an ``fftshift``-ed spectrum."""
    cy, cx = shape[0] // 2, shape[1] // 2
    return slice(max(cy - b, 0), cy + b + 1), slice(max(cx - b, 0), cx + b + 1)


def fourier_adapt(src: np.ndarray, target: np.ndarray, band: float) -> np.ndarray:
    """FDA on float images (H×W×C, same size): float32 result before rounding.

    ``band = 0`` returns ``src`` unchanged (as float32)."""
    if src.shape != target.shape:
        raise AdaptError(f"fourier: source {src.shape} and target {target.shape} differ in size")
    if not 0.0 <= band <= 0.5:
        raise AdaptError(f"fourier: band must be in [0, 0.5], got {band}")
    b = band_halfwidth(src.shape, band)
    if b == 0 and band == 0.0:
        return src.astype(np.float32)
    fs = np.fft.fftshift(np.fft.fft2(src.astype(np.float64), axes=(0, 1)), axes=(0, 1))
    ft = np.fft.fftshift(np.fft.fft2(target.astype(np.float64), axes=(0, 1)), axes=(0, 1))
    amp, phase = np.abs(fs), np.angle(fs)
    win = low_frequency_window(src.shape, b)
    amp[win] = np.abs(ft)[win]
    out = np.fft.ifft2(np.fft.ifftshift(amp * np.exp(1j * phase), axes=(0, 1)), axes=(0, 1))
    return out.real.astype(np.float32)


# ---------------------------------------------------------------- Reinhard (Lab mean/std)

def to_lab(rgb: np.ndarray) -> np.ndarray:
    """uint8 RGB -> float32 CIE Lab (L 0..100, a/b about -128..127)."""
    return cv2.cvtColor(rgb.astype(np.float32) / 255.0, cv2.COLOR_RGB2Lab)


def from_lab(lab: np.ndarray) -> np.ndarray:
    """float32 Lab -> float32 RGB in 0..255 (not clipped)."""
    return cv2.cvtColor(lab.astype(np.float32), cv2.COLOR_Lab2RGB) * 255.0


@dataclass(frozen=True)
class LabAffine:
    """Per-channel Lab map x -> (x - src_mean) * scale + dst_mean, fitted once, applied to every view."""

    src_mean: tuple[float, float, float]
    scale: tuple[float, float, float]
    dst_mean: tuple[float, float, float]

    def apply_lab(self, lab: np.ndarray) -> np.ndarray:
        sm, sc, dm = (np.asarray(v, np.float32) for v in (self.src_mean, self.scale, self.dst_mean))
        return (lab - sm) * sc + dm

    def apply(self, rgb: np.ndarray) -> np.ndarray:
        return _to_uint8(from_lab(self.apply_lab(to_lab(rgb))))


def fit_reinhard(src: np.ndarray, target: np.ndarray) -> LabAffine:
    """Lab mean/std transfer fitted on ``src`` toward ``target`` (a flat channel keeps scale 1)."""
    ls, lt = to_lab(src).reshape(-1, 3), to_lab(target).reshape(-1, 3)
    ms, ss = ls.mean(0), ls.std(0)
    mt, st = lt.mean(0), lt.std(0)
    scale = np.where(ss > 1e-6, st / np.maximum(ss, 1e-6), 1.0)
    return LabAffine(tuple(map(float, ms)), tuple(map(float, scale)), tuple(map(float, mt)))


# ---------------------------------------------------------------- histogram matching

def fit_histogram_lut(src: np.ndarray, target: np.ndarray) -> np.ndarray:
    """(3, 256) uint8 lookup tables mapping each channel's CDF onto the target's."""
    luts = np.empty((3, 256), np.uint8)
    levels = np.arange(256, dtype=np.float64)
    for c in range(3):
        hs = np.bincount(src[..., c].ravel(), minlength=256).astype(np.float64)
        ht = np.bincount(target[..., c].ravel(), minlength=256).astype(np.float64)
        cs, ct = np.cumsum(hs) / hs.sum(), np.cumsum(ht) / ht.sum()
        luts[c] = _to_uint8(np.interp(cs, ct, levels))
    return luts


def apply_lut(rgb: np.ndarray, luts: np.ndarray) -> np.ndarray:
    return np.stack([luts[c][rgb[..., c]] for c in range(3)], axis=-1)


# ---------------------------------------------------------------- one entry point

def resize_to(img: np.ndarray, shape: tuple[int, ...]) -> np.ndarray:
    """Target photo resized (area filter) to the render's H×W, so spectra and statistics compare."""
    h, w = shape[:2]
    if img.shape[:2] == (h, w):
        return img
    return cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA)


def adapt_views(views: list[np.ndarray], target: np.ndarray, method: str, band: float = 0.0) -> list[np.ndarray]:
    """Adapt every RGB view (left first) toward ``target`` with one transform.

    The transform is fitted on the first view; ``fourier`` applies the same target
    amplitude band to each view. Returns new uint8 arrays; inputs are not modified."""
    if not views:
        return []
    for i, v in enumerate(views):
        _check_rgb(v, f"view {i}")
    _check_rgb(target, "target photo")
    tgt = resize_to(target, views[0].shape)
    if method == "fourier":
        return [_to_uint8(fourier_adapt(v, resize_to(target, v.shape), band)) for v in views]
    if method == "reinhard":
        fit = fit_reinhard(views[0], tgt)
        return [fit.apply(v) for v in views]
    if method == "histogram":
        luts = fit_histogram_lut(views[0], tgt)
        return [apply_lut(v, luts) for v in views]
    raise AdaptError(f"unknown adaptation method {method!r}; choose one of {', '.join(METHODS)}")
