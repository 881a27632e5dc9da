"""Timing and memory of the live scene: per-sample update vs render, RSS over many samples.

Why here: the worker's overhead target (update + read-back <= 10% of the render) and
flat memory are properties of this package; ``crackgen bench`` or a developer can call
``bench_live_scene`` directly. Inputs (crack map, mesh, textures, shadow alpha) are
prepared before timing, cycling through ``distinct`` samples, so only the Blender side
is measured.
"""
from __future__ import annotations

import time

import numpy as np

from crackgen.blender.scene import LiveScene
from crackgen.config.recipe import Recipe
from crackgen.config.spec import make_spec
from crackgen.procedural.crackmap import crack_map
from crackgen.procedural.materials import material_maps
from crackgen.procedural.shadow_pattern import shadow_alpha
from crackgen.procedural.surface import surface_vertices, with_steps
from crackgen.sim.rig import make_rig


def bench_live_scene(recipe: Recipe, samples: int = 5, distinct: int = 2, shadow_px: int = 256) -> dict:
    """Median per-stage seconds and RSS (MB) after each sample; the first sample is a warm-up."""
    import psutil

    prepared = []
    for i in range(max(1, distinct)):
        s = make_spec(recipe, i)
        cm = crack_map(s.crack, recipe.surface.crackmap_px, s.surface.size_m, measure=False)
        prepared.append((s, make_rig(s), with_steps(surface_vertices(cm, recipe.surface.grid_px), s.surface.steps), material_maps(s.material, cm), shadow_alpha(s.shadow, shadow_px)))
    max_lights = max(len(p[0].lights) for p in prepared)
    r, c = recipe.render, recipe.camera
    t0 = time.perf_counter()
    live = LiveScene(
        recipe.surface.grid_px, recipe.material.texture_px, c.width_px, c.height_px, stereo=recipe.stereo.enabled,
        threads=r.threads, device=r.device, samples=r.samples, denoise=r.denoise, max_bounces=r.max_bounces,
        max_lights=max(8, max_lights), shadow_px=shadow_px, persistent_data=r.persistent_data,
    )
    build_s = time.perf_counter() - t0
    proc = psutil.Process()
    rows, rss = [], []
    try:
        for k in range(samples + 1):
            spec, rig, verts, maps, alpha = prepared[k % len(prepared)]
            t0 = time.perf_counter()
            live.update(spec, rig, verts, maps, alpha)
            t1 = time.perf_counter()
            out = live.render()
            t2 = time.perf_counter()
            rss.append(proc.memory_info().rss / 2**20)
            if k == 0:
                continue
            rows.append({"update_s": t1 - t0, "render_call_s": t2 - t1, "blender_s": out.meta["blender_s"], "readback_s": out.meta["readback_s"], "total_s": t2 - t0})
    finally:
        live.close()
    med = {k: float(np.median([row[k] for row in rows])) for k in rows[0]} if rows else {}
    overhead = med.get("total_s", 0.0) - med.get("blender_s", 0.0)
    return {
        "build_s": build_s,
        "median": med,
        "overhead_fraction": overhead / med["blender_s"] if rows else float("nan"),
        "rss_mb": rss,
        "rss_growth_mb": rss[-1] - rss[1] if len(rss) > 1 else 0.0,
        "counts": live.datablock_counts(),
    }
