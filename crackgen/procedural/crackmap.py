"""Crack map in surface coordinates: the thesis fBm map or a path-based shape family.

``spec.shape`` picks the family (one ``CrackMap`` for all, so renderer, sensors and GT are shared):

- ``fbm`` (thesis eq. 5.3-5.6): Z = |fBm|, M = Z < t, D = M |Z - t|.
- ``fracture`` / ``network`` / ``hairline`` (``crackgen.procedural.crack_shapes``): centre-line
  paths with a half-width w along them. Z = d / w, the distance to the nearest path over the
  local half-width, clipped to 1; this is the same equation with t = 1: M = Z < 1,
  D = M (1 - Z), depth = D * centre-line depth. So the crack is exactly 2 w wide, V-shaped;
  ``wall`` < 1 makes the walls steeper, D = M min(1, (1 - Z) / wall), with a flat floor.
- ``spec.present`` False (the recipe's crack-free share): an empty map, Z = t everywhere.

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

from crackgen.config.recipe import SHAPES
from crackgen.config.spec import CrackSpec
from crackgen.errors import CrackgenError
from crackgen.procedural.crack_shapes.fracture import fracture_paths
from crackgen.procedural.crack_shapes.hairline import DEPTH_SCALE, hairline_width_m
from crackgen.procedural.crack_shapes.network import network_paths
from crackgen.procedural.crack_shapes.paths import MIN_HALF_WIDTH_PX, render_paths, to_texels
from crackgen.procedural.crack_shapes.stairstep import JointGrid, stairstep_paths
from crackgen.procedural.noise import fbm
from fusion.measure.crack_length import crack_components, skeleton

__all__ = ["CrackMapError", "CrackMap", "crack_map", "texel_centres", "mask_at_uv", "nearest_texel", "depth_at_uv"]


class CrackMapError(CrackgenError, ValueError):
    """Bad crack-map arguments (names the field)."""


@dataclass
class CrackMap:
    """All crack-map layers of one sample, in surface coordinates (see module doc)."""

    z: np.ndarray  # float32 (N, N), Z = |fBm| (fbm) or d / w clipped to 1 (path families), unitless
    mask: np.ndarray  # bool (N, N), Z < threshold (fbm) or Z < 1 (path families)
    disp: np.ndarray  # float32 (N, N), D = M * |Z - t| in [0, t] (unitless; t = threshold or 1)
    depth_m: np.ndarray  # float32 (N, N), displacement into the surface (m) = D / t * centre-line depth
    skeleton: np.ndarray | None  # bool (N, N) one-pixel skeleton of ``mask`` (None if not measured)
    # Whole patch (m): the sum over skeleton components of their skeleton diameters (NaN if not
    # measured). Not the thesis length, and not what a camera sees: the per-view GT with the
    # thesis quantities is ``crackgen.sim.visible_gt`` (``visible`` in the sample JSON).
    length_m: float
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


def _check(spec: CrackSpec, size_px: int, size_m: float, pixel_m: float | None) -> None:
    if spec.shape not in SHAPES:
        raise CrackMapError(f"crack.shape must be one of {', '.join(SHAPES)}, got {spec.shape!r}")
    if pixel_m is not None and not (np.isfinite(pixel_m) and pixel_m > 0):
        raise CrackMapError(f"pixel_m must be a positive finite number (m), got {pixel_m!r}")
    if spec.shape in ("fracture", "network") and not (np.isfinite(spec.width_m) and spec.width_m > 0):
        raise CrackMapError(f"crack.width_m must be > 0 (m) for shape {spec.shape!r}, got {spec.width_m!r}")
    if spec.shape == "hairline" and not (np.isfinite(spec.hairline_px) and spec.hairline_px > 0):
        raise CrackMapError(f"crack.hairline_px must be > 0, got {spec.hairline_px!r}")
    if spec.shape == "network" and not (spec.cells >= 2 and 0 <= spec.gaps < 1):
        raise CrackMapError(f"crack.cells must be >= 2 and crack.gaps in [0, 1), got {spec.cells!r}, {spec.gaps!r}")
    if not (np.isfinite(spec.wall) and 0 < spec.wall <= 1):
        raise CrackMapError(f"crack.wall must be in (0, 1], got {spec.wall!r}")
    if not (np.isfinite(spec.jaggedness) and spec.jaggedness >= 0):
        raise CrackMapError(f"crack.jaggedness must be >= 0, got {spec.jaggedness!r}")
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


def crack_map(
    spec: CrackSpec, size_px: int, size_m: float, *, measure: bool = True, pixel_m: float | None = None,
    joints: JointGrid | None = None,
) -> CrackMap:
    """Evaluate the crack map of ``spec`` on an N x N texel grid over a ``size_m`` square.

    ``measure=False`` skips the skeleton and GT length (the slow part) for callers that
    only need the displacement, e.g. previews and benchmarks. ``pixel_m`` is the camera
    pixel's footprint on the surface (m, ``crackgen.config.spec.pixel_footprint_m``); only
    ``hairline`` uses it, and without it a hairline is ``hairline_px`` texels wide.
    ``joints``: the wall's mortar joints (``materials.brick_joints``) that a ``stairstep``
    crack follows; without them (a surface with no bricks) it is drawn as a ``fracture``.
    """
    _check(spec, size_px, size_m, pixel_m)
    n = int(size_px)
    if not spec.present:
        thr = np.float32(spec.threshold if spec.shape == "fbm" else 1.0)
        z = np.full((n, n), thr, dtype=np.float32)
        mask = np.zeros((n, n), dtype=bool)
        disp = np.zeros((n, n), dtype=np.float32)
        depth = disp.copy()
    elif spec.shape == "fbm":
        z, mask, disp, depth = _fbm_layers(spec, n)
    else:
        z, mask, disp, depth = _path_layers(spec, n, float(size_m), pixel_m, joints)
    skel: np.ndarray | None = None
    length = float("nan")
    if measure:
        skel = skeleton(mask)
        comps = crack_components(skel, float(size_m) / size_px, is_skeleton=True) if mask.any() else []
        length = float(sum(c.path_length for c in comps))
    return CrackMap(z=z, mask=mask, disp=disp, depth_m=depth, skeleton=skel, length_m=length, size_m=float(size_m), spec=spec)


def _fbm_layers(spec: CrackSpec, n: int) -> tuple[np.ndarray, ...]:
    """Thesis eq. 5.3-5.6 (unchanged: existing datasets stay bit-identical)."""
    t = texel_centres(n)
    u = t * spec.freq_x + spec.offset_u
    v = t * spec.freq_y + spec.offset_v
    z = np.abs(fbm(u, v, spec.noise_seed, spec.octaves, spec.persistence, spec.lacunarity))
    thr = np.float32(spec.threshold)
    mask = z < thr
    disp = np.where(mask, thr - z, np.float32(0)).astype(np.float32)
    depth = (disp * np.float32(spec.depth_m / spec.threshold)).astype(np.float32)
    return z, mask, disp, depth


def _path_layers(spec: CrackSpec, n: int, size_m: float, pixel_m: float | None,
                 joints: JointGrid | None = None) -> tuple[np.ndarray, ...]:
    """Path families: Z = d / w (clipped to 1), M = Z < 1, D = min(1, (1 - Z) / wall) inside,
    depth = D * centre depth. ``wall`` = 1 is the V-groove; smaller walls are steeper, with a flat
    floor between them, as in an open fracture whose faces have pulled apart."""
    rng = np.random.default_rng(spec.shape_seed)
    centre_depth = spec.depth_m
    if spec.shape == "network":
        paths = network_paths(spec, 0.5 * spec.width_m / size_m, rng)
    elif spec.shape == "stairstep" and joints is not None:
        paths = stairstep_paths(spec, 0.5 * spec.width_m / size_m, joints, size_m, rng)
    elif spec.shape in ("fracture", "stairstep"):  # a stairstep crack on a surface without joints: a fracture
        paths = fracture_paths(spec, 0.5 * spec.width_m / size_m, rng, MIN_HALF_WIDTH_PX / n)
    else:  # hairline; narrower than a texel -> widened to one texel by render_paths
        width_m = hairline_width_m(spec, pixel_m if pixel_m is not None else size_m / n)
        paths = fracture_paths(spec, 0.5 * width_m / size_m, rng, MIN_HALF_WIDTH_PX / n)
        centre_depth = DEPTH_SCALE * spec.depth_m
    z = render_paths(to_texels(paths, n), n)
    mask = z < np.float32(1.0)
    disp = np.where(mask, np.float32(1.0) - z, np.float32(0)).astype(np.float32)
    if spec.wall < 1.0:
        disp = np.minimum(disp / np.float32(spec.wall), np.float32(1.0))
    depth = (disp * np.float32(centre_depth)).astype(np.float32)
    return z, mask, disp, depth


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
