"""`crackgen bench RECIPE --sweep KEY=V1,V2 ...`: seconds per sample against image error.

Each setting (a recipe variant and a worker layout, see ``sweep_args``) renders the same
sample indices with the full sample pipeline in fresh worker processes: one warm-up sample
(scene build, imports, JIT; a different index) per worker, then the timed samples, started
together behind a barrier. s/sample is wall time / samples over all workers, so
``layout=2x1`` against ``layout=1x2`` is a throughput comparison on the same cores.

Each render is compared with a high-sample reference of the same sample: the baseline recipe
with ``render.samples = --reference-samples`` (256) and no denoiser. References are cached
on disk under a key of (reference recipe hash, index, crackgen version), so re-runs and
further sweeps only render the new settings. Every run sets ``label.invisible = "keep"``: a
``redraw`` label policy would pick a different crack whenever the render changes, and the
rows must compare one scene. The crack region is the pixel-centre thesis mask of the
reference run, grown by ``--dilate`` pixels. The first sample of every row (and of the
reference) is also written as an 8-bit PNG under ``previews/``.

Content keys (``material.texture_px``, ``surface.grid_px``...) are compared with the same
baseline-content reference, so their rows measure what the change costs in the image, render
noise included. The procedural textures are not the same pattern at another ``texture_px``
(a 128 px albedo area-downsampled to 64 px correlates 0.36 with the 64 px one), so those rows'
whole-image figures mostly measure a different texture; judge them by the crack columns and
the previews.
"""
from __future__ import annotations

import csv
import hashlib
import json
import math
import multiprocessing as mp
import os
import queue as queue_mod
import statistics
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

import crackgen
from crackgen.config.recipe import Recipe
from crackgen.errors import CrackgenError
from crackgen.tools.image_error import image_error
from crackgen.tools.sweep_args import Layout, Setting, apply_overrides, resolve

SWEEP_FIXED = {"label.invisible": "keep"}  # one scene per index in every row (see module doc)
COLUMNS = ("setting", "layout", "s_per_sample", "cycles_share", "psnr", "ssim", "crack_mae", "crack_psnr",
           "rss_growth_mb", "samples")


class BenchSweepError(CrackgenError, RuntimeError):
    """A sweep that could not finish a setting (names it); rows already written stay on disk."""


@dataclass
class SweepOptions:
    samples: int = 5
    first_index: int = 0
    reference_samples: int = 256
    workers: int = 1
    threads: int = 0  # per worker; 0 = cores // workers
    dilate_px: int = 3
    cache_dir: str = ""  # "" = $XDG_CACHE_HOME/crackgen/bench_refs
    out: str = "bench_sweep"
    cores: int = field(default_factory=lambda: os.cpu_count() or 1)

    def indices(self) -> list[int]:
        return list(range(self.first_index, self.first_index + self.samples))


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "crackgen" / "bench_refs"


# ---- worker processes -----------------------------------------------------------------------------
def _worker(recipe_json: str, indices: list[int], warmup: int | None, threads: int, keep_mask: bool,
            barrier: Any, out: Any) -> None:
    """One worker: build the producer, warm up, wait for the others, render ``indices``, report each."""
    try:
        import psutil

        from crackgen.datagen.pipeline import SampleProducer

        recipe = Recipe.model_validate_json(recipe_json)
        producer = SampleProducer(recipe, threads=threads, keep_linear=True)
        if warmup is not None:
            producer.make(warmup)
        proc = psutil.Process()
        rss0 = proc.memory_info().rss / 2**20
        barrier.wait()
        t_start = time.perf_counter()
        for i in indices:
            t0 = time.perf_counter()
            s = producer.make(i)
            total = time.perf_counter() - t0
            mask = s.members.get("mask_thesis.png", s.members["mask.png"]) if keep_mask else None
            out.put(("sample", i, total, s.timings.get("render", 0.0), s.rgb_linear, mask))
        t_end = time.perf_counter()
        producer.close()
        out.put(("done", t_start, t_end, rss0, proc.memory_info().rss / 2**20))
    except BaseException as exc:  # reported to the parent, which names the setting
        msg = str(exc).strip().splitlines()
        out.put(("error", f"{type(exc).__name__}: {msg[0] if msg else ''}"))


@dataclass
class RunResult:
    renders: dict[int, np.ndarray]
    masks: dict[int, np.ndarray]
    totals: dict[int, float]  # index -> seconds of the whole sample
    cycles: dict[int, float]  # index -> seconds of its render stage (Cycles + EXR read-back)
    wall_s: float
    rss_growth_mb: float  # largest growth of one worker from after its warm-up to its last sample
    layout: Layout | None = None  # as run: workers, Cycles threads per worker (0 resolved)


def run_renders(recipe: Recipe, indices: list[int], layout: Layout, cores: int, warmup: bool = True,
                keep_mask: bool = False, on_sample: Any = None, name: str = "") -> RunResult:
    """Render ``indices`` with ``layout.workers`` spawned processes (round-robin split)."""
    workers = max(1, min(layout.workers, len(indices)))
    threads = layout.threads or max(1, cores // workers)
    ctx = mp.get_context("spawn")
    out = ctx.Queue()
    barrier = ctx.Barrier(workers)
    warm_index = max(indices) + 1 if warmup else None
    text = recipe.model_dump_json()
    procs = [ctx.Process(target=_worker, args=(text, indices[w::workers], warm_index, threads, keep_mask, barrier, out),
                         daemon=True) for w in range(workers)]
    for p in procs:
        p.start()
    res = RunResult({}, {}, {}, {}, 0.0, 0.0, Layout(workers, threads))
    spans, done = [], 0
    try:
        while done < workers:
            try:
                msg = out.get(timeout=5.0)
            except queue_mod.Empty:
                if any(p.exitcode not in (None, 0) for p in procs):
                    raise BenchSweepError(f"{name}: a worker process died (exit code "
                                          f"{[p.exitcode for p in procs]})") from None
                continue
            if msg[0] == "error":
                raise BenchSweepError(f"{name}: {msg[1]}")
            if msg[0] == "sample":
                _, i, total, cyc, lin, mask = msg
                res.renders[i] = lin
                if mask is not None:
                    res.masks[i] = mask
                res.totals[i] = total
                res.cycles[i] = cyc
                if on_sample:
                    on_sample()
            else:
                _, t0, t1, rss0, rss1 = msg
                spans.append((t0, t1))
                res.rss_growth_mb = max(res.rss_growth_mb, rss1 - rss0)
                done += 1
    finally:
        for p in procs:
            p.join(timeout=30)
            if p.is_alive():
                p.terminate()
    # perf_counter is CLOCK_MONOTONIC on Linux: one clock for all processes
    res.wall_s = max(t1 for _, t1 in spans) - min(t0 for t0, _ in spans)
    return res


# ---- references -----------------------------------------------------------------------------------
def reference_recipe(recipe: Recipe, spp: int) -> Recipe:
    return apply_overrides(recipe, {"render.samples": spp, "render.denoise": False}, "reference")


def reference_key(ref: Recipe, index: int) -> str:
    return hashlib.sha256(f"{ref.hash}:{index}:{crackgen.__version__}".encode()).hexdigest()[:24]


def load_references(ref: Recipe, indices: list[int], cache: Path, cores: int, on_sample: Any = None) -> dict[int, tuple]:
    """(linear RGB, crack mask) per index, rendered once and cached as NPZ files."""
    cache.mkdir(parents=True, exist_ok=True)
    paths = {i: cache / f"{reference_key(ref, i)}.npz" for i in indices}
    todo = [i for i in indices if not paths[i].is_file()]
    if todo:
        res = run_renders(ref, todo, Layout(1, cores), cores, warmup=False, keep_mask=True, on_sample=on_sample,
                          name="reference")
        for i in todo:
            tmp = paths[i].with_suffix(".tmp.npz")
            np.savez_compressed(tmp, rgb_linear=res.renders[i], mask=res.masks[i])
            os.replace(tmp, paths[i])
    out = {}
    for i in indices:
        with np.load(paths[i]) as z:
            out[i] = (z["rgb_linear"], z["mask"])
    return out


# ---- the sweep ------------------------------------------------------------------------------------
def _mean(xs: list[float]) -> float:
    xs = [x for x in xs if not math.isnan(x)]
    return float(statistics.fmean(xs)) if xs else math.nan


def summarise(setting: Setting, layout: Layout, res: RunResult, refs: dict[int, tuple], dilate_px: int) -> dict[str, Any]:
    order = sorted(res.renders)
    errs = [image_error(res.renders[i], refs[i][0], refs[i][1], dilate_px) for i in order]
    n = len(order)

    def finite_mean(key: str) -> float:  # inf (identical to the reference) and NaN (no crack) left out
        xs = [e[key] for e in errs if math.isfinite(e[key])]
        return _mean(xs) if xs else (math.inf if any(e[key] == math.inf for e in errs) else math.nan)

    return {
        "setting": setting.label,
        "layout": (res.layout or layout).label(),
        "s_per_sample": res.wall_s / n if n else math.nan,
        "cycles_share": sum(res.cycles.values()) / sum(res.totals.values()) if n else math.nan,
        "psnr": finite_mean("psnr"),
        "ssim": _mean([e["ssim"] for e in errs]),
        "crack_mae": _mean([e["crack_mae"] for e in errs]),
        "crack_psnr": finite_mean("crack_psnr"),
        "rss_growth_mb": res.rss_growth_mb,
        "samples": n,
        "per_sample": [{"index": i, "total_s": res.totals[i], **e} for i, e in zip(order, errs)],
    }


def format_rows(rows: list[dict[str, Any]], header: str = "") -> str:
    lines = [header] if header else []
    lines.append(f"{'setting':<48}{'layout':>7}{'s/sample':>10}{'Cycles':>8}{'PSNR dB':>9}{'SSIM':>8}"
                 f"{'crack MAE':>11}{'crack PSNR':>11}")
    lines.append("-" * 112)
    for r in rows:
        lines.append(f"{r['setting'][:48]:<48}{r['layout']:>7}{r['s_per_sample']:>10.2f}{r['cycles_share'] * 100:>7.0f}%"
                     f"{r['psnr']:>9.2f}{r['ssim']:>8.4f}{r['crack_mae']:>11.4f}{r['crack_psnr']:>11.2f}")
    return "\n".join(lines)


def format_markdown(rows: list[dict[str, Any]], header: str) -> str:
    out = [f"<!-- {header} -->", "", "| setting | layout | s/sample | Cycles share | PSNR (dB, linear) | SSIM (sRGB) | "
           "crack MAE (linear) | crack PSNR (dB) |", "|---|---|---|---|---|---|---|---|"]
    for r in rows:
        out.append(f"| `{r['setting']}` | {r['layout']} | {r['s_per_sample']:.2f} | {r['cycles_share'] * 100:.0f}% | "
                   f"{r['psnr']:.2f} | {r['ssim']:.4f} | {r['crack_mae']:.4f} | {r['crack_psnr']:.2f} |")
    return "\n".join(out) + "\n"


def _slug(label: str) -> str:
    return "".join(c if c.isalnum() or c in "._=-" else "_" for c in label)[:120] or "setting"


def write_preview(out: Path, label: str, index: int, rgb_linear: np.ndarray) -> Path:
    """The 8-bit sRGB image of one render, to look at what the figures say (previews/SETTING_INDEX.png)."""
    import cv2

    from crackgen.postrender.camera_effects import linear_to_srgb, quantise

    path = out / "previews" / f"{_slug(label)}_{index:06d}.png"
    path.parent.mkdir(parents=True, exist_ok=True)
    cv2.imwrite(str(path), cv2.cvtColor(quantise(linear_to_srgb(rgb_linear)), cv2.COLOR_RGB2BGR))
    return path


def write_outputs(rows: list[dict[str, Any]], meta: dict[str, Any], out: Path) -> list[Path]:
    out.mkdir(parents=True, exist_ok=True)
    paths = [out / "sweep.csv", out / "sweep.json", out / "sweep.md"]
    with open(paths[0].with_suffix(".csv.tmp"), "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(COLUMNS)
        for r in rows:
            w.writerow([r[c] for c in COLUMNS])
    paths[1].with_suffix(".json.tmp").write_text(json.dumps({**meta, "rows": rows}, indent=1))
    paths[2].with_suffix(".md.tmp").write_text(format_markdown(rows, meta["header"]))
    for p in paths:
        os.replace(p.with_suffix(p.suffix + ".tmp"), p)
    return paths


def sweep(recipe: Recipe, settings: list[Setting], opts: SweepOptions, progress: bool = True) -> dict[str, Any]:
    """Run every setting; rows are written to ``opts.out`` after each one (a crash keeps them)."""
    from tqdm import tqdm

    base = apply_overrides(recipe, SWEEP_FIXED, "sweep")
    variants = [(s, apply_overrides(r, SWEEP_FIXED, "sweep")) for s, r in resolve(recipe, settings)]
    indices = opts.indices()
    ref = reference_recipe(base, opts.reference_samples)
    cache = Path(opts.cache_dir) if opts.cache_dir else default_cache_dir()
    default_layout = Layout(opts.workers, opts.threads)
    header = (f"crackgen bench --sweep: {recipe.dataset.name} ({recipe.camera.width_px}x{recipe.camera.height_px} px, "
              f"baseline {recipe.render.samples} spp, denoise {'on' if recipe.render.denoise else 'off'}), samples "
              f"{indices[0]}..{indices[-1]}, reference {opts.reference_samples} spp no denoiser, crack region = thesis "
              f"mask + {opts.dilate_px} px, {opts.cores} cores")
    meta = {"header": header, "recipe": recipe.dataset.name, "recipe_hash": recipe.hash[:16], "indices": indices,
            "reference_samples": opts.reference_samples, "reference_cache": str(cache), "dilate_px": opts.dilate_px,
            "cores": opts.cores, "crackgen": crackgen.__version__}
    missing = sum(not (cache / f"{reference_key(ref, i)}.npz").is_file() for i in indices)
    bar = tqdm(total=missing + len(variants) * len(indices), desc="sweep", unit="render", disable=not progress)
    rows: list[dict[str, Any]] = []
    out = Path(opts.out)
    try:
        bar.set_postfix_str(f"references ({missing} to render)")
        refs = load_references(ref, indices, cache, opts.cores, on_sample=lambda: bar.update(1))
        write_preview(out, "reference", indices[0], refs[indices[0]][0])
        for setting, r in variants:
            layout = setting.layout or default_layout
            bar.set_postfix_str(setting.label[:40])
            res = run_renders(r, indices, layout, opts.cores, on_sample=lambda: bar.update(1), name=setting.label)
            rows.append(summarise(setting, layout, res, refs, opts.dilate_px))
            write_preview(out, setting.label, indices[0], res.renders[indices[0]])
            write_outputs(rows, meta, out)
    finally:
        bar.close()
    return {**meta, "rows": rows, "written": [str(p) for p in write_outputs(rows, meta, out)] if rows else []}
