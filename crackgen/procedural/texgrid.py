"""Texture-space sampling grid and the noise fields material maps are built from.

Why a module of its own: materials and distractors both need "a smooth random field
with features of about S metres over this texture", and both must get it cheaply.
fBm is evaluated only as densely as its finest octave needs (a few samples per
feature) and then bilinearly upsampled, so a 0.5 m mottling layer on a 1024 px map
costs a 64 x 64 noise grid instead of a million evaluations.

Index convention (same as the crack map): ``array[j, i]``, ``i`` along u = world +x,
``j`` along v = world +y, row 0 at v = 0, texel centre at ``(i + 0.5) / px``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from crackgen.procedural.noise import fbm, noise2

NOISE_STD = 0.37  # std of one OpenSimplex octave (measured); fields are divided by it
SAMPLES_PER_FEATURE = 4.0  # grid samples per noise unit of the finest octave (then bilinear)
MIN_FEATURE_TEXELS = 2.0  # finest octave kept: about this many texels per noise unit
MIN_GRID = 8


def clip01(a: np.ndarray) -> np.ndarray:
    """Clip to [0, 1] in place (np.clip is several times slower on large float32 arrays)."""
    return np.minimum(np.maximum(a, 0.0, out=a), 1.0, out=a)


def smoothstep(edge0: float | np.ndarray, edge1: float | np.ndarray, x: np.ndarray) -> np.ndarray:
    """Hermite step 0 -> 1 between edge0 and edge1 (edge0 > edge1 gives a falling step)."""
    t = np.asarray((x - edge0) * np.float32(1.0 / (edge1 - edge0)), dtype=np.float32)
    clip01(t)
    return t * t * (3.0 - 2.0 * t)


def fbm_std(octaves: int, persistence: float) -> float:
    """Expected std of an unnormalised fBm sum (octaves are nearly uncorrelated)."""
    return NOISE_STD * math.sqrt(sum(persistence ** (2 * k) for k in range(int(octaves))))


def quantile_fast(a: np.ndarray, q: float, step: int = 4) -> float:
    """Quantile of a smooth field from a strided subsample (the field varies slowly)."""
    return float(np.quantile(a[::step, ::step], q))


@dataclass(frozen=True)
class TexGrid:
    """A square texture of ``px`` texels covering ``size_m`` metres of surface."""

    px: int
    size_m: float
    x_m: np.ndarray = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        object.__setattr__(self, "x_m", ((np.arange(self.px) + 0.5) * self.texel_m).astype(np.float64))

    @property
    def texel_m(self) -> float:
        return self.size_m / self.px

    def field(
        self,
        seed: int,
        scale_m: float,
        octaves: int = 1,
        persistence: float = 0.5,
        lacunarity: float = 2.0,
        stretch: tuple[float, float] = (1.0, 1.0),
        offset: tuple[float, float] = (0.0, 0.0),
    ) -> np.ndarray:
        """fBm with base feature size ``scale_m`` (metres), normalised to ~unit std, (px, px) float32.

        ``stretch`` multiplies the feature size along u / v (anisotropic streaks);
        ``offset`` shifts the noise domain (noise units) to decorrelate layers sharing a seed.
        """
        sx, sy = scale_m * stretch[0], scale_m * stretch[1]
        # Octaves finer than ~2 texels would only alias: drop them (band-limit to the texture).
        while octaves > 1 and min(sx, sy) / lacunarity ** (octaves - 1) < MIN_FEATURE_TEXELS * self.texel_m:
            octaves -= 1
        fine = lacunarity ** (octaves - 1)
        nu = self._samples(sx / fine)
        nv = self._samples(sy / fine)
        cu = (np.arange(nu) + 0.5) * (self.size_m / nu)
        cv = (np.arange(nv) + 0.5) * (self.size_m / nv)
        f = fbm(cu / sx + offset[0], cv / sy + offset[1], seed, octaves, persistence, lacunarity)
        f *= np.float32(1.0 / fbm_std(octaves, persistence))
        if (nv, nu) != (self.px, self.px):
            # INTER_LINEAR maps texel centres to texel centres, matching the (k + 0.5) grids above.
            f = cv2.resize(f, (self.px, self.px), interpolation=cv2.INTER_LINEAR)
        return f

    def _samples(self, finest_m: float) -> int:
        """Grid size that resolves features of ``finest_m`` metres, at most the texture size."""
        return int(np.clip(math.ceil(self.size_m / finest_m * SAMPLES_PER_FEATURE), MIN_GRID, self.px))

    def profile(self, seed: int, t_m: np.ndarray, scale_m: float, offset: float = 0.0) -> np.ndarray:
        """1-D noise (~unit std) at arbitrary positions ``t_m`` (metres), e.g. along a line.

        Sampled once on a 1-D grid and interpolated, so its cost does not grow with the texture.
        """
        lo, hi = float(t_m.min()), float(t_m.max())
        n = max(int(math.ceil((hi - lo) / scale_m * SAMPLES_PER_FEATURE)) + 2, 2)
        ts = np.linspace(lo, hi, n)
        vals = noise2(ts / scale_m + offset, np.array([0.5 + offset]), seed)[0] / NOISE_STD
        return np.interp(t_m, ts, vals).astype(np.float32)

    def line_coords(self, angle_rad: float, through_m: tuple[float, float]) -> tuple[np.ndarray, np.ndarray]:
        """(signed distance across, position along) a straight line, metres, (px, px) each."""
        c, s = math.cos(angle_rad), math.sin(angle_rad)
        x = (self.x_m - through_m[0]).astype(np.float32)
        y = (self.x_m - through_m[1]).astype(np.float32)
        along = x[None, :] * np.float32(c) + y[:, None] * np.float32(s)
        across = y[:, None] * np.float32(c) - x[None, :] * np.float32(s)
        return across, along
