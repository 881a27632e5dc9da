"""Alpha pattern of the shadow occluder (thesis 5.2.5: a random texture mask blocking part of a light).

Pure numpy/OpenCV so the pattern is testable without Blender and reproducible from
``ShadowSpec.seed`` alone (one explicit Generator). Three kinds, each hitting the
requested opaque fraction ``coverage`` before blurring:

- ``noise``: fBm blobs (foliage-like), thresholded at the (1 - coverage) quantile;
- ``shapes``: random filled ellipses and polygons (poles, signs, people), added until covered;
- ``stripes``: parallel bars at a random angle and period (railings, blinds), duty = coverage.

``softness`` (fraction of the occluder side) sets a Gaussian edge blur, i.e. penumbra
baked into the mask on top of the light's own size. Array convention: ``alpha[j, i]``,
i along the occluder's local +x, row 0 at local -y (bottom-up, as Blender images).
1 = opaque, 0 = clear.
"""
from __future__ import annotations

import math

import cv2
import numpy as np

from crackgen.config.spec import ShadowSpec
from crackgen.errors import CrackgenError
from crackgen.procedural.noise import fbm

PATTERNS = ("noise", "shapes", "stripes")
MAX_SHAPES = 400


class ShadowPatternError(CrackgenError, ValueError):
    """Bad shadow-pattern arguments (names the field)."""


def _check(spec: ShadowSpec, px: int) -> None:
    if spec.pattern not in PATTERNS:
        raise ShadowPatternError(f"shadow.pattern must be one of {', '.join(PATTERNS)}, got {spec.pattern!r}")
    if not 0.0 <= spec.coverage <= 1.0:
        raise ShadowPatternError(f"shadow.coverage must be within [0, 1], got {spec.coverage!r}")
    if not 0.0 <= spec.softness <= 0.5:
        raise ShadowPatternError(f"shadow.softness must be within [0, 0.5], got {spec.softness!r}")
    if int(px) != px or px < 8:
        raise ShadowPatternError(f"shadow pattern px must be an integer >= 8, got {px!r}")


def _noise(rng: np.random.Generator, px: int, coverage: float) -> np.ndarray:
    scale = rng.uniform(2.0, 5.0)  # blobs per occluder side
    t = (np.arange(px) + 0.5) / px * scale
    f = fbm(t + rng.uniform(-500, 500), t + rng.uniform(-500, 500), int(rng.integers(0, 2**31 - 1)), 4, 0.5, 2.0)
    q = np.quantile(f, 1.0 - coverage)
    return (f > q).astype(np.float32)


def _shapes(rng: np.random.Generator, px: int, coverage: float) -> np.ndarray:
    img = np.zeros((px, px), np.uint8)
    target = coverage * img.size
    for _ in range(MAX_SHAPES):
        if np.count_nonzero(img) >= target:
            break
        centre = (int(rng.integers(0, px)), int(rng.integers(0, px)))
        r = rng.uniform(0.04, 0.2) * px
        if rng.random() < 0.5:
            axes = (max(1, int(r)), max(1, int(r * rng.uniform(0.2, 1.0))))
            cv2.ellipse(img, centre, axes, float(rng.uniform(0, 180)), 0, 360, 255, -1)
        else:
            n = int(rng.integers(3, 7))
            ang = np.sort(rng.uniform(0, 2 * math.pi, n))
            rad = r * rng.uniform(0.5, 1.0, n)
            pts = np.stack([centre[0] + rad * np.cos(ang), centre[1] + rad * np.sin(ang)], 1)
            cv2.fillPoly(img, [np.round(pts).astype(np.int32)], 255)
    return (img > 0).astype(np.float32)


def _stripes(rng: np.random.Generator, px: int, coverage: float) -> np.ndarray:
    angle = rng.uniform(0, math.pi)
    period = rng.uniform(0.08, 0.3) * px
    phase = rng.uniform(0, 1)
    i, j = np.meshgrid(np.arange(px) + 0.5, np.arange(px) + 0.5)
    s = (i * math.cos(angle) + j * math.sin(angle)) / period + phase
    return ((s % 1.0) < coverage).astype(np.float32)


def shadow_alpha(spec: ShadowSpec, px: int = 256) -> np.ndarray:
    """(px, px) float32 occluder opacity in [0, 1] for ``spec`` (1 = blocks the light)."""
    _check(spec, px)
    rng = np.random.default_rng(int(spec.seed))
    if spec.coverage <= 0.0:
        return np.zeros((px, px), np.float32)
    if spec.coverage >= 1.0:
        return np.ones((px, px), np.float32)
    alpha = {"noise": _noise, "shapes": _shapes, "stripes": _stripes}[spec.pattern](rng, px, spec.coverage)
    sigma = spec.softness * px
    if sigma > 0.3:
        alpha = cv2.GaussianBlur(alpha, (0, 0), sigmaX=sigma, borderType=cv2.BORDER_REFLECT)
    return np.clip(alpha, 0.0, 1.0).astype(np.float32)
