"""Crack map in surface coordinates (thesis eq. 5.3-5.6): Z = |fBm|, M = Z < t, D = M |Z - t|.

Index convention (the renderer, ray caster and mesh rely on it): ``array[j, i]``; columns
``i`` run along u = world +x, rows ``j`` along v = world +y.  Texel [j, i] covers
u in [i/N, (i+1)/N), its centre is u = (i + 0.5)/N; world x = (u - 0.5) * size_m,
y = (v - 0.5) * size_m.  Row 0 is v = 0 (world y = -size/2): bottom-up like Blender images.

Noise is sampled at texel centres, ``u*f_x + offset_u``, so the same spec at different
resolutions samples the same continuous function (resolution independence); e.g. the
centre of texel k at N equals the centre of texel 3k+1 at 3N exactly.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from crackgen.config.spec import CrackSpec
from crackgen.errors import CrackgenError
from crackgen.procedural.noise import fbm
from fusion.crack_length import crack_length, skeleton

__all__ = ["CrackMapError", "CrackMap", "crack_map", "texel_centres", "mask_at_uv", "nearest_texel", "depth_at_uv"]


class CrackMapError(CrackgenError, ValueError):
    """Bad crack-map arguments (names the field)."""


@dataclass
class CrackMap:
    """All crack-map layers of one sample, in surface coordinates (see module doc)."""

    z: np.ndarray  # float32 (N, N), Z = |fBm| (unitless)
    mask: np.ndarray  # bool (N, N), Z < threshold
    disp: np.ndarray  # float32 (N, N), D = M * |Z - threshold| in [0, threshold] (unitless)
    depth_m: np.ndarray  # float32 (N, N), displacement into the surface (m) = D / threshold * spec.depth_m
    skeleton: np.ndarray | None  # bool (N, N) one-pixel skeleton of ``mask`` (None if not measured)
    length_m: float  # GT crack length (m): sum of skeleton geodesic diameters (NaN if not measured)
    size_m: float  # side of the square surface patch (m)
    spec: CrackSpec  # the parameters that made it

    @property
    def size_px(self) -> int:
        return int(self.z.shape[0])

    @property
    def texel_m(self) -> float:
        """Texel side in metres (the pixel size for length measurements)."""
        return self.size_m / self.size_px

    @property
    def coverage(self) -> float:
        """Fraction of the surface inside the crack mask."""
        return float(self.mask.mean())


def texel_centres(size_px: int) -> np.ndarray:
    """u (or v) of the texel centres, (i + 0.5) / N, float64."""
    return (np.arange(size_px, dtype=np.float64) + 0.5) / size_px


def _check(spec: CrackSpec, size_px: int, size_m: float) -> None:
    if int(size_px) != size_px or size_px < 2:
        raise CrackMapError(f"size_px must be an integer >= 2, got {size_px!r}")
    if not (np.isfinite(size_m) and size_m > 0):
        raise CrackMapError(f"size_m must be a positive finite number (m), got {size_m!r}")
    if not (np.isfinite(spec.threshold) and spec.threshold > 0):
        raise CrackMapError(f"crack.threshold must be > 0, got {spec.threshold!r}")
    if not (np.isfinite(spec.depth_m) and spec.depth_m >= 0):
        raise CrackMapError(f"crack.depth_m must be >= 0 (m), got {spec.depth_m!r}")
    for name in ("freq_x", "freq_y"):
        f = getattr(spec, name)
        if not (np.isfinite(f) and f > 0):
            raise CrackMapError(f"crack.{name} must be > 0, got {f!r}")


def crack_map(spec: CrackSpec, size_px: int, size_m: float, *, measure: bool = True) -> CrackMap:
    """Evaluate the crack map of ``spec`` on an N x N texel grid over a ``size_m`` square.

    ``measure=False`` skips the skeleton and GT length (the slow part) for callers that
    only need the displacement, e.g. previews and benchmarks.
    """
    _check(spec, size_px, size_m)
    t = texel_centres(int(size_px))
    u = t * spec.freq_x + spec.offset_u
    v = t * spec.freq_y + spec.offset_v
    z = np.abs(fbm(u, v, spec.noise_seed, spec.octaves, spec.persistence, spec.lacunarity))
    thr = np.float32(spec.threshold)
    mask = z < thr
    disp = np.where(mask, thr - z, np.float32(0)).astype(np.float32)
    depth = (disp * np.float32(spec.depth_m / spec.threshold)).astype(np.float32)
    skel: np.ndarray | None = None
    length = float("nan")
    if measure:
        skel = skeleton(mask)
        length = crack_length(skel, float(size_m) / size_px, is_skeleton=True)
    return CrackMap(z=z, mask=mask, disp=disp, depth_m=depth, skeleton=skel, length_m=length, size_m=float(size_m), spec=spec)


def mask_at_uv(cm: CrackMap, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """GT mask at surface coordinates (nearest texel, clamped at the edges); shape of ``u``."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if u.shape != v.shape:
        raise CrackMapError(f"u and v must have the same shape, got {u.shape} and {v.shape}")
    return nearest_texel(cm.mask, u, v)


def nearest_texel(texels: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """``texels[j, i]`` of the texel containing (u, v), clamped at the edges (the one UV->texel rule)."""
    n_v, n_u = texels.shape[:2]
    i = np.clip(np.floor(u * n_u), 0, n_u - 1).astype(np.intp)
    j = np.clip(np.floor(v * n_v), 0, n_v - 1).astype(np.intp)
    return texels[j, i]


def depth_at_uv(cm: CrackMap, u: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Crack depth (m) at surface coordinates, bilinear between texel centres, clamped edges."""
    u = np.asarray(u, dtype=np.float64)
    v = np.asarray(v, dtype=np.float64)
    if u.shape != v.shape:
        raise CrackMapError(f"u and v must have the same shape, got {u.shape} and {v.shape}")
    n = cm.size_px
    rows = v * n - 0.5  # continuous texel index: centre of texel k is at k
    cols = u * n - 0.5
    out = ndimage.map_coordinates(cm.depth_m, [rows.ravel(), cols.ravel()], order=1, mode="nearest")
    return out.reshape(u.shape).astype(np.float32)
