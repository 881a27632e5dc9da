"""2-D OpenSimplex noise and fBm on grids, as pure functions of (coordinates, seed).

Why not ``opensimplex.seed()``: it mutates module-global state, so two callers
(threads, or the crack map and the material textures) would silently change each
other's noise.  We build the permutation table from the seed ourselves with
``opensimplex.internals._init`` and pass it explicitly to the numba-jitted kernels.

fBm evaluates all octaves per grid point inside one numba ``prange`` loop (calling
opensimplex's own jitted ``_noise2``), which avoids O temporary (M, N) arrays and
parallelises over rows.
"""

from __future__ import annotations

from functools import lru_cache

import numpy as np
from numba import njit, prange
from opensimplex.internals import _init, _noise2, _noise2a

from crackgen.errors import CrackgenError

__all__ = ["noise2", "fbm", "NoiseError"]


class NoiseError(CrackgenError, ValueError):
    """Bad arguments to a noise function (names the argument)."""


@lru_cache(maxsize=64)
def _perm(seed: int) -> np.ndarray:
    """Permutation table for ``seed`` (cached: building it is a Python loop of 256 steps)."""
    perm, _ = _init(int(seed))
    perm.setflags(write=False)
    return perm


def _coords(name: str, a: np.ndarray) -> np.ndarray:
    arr = np.ascontiguousarray(a, dtype=np.float64)
    if arr.ndim != 1:
        raise NoiseError(f"{name} must be a 1-D coordinate array, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise NoiseError(f"{name} contains non-finite coordinates")
    return arr


def _check_seed(seed: int) -> int:
    try:
        s = int(seed)
    except (TypeError, ValueError) as exc:
        raise NoiseError(f"seed must be an integer, got {seed!r}") from exc
    if s != seed:
        raise NoiseError(f"seed must be an integer, got {seed!r}")
    return s


def noise2(u: np.ndarray, v: np.ndarray, seed: int) -> np.ndarray:
    """2-D OpenSimplex noise over the grid u x v -> (len(v), len(u)) float32, roughly in [-1, 1]."""
    x = _coords("u", u)
    y = _coords("v", v)
    return _noise2a(x, y, _perm(_check_seed(seed))).astype(np.float32)


@njit(cache=True, parallel=True, fastmath=False)
def _fbm_kernel(x, y, perm, octaves, persistence, lacunarity):  # pragma: no cover - jitted
    out = np.empty((y.size, x.size), dtype=np.float32)
    for j in prange(y.size):
        for i in range(x.size):
            total = 0.0
            amp = 1.0
            freq = 1.0
            for _k in range(octaves):
                total += _noise2(x[i] * freq, y[j] * freq, perm) * amp
                amp *= persistence
                freq *= lacunarity
            out[j, i] = total
    return out


def fbm(
    u: np.ndarray,
    v: np.ndarray,
    seed: int,
    octaves: int,
    persistence: float,
    lacunarity: float,
) -> np.ndarray:
    """Signed fBm sum_{k<O} N(u*L^k, v*L^k) * P^k over the grid u x v -> (len(v), len(u)) float32.

    Every octave uses the same permutation (same seed), as in the thesis' eq. 5.4; the
    frequency scaling decorrelates the octaves.
    """
    x = _coords("u", u)
    y = _coords("v", v)
    if int(octaves) != octaves or not 1 <= int(octaves) <= 32:
        raise NoiseError(f"octaves must be an integer in [1, 32], got {octaves!r}")
    if not (np.isfinite(persistence) and persistence > 0):
        raise NoiseError(f"persistence must be a positive finite number, got {persistence!r}")
    if not (np.isfinite(lacunarity) and lacunarity > 0):
        raise NoiseError(f"lacunarity must be a positive finite number, got {lacunarity!r}")
    return _fbm_kernel(
        x, y, _perm(_check_seed(seed)), int(octaves), float(persistence), float(lacunarity)
    )
