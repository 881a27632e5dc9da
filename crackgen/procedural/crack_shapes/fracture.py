"""``fracture`` family: open cracks grown along a main direction, jagged, branching, tapering.

Each main crack is a straight chord at a random angle through a random point of the middle
of the patch, 0.7-1.4 patch sides long (so it often leaves the patch), made jagged at every
octave by midpoint displacement. Its half-width peaks at ``width_m / 2`` (the recipe's width
at the widest point, exactly) near the middle and tapers as sqrt-ish to the tips, with a mild
smooth wobble. Branches leave at 20-60 deg from a point on the middle of the parent, start at
40-80 % of the parent's local width and taper to nothing at their free end.
"""

from __future__ import annotations

import numpy as np

from crackgen.config.spec import CrackSpec
from crackgen.procedural.crack_shapes.paths import Path, arc_fraction, jagged_line, smooth_wobble

__all__ = ["fracture_paths", "main_profile"]


def main_profile(s: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    """Relative half-width along a main crack (max exactly 1, 0 at both tips)."""
    base = np.sqrt(np.clip(4.0 * s * (1.0 - s), 0.0, 1.0))
    prof = base * smooth_wobble(s, rng, 0.2)
    return prof / prof.max()


def _branch(parent: Path, spec: CrackSpec, rng: np.random.Generator) -> Path:
    s = arc_fraction(parent.xy)
    k = int(np.searchsorted(s, rng.uniform(0.2, 0.8)))
    k = min(max(k, 1), len(s) - 2)
    span = max(2, len(s) // 20)  # tangent over ~5 % of the parent, not the jagged local segment
    tang = parent.xy[min(k + span, len(s) - 1)] - parent.xy[max(k - span, 0)]
    angle = np.arctan2(tang[1], tang[0]) + rng.choice([-1.0, 1.0]) * np.radians(rng.uniform(20.0, 60.0))
    length = rng.uniform(0.2, 0.5) * float(np.hypot(*(parent.xy[-1] - parent.xy[0])))
    start = parent.xy[k]
    end = start + length * np.array([np.cos(angle), np.sin(angle)])
    xy = jagged_line(start, end, spec.jaggedness, rng)
    sb = arc_fraction(xy)
    w0 = parent.half_width[k] * rng.uniform(0.4, 0.8)
    return Path(xy=xy, half_width=w0 * (1.0 - sb) ** 0.7)


def fracture_paths(spec: CrackSpec, half_width: float, rng: np.random.Generator) -> list[Path]:
    """Main cracks (``spec.count``) and their branches (``spec.branches`` each), in patch units;
    ``half_width`` (patch units) is the half-width at the widest point."""
    n = 1.0
    paths: list[Path] = []
    for _ in range(max(1, spec.count)):
        centre = rng.uniform(0.2 * n, 0.8 * n, 2)
        angle = rng.uniform(0.0, np.pi)
        half = 0.5 * rng.uniform(0.7, 1.4) * n * np.array([np.cos(angle), np.sin(angle)])
        xy = jagged_line(centre - half, centre + half, spec.jaggedness, rng)
        main = Path(xy=xy, half_width=half_width * main_profile(arc_fraction(xy), rng))
        paths.append(main)
        paths.extend(_branch(main, spec, rng) for _ in range(max(0, spec.branches)))
    return paths
