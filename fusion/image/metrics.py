"""No-reference fusion quality: how much of the sources survives in the fused image (thesis 3.1).

All four take the sources A, B and the fused F as grey images on the 0..255 scale (SSIM's
constants assume it; colour images are reduced to luminance); higher is better.  With more than two sources, the pairwise
scores are averaged over all source pairs.

- Q_Y (Yang et al. 2008): SSIM per 7 x 7 window.  Where the sources agree (SSIM(A, B) >= 0.75)
  the score is the variance-weighted SSIM(A, F) and SSIM(B, F), else the larger of the two.
- Q_C (Cvejic et al. 2005): UIQI (Wang-Bovik Q0) of A-F and B-F per 7 x 7 window, weighted by
  mu = cov(A, F) / (cov(A, F) + cov(B, F)) clipped to [0, 1].
- Q_G (Xydeas & Petrovic 2000, Q^AB/F): how well the Sobel edge strength and orientation of
  each source are kept in F (sigmoid-mapped), weighted by the source's edge strength.
- Q_MI (Hossny et al. 2008): 2 [MI(A, F) / (H(A) + H(F)) + MI(B, F) / (H(B) + H(F))], 256-bin
  histograms; in [0, 2].
"""

from __future__ import annotations

from itertools import combinations

import cv2
import numpy as np

from fusion.image.fuse import luminance
from fusion.image.guided_filter import box_mean

__all__ = ["q_y", "q_c", "q_g", "q_mi", "fusion_quality", "WINDOW"]

WINDOW = 7
_C1 = (0.01 * 255) ** 2
_C2 = (0.03 * 255) ** 2


def _stats(x: np.ndarray, y: np.ndarray):
    r = WINDOW // 2
    mx, my = box_mean(x, r), box_mean(y, r)
    vx = box_mean(x * x, r) - mx * mx
    vy = box_mean(y * y, r) - my * my
    cxy = box_mean(x * y, r) - mx * my
    return mx, my, np.maximum(vx, 0.0), np.maximum(vy, 0.0), cxy


def _ssim_map(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    mx, my, vx, vy, cxy = _stats(x, y)
    return ((2 * mx * my + _C1) * (2 * cxy + _C2)) / ((mx * mx + my * my + _C1) * (vx + vy + _C2))


def _uiqi_map(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    mx, my, vx, vy, cxy = _stats(x, y)
    num = 4 * cxy * mx * my
    den = (vx + vy) * (mx * mx + my * my)
    flat = den < 1e-12  # both windows constant: equal means score 1, else 0 (the limit of the formula)
    same = np.isclose(mx, my)
    return np.where(flat, np.where(same, 1.0, 0.0), num / np.where(flat, 1.0, den))


def _grey(img: np.ndarray) -> np.ndarray:
    return luminance(np.asarray(img, dtype=np.float64))


def _pairs(sources, fused, fn) -> float:
    src = [_grey(s) for s in sources]
    f = _grey(fused)
    return float(np.mean([fn(a, b, f) for a, b in combinations(src, 2)]))


def _q_y(a, b, f) -> float:
    s_ab, s_af, s_bf = _ssim_map(a, b), _ssim_map(a, f), _ssim_map(b, f)
    _, _, va, vb, _ = _stats(a, b)
    lam = np.where(va + vb > 0, va / np.where(va + vb > 0, va + vb, 1.0), 0.5)
    q = np.where(s_ab >= 0.75, lam * s_af + (1 - lam) * s_bf, np.maximum(s_af, s_bf))
    return float(q.mean())


def _q_c(a, b, f) -> float:
    _, _, _, _, c_af = _stats(a, f)
    _, _, _, _, c_bf = _stats(b, f)
    s = c_af + c_bf
    mu = np.clip(np.where(np.abs(s) > 1e-12, c_af / np.where(np.abs(s) > 1e-12, s, 1.0), 0.5), 0.0, 1.0)
    return float((mu * _uiqi_map(a, f) + (1 - mu) * _uiqi_map(b, f)).mean())


def _sobel(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    gx = cv2.Sobel(x, cv2.CV_64F, 1, 0, ksize=3, borderType=cv2.BORDER_REFLECT)
    gy = cv2.Sobel(x, cv2.CV_64F, 0, 1, ksize=3, borderType=cv2.BORDER_REFLECT)
    g = np.hypot(gx, gy)
    with np.errstate(divide="ignore", invalid="ignore"):
        alpha = np.where(gx == 0, np.where(gy == 0, 0.0, np.pi / 2), np.arctan(gy / gx))
    return g, alpha


def _edge_kept(gs, as_, gf, af) -> np.ndarray:
    """Q^{SF}: edge strength and orientation of source S preserved in F, per pixel."""
    with np.errstate(divide="ignore", invalid="ignore"):
        G = np.where(gs > gf, gf / gs, np.where(gf > 0, gs / gf, 1.0))
    A = 1.0 - np.abs(as_ - af) / (np.pi / 2)
    qg = 0.9994 / (1 + np.exp(-15 * (G - 0.5)))
    qa = 0.9879 / (1 + np.exp(-22 * (A - 0.8)))
    return qg * qa


def _q_g(a, b, f) -> float:
    ga, aa = _sobel(a)
    gb, ab = _sobel(b)
    gf, af = _sobel(f)
    w = ga + gb
    if w.sum() <= 0:
        return 1.0  # no edges anywhere: nothing to lose
    return float(((_edge_kept(ga, aa, gf, af) * ga + _edge_kept(gb, ab, gf, af) * gb).sum()) / w.sum())


def _hist_entropy(counts: np.ndarray) -> float:
    p = counts[counts > 0] / counts.sum()
    return float(-(p * np.log2(p)).sum())


def _mutual_information(x: np.ndarray, y: np.ndarray) -> tuple[float, float, float]:
    """(MI, H(x), H(y)) in bits from 256-bin histograms over the joint range."""
    lo, hi = min(x.min(), y.min()), max(x.max(), y.max())
    if hi <= lo:
        hi = lo + 1.0
    j, _, _ = np.histogram2d(x.ravel(), y.ravel(), bins=256, range=[[lo, hi], [lo, hi]])
    hx, hy, hxy = _hist_entropy(j.sum(axis=1)), _hist_entropy(j.sum(axis=0)), _hist_entropy(j.ravel())
    return hx + hy - hxy, hx, hy


def _q_mi(a, b, f) -> float:
    total = 0.0
    for s in (a, b):
        mi, hs, hf = _mutual_information(s, f)
        total += mi / (hs + hf) if hs + hf > 0 else 1.0
    return 2.0 * total


def q_y(sources, fused) -> float:
    return _pairs(sources, fused, _q_y)


def q_c(sources, fused) -> float:
    return _pairs(sources, fused, _q_c)


def q_g(sources, fused) -> float:
    return _pairs(sources, fused, _q_g)


def q_mi(sources, fused) -> float:
    return _pairs(sources, fused, _q_mi)


def fusion_quality(sources, fused) -> dict[str, float]:
    """The thesis's four scores; sources and fused on the 0..255 scale (uint8 or float)."""
    return {"Q_Y": q_y(sources, fused), "Q_C": q_c(sources, fused), "Q_G": q_g(sources, fused),
            "Q_MI": q_mi(sources, fused)}
