"""``fracture`` family: open cracks grown along a main direction, jagged, branching, tapering.

Each main crack is a straight chord through a random point of the middle of the patch, at
the patch's random direction +- a small spread, 0.7-1.4 patch sides long (so it often leaves
the patch), made jagged at every octave by midpoint displacement. Branches leave at 30-70 deg
from a point on the middle of the parent and are 20-50 % of its length.

Cracks stay open (no closed loops, like real fractures, where a later crack stops at an
earlier one): each new path may touch the cracks drawn before it at one point at most. A
main crack runs from its centre until it meets an earlier crack (a T-junction); on its other
side, and for a branch beyond its parent, it stops short of any earlier crack instead.

Half-widths: a main crack peaks at ``half_width`` (the recipe's width at the widest point,
exactly) near its middle and tapers as a square root to both tips, with a mild smooth wobble;
a branch starts at 40-80 % of its parent's local width and tapers to nothing at its end.
"""

from __future__ import annotations

import cv2
import numpy as np

from crackgen.config.spec import CrackSpec
from crackgen.procedural.crack_shapes.paths import Path, arc_fraction, jagged_line, smooth_wobble

__all__ = ["fracture_paths", "main_profile"]

_SPREAD = np.radians(12.0)  # s.d. of each main crack's angle about the patch direction
_BRANCH_DEG = (30.0, 70.0)  # branch angle to the parent: wide enough not to run back into it
_CELLS = 512  # occupancy grid cells per patch side (for stopping paths at earlier ones)
_PAD = 0.5  # the grid covers [-_PAD, 1 + _PAD] patch units


class _Occupancy:
    """Distance (patch units) from any point to the paths drawn so far, on a coarse grid."""

    def __init__(self) -> None:
        self.m = int(_CELLS * (1 + 2 * _PAD))
        self.free = np.full((self.m, self.m), 255, dtype=np.uint8)
        self.dist: np.ndarray | None = None

    def _cells(self, xy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        c = np.rint((xy + _PAD) * _CELLS).astype(np.intp)
        return c, np.all((c >= 0) & (c < self.m), axis=1)

    def add(self, xy: np.ndarray) -> None:
        c, ok = self._cells(xy)
        self.free[c[ok, 1], c[ok, 0]] = 0
        self.dist = None

    def distance(self, xy: np.ndarray) -> np.ndarray:
        if not (self.free == 0).any():
            return np.full(len(xy), np.inf)
        if self.dist is None:
            self.dist = cv2.distanceTransform(self.free, cv2.DIST_L2, cv2.DIST_MASK_PRECISE) / _CELLS
        c, ok = self._cells(xy)
        out = np.full(len(xy), np.inf)
        out[ok] = self.dist[c[ok, 1], c[ok, 0]]
        return out


def main_profile(s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Relative half-width along a main crack (max exactly 1, 0 at both tips)."""
    base = np.sqrt(np.clip(4.0 * s * (1.0 - s), 0.0, 1.0))
    prof = base * smooth_wobble(s, rng, 0.2)
    peak = prof.max()  # 0 for a path cut down to its two end points (both tips): no crack
    return prof / peak if peak > 0 else np.zeros_like(prof)


def _first(hit: np.ndarray) -> int | None:
    k = np.flatnonzero(hit)
    return int(k[0]) if len(k) else None


def _main(spec: CrackSpec, direction: float, half_width: float, gap: float, occ: _Occupancy, rng) -> Path:
    centre = rng.uniform(0.2, 0.8, 2)
    angle = direction + rng.normal(0.0, _SPREAD)
    half = 0.5 * rng.uniform(0.7, 1.4) * np.array([np.cos(angle), np.sin(angle)])
    xy = jagged_line(centre - half, centre + half, spec.jaggedness, rng)
    d = occ.distance(xy)
    k0 = int(np.argmin(np.hypot(*(xy - centre).T)))
    end = len(xy)
    f = _first(d[k0:] < gap)
    if f is not None:  # T-junction: run on to the earlier crack's centre line
        f2 = _first(d[k0 + f :] < 1.0 / _CELLS)
        end = k0 + f + (f2 if f2 is not None else 0) + 1
    b = _first(d[:k0][::-1] < 2 * gap)  # other side: stop short (a second contact would close a loop)
    start = k0 - b if b is not None else 0
    xy = xy[start:end]
    return Path(xy=xy, half_width=half_width * main_profile(arc_fraction(xy), rng))


def _branch(parent: Path, spec: CrackSpec, gap: float, occ: _Occupancy, rng: np.random.Generator) -> Path:
    s = arc_fraction(parent.xy)
    k = int(np.searchsorted(s, rng.uniform(0.2, 0.8)))
    k = min(max(k, 1), len(s) - 2)
    span = max(2, len(s) // 20)  # tangent over ~5 % of the parent, not the jagged local segment
    tang = parent.xy[min(k + span, len(s) - 1)] - parent.xy[max(k - span, 0)]
    angle = np.arctan2(tang[1], tang[0]) + rng.choice([-1.0, 1.0]) * np.radians(rng.uniform(*_BRANCH_DEG))
    length = rng.uniform(0.2, 0.5) * float(np.hypot(*(parent.xy[-1] - parent.xy[0])))
    start = parent.xy[k]
    xy = jagged_line(start, start + length * np.array([np.cos(angle), np.sin(angle)]), spec.jaggedness, rng)
    w0 = parent.half_width[k] * rng.uniform(0.4, 0.8)
    # Beyond its root (where it is on its parent), stop short of every earlier crack.
    away = np.hypot(*(xy - start).T) > 4 * gap
    stop = _first(away & (occ.distance(xy) < 2 * gap))
    if stop is not None:
        xy = xy[: max(stop, 2)]
    return Path(xy=xy, half_width=w0 * (1.0 - arc_fraction(xy)) ** 0.7)


def fracture_paths(
    spec: CrackSpec, half_width: float, rng: np.random.Generator, min_half_width: float = 0.0
) -> list[Path]:
    """Main cracks (``spec.count``) and their branches (``spec.branches`` each), in patch units;
    ``half_width`` (patch units) is the half-width at the widest point, ``min_half_width`` the
    renderer's floor (so paths that stop short of each other stay apart in the mask too)."""
    gap = 2.0 * max(half_width, min_half_width) + 2.0 / _CELLS  # centre lines closer than this touch
    occ = _Occupancy()
    paths: list[Path] = []
    direction = rng.uniform(0.0, np.pi)  # the patch's main crack direction
    for _ in range(max(1, spec.count)):
        main = _main(spec, direction, half_width, gap, occ, rng)
        if not main.half_width.any():  # cut short to nothing by an earlier crack: no crack, no branches
            continue
        occ.add(main.xy)
        paths.append(main)
        for _ in range(max(0, spec.branches)):
            br = _branch(main, spec, gap, occ, rng)
            occ.add(br.xy)
            paths.append(br)
    return paths
