"""Material-map benchmark: seconds per ``material_maps`` call for each material family.

Why a tool and not part of ``procedural.materials``: timing is not the library's
job, and these figures only go into issue notes (``crackgen bench
--component materials --component-args='--px 1024'``); nothing asserts them.
"""
from __future__ import annotations

import argparse
import json
import time

from crackgen.config.spec import CrackSpec, DistractorSpec, MaterialSpec
from crackgen.procedural.crackmap import crack_map
from crackgen.procedural.materials import list_families, material_maps


def bench_materials(
    families: list[str] | None = None, px: int = 1024, size_m: float = 2.5, repeats: int = 3, seed: int = 0
) -> dict[str, float]:
    """Best-of-``repeats`` seconds per ``material_maps`` call per family, after a warm-up call
    (numba compilation excluded)."""
    crack = CrackSpec(freq_x=3.0, freq_y=3.0, octaves=5, persistence=0.5, lacunarity=2.0, threshold=0.03,
                      depth_m=0.01, noise_seed=seed, offset_u=0.0, offset_v=0.0)
    cm = crack_map(crack, px, size_m, measure=False)
    out = {}
    for fam in families or list_families():
        spec = MaterialSpec(family=fam, seed=seed, texture_px=px, hue_shift=0.0, value_scale=1.0,
                            roughness_offset=0.0, crack_darkening=0.3, crack_roughness=0.95,
                            distractors=[DistractorSpec("stain", seed + 1)])
        material_maps(spec, cm)
        times = []
        for _ in range(repeats):
            t0 = time.perf_counter()
            material_maps(spec, cm)
            times.append(time.perf_counter() - t0)
        out[fam] = min(times)
    return out


def main(argv: list[str] | None = None) -> int:
    """Print ``bench_materials`` as one JSON object (family -> seconds)."""
    ap = argparse.ArgumentParser(prog="python -m crackgen.tools.bench_materials", description=__doc__.splitlines()[0])
    ap.add_argument("--families", default="", help="comma-separated; default all")
    ap.add_argument("--px", type=int, default=1024, help="texture side in pixels")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)
    fams = [f.strip() for f in args.families.split(",") if f.strip()] or None
    print(json.dumps(bench_materials(fams, px=args.px, repeats=args.repeats)))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
