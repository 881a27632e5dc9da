"""``network`` family: map / alligator cracking along perturbed Voronoi cell boundaries.

``cells`` seed points per patch area, uniform over the patch and a quarter-patch border
around it (so cells at the edge are closed by neighbours outside); every finite Voronoi
ridge near the patch becomes a jagged path (midpoint displacement), a ``gaps`` share of them
is dropped so the net is not perfect. Each boundary has its own width, 50-100 % of
``width_m`` (the widest is exactly ``width_m``), with a mild smooth wobble along it.
"""

from __future__ import annotations

import numpy as np
from scipy.spatial import Voronoi

from crackgen.config.spec import CrackSpec
from crackgen.procedural.crack_shapes.paths import Path, arc_fraction, jagged_line, smooth_wobble

__all__ = ["network_paths"]

_BORDER = 0.25  # extra margin (fraction of the patch) sown with cells on every side


def network_paths(spec: CrackSpec, half_width: float, rng: np.random.Generator) -> list[Path]:
    """Cell-boundary paths in patch units; ``half_width`` (patch units) at the widest boundary."""
    n = 1.0
    lo, hi = -_BORDER * n, (1 + _BORDER) * n
    count = max(4, int(round(spec.cells * (1 + 2 * _BORDER) ** 2)))
    vor = Voronoi(rng.uniform(lo, hi, (count, 2)))
    ridges = [r for r in vor.ridge_vertices if -1 not in r]
    ends = vor.vertices[np.array(ridges, dtype=np.intp)] if ridges else np.zeros((0, 2, 2))
    inside = np.all((ends >= -0.1 * n) & (ends <= 1.1 * n), axis=2)  # (ridges, 2 ends)
    near = inside.any(axis=1) if len(ends) else np.zeros(0, bool)
    # Draw gap coin, width factor and wobble for every ridge (fixed count per ridge).
    keep = rng.random(len(ends)) >= spec.gaps
    factor = rng.uniform(0.5, 1.0, len(ends))
    chosen = np.nonzero(keep & near)[0]
    if len(chosen):
        factor = factor / factor[chosen].max()
    paths = []
    for e in chosen:
        xy = jagged_line(ends[e, 0], ends[e, 1], spec.jaggedness, rng)
        w = half_width * factor[e] * smooth_wobble(arc_fraction(xy), rng, 0.1)
        paths.append(Path(xy=xy, half_width=np.minimum(w, half_width)))
    return paths
