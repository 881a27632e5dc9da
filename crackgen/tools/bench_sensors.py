"""Sensor-stage benchmark on a real sample surface: BVH build, GT view, ToF, LiDAR, projection.

Run: ``crackgen bench --component sensors --component-args='--samples N --json'``. Uses the default
recipe (512^2 RGB, ToF 320x240 with mixed pixels, 16-beam LiDAR, 384^2 grid) and
the real crack map / material albedo, so the mixed-pixel count is realistic.
Times are medians over samples, in milliseconds (wall, and ``_cpu``: process CPU
time summed over open3d's threads, which is steadier on a shared machine); the BVH build is reported
separately because the pipeline builds one caster per sample and shares it.
"""
from __future__ import annotations

import argparse
import json
import time

import numpy as np


def bench(samples: int = 3, grid_px: int | None = None) -> dict[str, float]:
    from crackgen.config.recipe import Recipe
    from crackgen.config.spec import make_spec
    from crackgen.procedural.crackmap import crack_map
    from crackgen.procedural.materials import material_maps
    from crackgen.procedural.surface import surface_faces, surface_uvs, surface_vertices
    from crackgen.sim.groundtruth import view_ground_truth
    from crackgen.sim.raycast import MeshRaycaster
    from crackgen.sim.rig import make_rig
    from crackgen.sim.sensors import sensor_rng
    from crackgen.sim.sensors.lidar import simulate_lidar
    from crackgen.sim.sensors.tof import albedo_from_map, simulate_tof

    recipe = Recipe()
    rows: dict[str, list[float]] = {k: [] for k in ("bvh_build", "groundtruth", "tof", "lidar", "sensors_total")}
    extra: dict[str, list[float]] = {"tof_mixed_px": [], "tof_fill_rgb": [], "lidar_points": []}
    for i in range(samples):
        spec = make_spec(recipe, i)
        g = grid_px or spec.surface.grid_px
        rig = make_rig(spec)
        cm = crack_map(spec.crack, size_px=spec.surface.crackmap_px, size_m=spec.surface.size_m)
        maps = material_maps(spec.material, cm)
        verts, faces, uvs = surface_vertices(cm, g), np.asarray(surface_faces(g)), np.asarray(surface_uvs(g))
        clock = [(time.perf_counter(), time.process_time())]
        caster = MeshRaycaster(verts, faces, uvs)
        caster.cast(np.zeros((1, 3)), np.array([[0.0, 0.0, -1.0]]))  # open3d builds the BVH lazily
        clock.append((time.perf_counter(), time.process_time()))
        view_ground_truth(rig.rgb, caster, cm.mask)
        clock.append((time.perf_counter(), time.process_time()))
        tof = simulate_tof(spec.tof, rig, caster, albedo_from_map(maps.albedo), sensor_rng(spec.tof.seed))
        clock.append((time.perf_counter(), time.process_time()))
        lid = simulate_lidar(spec.lidar, rig, caster, sensor_rng(spec.lidar.seed))
        clock.append((time.perf_counter(), time.process_time()))
        spans = {"bvh_build": (0, 1), "groundtruth": (1, 2), "tof": (2, 3), "lidar": (3, 4), "sensors_total": (2, 4)}
        for k, (a, b) in spans.items():
            rows[k].append((clock[b][0] - clock[a][0]) * 1e3)
            rows.setdefault(k + "_cpu", []).append((clock[b][1] - clock[a][1]) * 1e3)
        extra["tof_mixed_px"].append(float(tof.mixed.sum()))
        extra["tof_fill_rgb"].append(float((tof.depth_rgb > 0).mean()))
        extra["lidar_points"].append(float(len(lid.points_world)))
    out = {f"{k}_ms": float(np.median(v)) for k, v in rows.items()}
    out.update({k: float(np.median(v)) for k, v in extra.items()})
    return out


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--samples", type=int, default=3)
    ap.add_argument("--grid-px", type=int, default=None)
    ap.add_argument("--json", action="store_true")
    a = ap.parse_args(argv)
    res = bench(a.samples, a.grid_px)
    if a.json:
        print(json.dumps(res))
    else:
        for k, v in res.items():
            print(f"{k:>20s}  {v:10.2f}")


if __name__ == "__main__":
    main()
