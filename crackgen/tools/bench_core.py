"""Micro-benchmarks of the numpy core: crack map, skeleton, skeleton diameters, crack measurement, surface mesh.

Run ``crackgen bench --component core --component-args='--px 1024 --grid 384 --repeat 5'``; prints the
median seconds per stage (after one warm-up call, so numba compilation is excluded).
Speed is reported here, never asserted in tests.
"""

from __future__ import annotations

import argparse
import json
import time
from collections.abc import Callable

import numpy as np


def _median_time(fn: Callable[[], object], repeat: int) -> float:
    fn()  # warm-up (numba JIT / caches)
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times))


def bench_core(px: int = 1024, grid: int = 384, octaves: int = 6, repeat: int = 5, index: int = 0) -> dict[str, float]:
    """Median seconds per stage for sample ``index`` of the default recipe (octaves forced)."""
    import dataclasses

    from crackgen.config.recipe import Recipe
    from crackgen.config.spec import make_spec
    from crackgen.procedural.crackmap import crack_map
    from crackgen.procedural.surface import surface_mesh, surface_vertices
    from fusion.measure.crack_length import crack_components, skeleton
    from fusion.measure.crack_measure import measure_cracks

    spec = make_spec(Recipe(), index)
    cs = dataclasses.replace(spec.crack, octaves=octaves)
    size = spec.surface.size_m
    cm = crack_map(cs, px, size, measure=False)
    skel = skeleton(cm.mask)
    return {
        "crack_map_s": _median_time(lambda: crack_map(cs, px, size, measure=False), repeat),
        "skeleton_s": _median_time(lambda: skeleton(cm.mask), repeat),
        "length_s": _median_time(lambda: crack_components(skel, size / px, is_skeleton=True), repeat),
        "measure_s": _median_time(lambda: measure_cracks(cm.mask, size / px), repeat),
        "surface_vertices_s": _median_time(lambda: surface_vertices(cm, grid), repeat),
        "surface_mesh_s": _median_time(lambda: surface_mesh(cm, grid), repeat),
    }


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--px", type=int, default=1024, help="crack map size (px per side)")
    ap.add_argument("--grid", type=int, default=384, help="mesh vertices per side")
    ap.add_argument("--octaves", type=int, default=6)
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--json", action="store_true", help="print JSON instead of a table")
    a = ap.parse_args(argv)
    res = bench_core(a.px, a.grid, a.octaves, a.repeat)
    if a.json:
        print(json.dumps(res))
    else:
        for k, v in res.items():
            print(f"{k:<22}{v * 1000:9.1f} ms")


if __name__ == "__main__":
    main()
