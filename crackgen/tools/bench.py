"""`crackgen bench RECIPE`: where the time of one sample goes, stage by stage.

Runs the real ``SampleProducer`` in this process (one warm-up sample first, which pays
for bpy import, scene build and JIT compiles), then N timed samples. Encoding and the
tar write are timed separately with the real codecs and ``ShardWriter`` into a temp
dir. The headline figure is the *overhead ratio* (everything but the render divided by
the render): the share of a sample's time the generator itself adds (P1 figure).
"""
from __future__ import annotations

import os
import statistics
import tempfile
import time
from typing import Any

import numpy as np

from crackgen.config.recipe import Recipe

# table rows: (label, stage keys summed)
ROWS = (
    ("spec", ("spec",)),
    ("crack map", ("crackmap",)),
    ("surface", ("surface",)),
    ("materials", ("materials",)),
    ("shadow pattern", ("shadow",)),
    ("scene update", ("scene_update",)),
    ("render", ("render",)),
    ("ray cast + GT", ("raycast", "groundtruth")),
    ("sensors", ("tof", "lidar", "stereo")),
    ("encode", ("encode",)),
    ("write", ("write",)),
)


def bench(recipe: Recipe, samples: int = 5, threads: int = 0, progress: bool = True) -> dict[str, Any]:
    """Median and mean per-stage seconds over ``samples`` samples after one warm-up sample.

    With ``[camera] views_per_scene`` = K the timed samples start at the second scene (index K: the warm-up
    built the first) and the mean is the per-sample cost (one view in K builds the scene; the median hides it);
    give a multiple of K samples."""
    import psutil
    from tqdm import tqdm

    from crackgen.datagen.pipeline import SampleProducer
    from crackgen.shards import ShardWriter, sample_key
    from crackgen.shards.codecs import encode_member

    threads = threads or recipe.render.threads or (os.cpu_count() or 1)
    producer = SampleProducer(recipe, threads=threads)
    t0 = time.perf_counter()
    producer.make(0)
    warmup_s = time.perf_counter() - t0
    proc = psutil.Process()
    rss_start = proc.memory_info().rss / 2**20  # after the warm-up: scene built, caches filled
    per: list[dict[str, float]] = []
    sizes: list[int] = []
    rss_trace: list[float] = []  # after each sample: a slow leak shows as a trend, not only as end - start
    first = recipe.camera.views_per_scene  # the first sample of the second scene (1 with one view per scene)
    with tempfile.TemporaryDirectory(prefix="crackgen_bench_") as tmp, ShardWriter(tmp, 0) as writer:
        for i in tqdm(range(first, first + samples), desc="bench", unit="sample", disable=not progress):
            t_start = time.perf_counter()
            s = producer.make(i)
            t = dict(s.timings)
            members = {**s.members, "json": s.meta}
            t1 = time.perf_counter()
            encoded = {n: encode_member(n, v, name=n) for n, v in members.items()}
            t["encode"] = time.perf_counter() - t1
            sizes.append(sum(len(b) for b in encoded.values()))
            t2 = time.perf_counter()
            writer.add(sample_key(0, i), members)
            # add() encodes again (it validates its input); the write share is what it took beyond encoding
            t["write"] = max(0.0, time.perf_counter() - t2 - t["encode"])
            t["total"] = time.perf_counter() - t_start
            per.append(t)
            rss_trace.append(proc.memory_info().rss / 2**20)
    rss_end = proc.memory_info().rss / 2**20
    producer.close()
    stages = {}
    for label, keys in ROWS:
        stages[label] = statistics.median(sum(t.get(k, 0.0) for k in keys) for t in per)
    means = {label: statistics.fmean(sum(t.get(k, 0.0) for k in keys) for t in per) for label, keys in ROWS}
    total = statistics.median(t["total"] for t in per)
    render = stages["render"]
    r = recipe
    return {
        "recipe": {"name": r.dataset.name, "hash": r.hash[:16], "image": f"{r.camera.width_px}x{r.camera.height_px}",
                   "spp": r.render.samples, "grid_px": r.surface.grid_px, "texture_px": r.material.texture_px,
                   "crackmap_px": r.surface.crackmap_px, "tof": r.tof.enabled, "lidar": r.lidar.enabled,
                   "stereo": r.stereo.enabled, "views_per_scene": r.camera.views_per_scene},
        "samples": samples,
        "threads": threads,
        "warmup_s": warmup_s,
        "median_s": stages,
        "median_total_s": total,
        "mean_s": means,
        "mean_total_s": statistics.fmean(t["total"] for t in per),
        "render_fraction": render / total if total > 0 else None,
        "overhead_ratio": (total - render) / render if render > 0 else None,
        "median_sample_bytes": statistics.median(sizes) if sizes else 0,
        "samples_per_hour_one_worker": 3600.0 / total if total > 0 else None,
        "rss_mb_after_warmup": rss_start,
        "rss_mb_end": rss_end,
        "rss_growth_mb": rss_end - rss_start,
        "rss_mb_max": max(rss_trace, default=rss_start),
        "rss_trend_mb_per_100": rss_trend_per_100(rss_trace),
        "rss_trace_mb": [round(v, 1) for v in rss_trace],
    }


def rss_trend_per_100(trace: list[float]) -> float | None:
    """Least-squares slope of RSS over the second half of the samples, in MB per 100 samples: the steady-state
    drift once caches and allocator pools have filled (None under 10 samples)."""
    if len(trace) < 10:
        return None
    half = trace[len(trace) // 2:]
    slope = np.polyfit(np.arange(len(half), dtype=float), np.asarray(half, dtype=float), 1)[0]
    return float(slope * 100.0)


def format_table(res: dict[str, Any]) -> str:
    r = res["recipe"]
    total = res["median_total_s"]
    lines = [
        f"crackgen bench: {r['name']} ({r['image']} px, {r['spp']} spp, grid {r['grid_px']}, texture {r['texture_px']}, "
        f"crack map {r['crackmap_px']}; tof={r['tof']} lidar={r['lidar']} stereo={r['stereo']})",
        f"{res['samples']} timed samples after a {res['warmup_s']:.1f} s warm-up, {res['threads']} Cycles threads",
        f"{'stage':<16}{'median s':>10}{'share':>8}{'mean s':>10}",
        "-" * 44,
    ]
    means = res.get("mean_s", {})
    for label, v in res["median_s"].items():
        mean = f"{means[label]:>10.4f}" if label in means else ""
        lines.append(f"{label:<16}{v:>10.4f}{(v / total * 100 if total else 0):>7.1f}%{mean}")
    lines.append("-" * 44)
    lines.append(f"{'total':<16}{total:>10.4f}{'':>8}" + (f"{res['mean_total_s']:>10.4f}" if "mean_total_s" in res else ""))
    if r.get("views_per_scene", 1) > 1:
        lines.append(f"{r['views_per_scene']} views per scene: the mean is the cost per sample (one view in "
                     f"{r['views_per_scene']} builds the scene)")
    if res["overhead_ratio"] is not None:
        lines.append(f"render share {res['render_fraction'] * 100:.1f}%, overhead ratio (non-render / render) "
                     f"{res['overhead_ratio']:.3f}")
    lines.append(f"median sample size {res['median_sample_bytes'] / 1e3:.0f} kB; "
                 f"{res['samples_per_hour_one_worker']:.0f} samples/h per worker at this thread count")
    if "rss_growth_mb" in res:
        lines.append(f"memory (RSS) {res['rss_mb_after_warmup']:.0f} MB after the warm-up, {res['rss_mb_end']:.0f} MB "
                     f"after {res['samples']} samples: growth {res['rss_growth_mb']:+.1f} MB, max "
                     f"{res.get('rss_mb_max', res['rss_mb_end']):.0f} MB")
        if res.get("rss_trend_mb_per_100") is not None:
            lines.append(f"RSS trend over the second half: {res['rss_trend_mb_per_100']:+.1f} MB per 100 samples")
    return "\n".join(lines)
