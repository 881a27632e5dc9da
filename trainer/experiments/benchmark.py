"""``cracktrain benchmark``: trained models on several real sets, one table (CSV, markdown, PNG).

Models are checkpoints, run folders (their final ``checkpoint.pt``) or ``sim2real``
output folders (every finished row). Each is scored at its own validation threshold
(stored in the checkpoint by ``seg``/``sim2real``; for a model without one it is
chosen here on ``--val``, never on a scored set). ``LABEL=PATH`` names a model;
models with one label are seeds of one configuration (mean ± sample sd).

Default sets: the test side of the grouped split of DeepCrack's training folder
(the split every ``sim2real`` run makes with the same seed and fractions) and the
three evaluation-only cross-domain sets. A model is refused on a set that holds
photos of a group it was trained on.
"""
from __future__ import annotations

import argparse
import json
import logging
import time
from pathlib import Path
from typing import Any, Callable, TypeVar

import torch
from tqdm import tqdm

from trainer.core.checkpoint import load_checkpoint
from trainer.core.device import pick_device
from trainer.core.errors import TrainerInputError
from trainer.experiments.config import BenchmarkOptions
from trainer.experiments.error_overlays import describe_errors
from trainer.experiments.eval_sets import (
    CROSS_DOMAIN_SETS,
    DEEPCRACK_TEST,
    DEEPCRACK_VAL,
    DEFAULT_REAL_ROOT,
    check_no_overlap,
    parse_set,
    trained_images,
)
from trainer.experiments.scoreboard import (
    EvalSet,
    ModelEntry,
    markdown_lines,
    plot_bars,
    plot_cost,
    plot_volume,
    score_all,
    write_csv,
)
from trainer.seg.builders import add_split_args
from trainer.seg.scoring import CheckpointScorer
from trainer.seg.threshold import choose_threshold, stored_threshold

log = logging.getLogger(__name__)

DEFAULT_SETS = (DEEPCRACK_TEST, *CROSS_DOMAIN_SETS)
T = TypeVar("T")


def add_benchmark_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("models", nargs="+", metavar="[LABEL=]MODEL",
                   help="checkpoint, run folder or sim2real folder; one LABEL for several = seeds of one configuration")
    p.add_argument("--set", dest="sets", action="append", default=None, metavar="NAME=FOLDER[@SIDE]",
                   help="a labelled set to score (repeatable); FOLDER@test|val|train: that side of the folder's grouped "
                        "split; relative folders are under --real-root when they exist there (default: DeepCrack's "
                        "test split and the three cross-domain sets)")
    p.add_argument("--val", default=DEEPCRACK_VAL, metavar="NAME=FOLDER[@SIDE]",
                   help="where a model without a stored validation threshold gets one ('none': use 0.5)")
    p.add_argument("--real-root", default=DEFAULT_REAL_ROOT, help="folder the default sets are under")
    p.add_argument("--out", required=True, help="writes benchmark.csv, benchmark.md, benchmark.png, benchmark.json")
    p.add_argument("--title", default=None, help="title of the markdown page and the chart")
    p.add_argument("--errors", type=int, default=0, metavar="N",
                   help="also describe what the first model of each row gets wrong on each set: its N images with the "
                        "most false-positive pixels as overlays (OUT/errors/ROW/SET/), and its false positives as line- "
                        "or blob-like, darker or brighter than their surround (0: off)")
    p.add_argument("--cost", action="append", default=None, metavar="LABEL=BENCH.json",
                   help="what one sample of LABEL's training data cost to make: a `crackgen bench --json` file "
                        "(core-seconds per sample = its mean s/sample x its Cycles threads); adds a cost column and "
                        "cost.png, F1 against core-seconds per sample (repeatable)")
    p.add_argument("--renders", action="append", default=None, metavar="LABEL=N",
                   help="how many renders LABEL's models trained on; adds a renders column and volume.png, F1 against "
                        "the number of renders: the data-volume curve (repeatable)")
    p.add_argument("--workers", "-j", type=int, default=2)
    p.add_argument("--device", default=None)
    p.add_argument("--no-progress", action="store_true")
    p.add_argument("--image-dir", default="images", help="image subfolder of every set")
    p.add_argument("--mask-dir", default="masks", help="mask subfolder (mask = value > 127)")
    p.add_argument("--mask-suffix", default="", help="mask file stem = image stem + suffix")
    add_split_args(p, val_fraction=0.2, test_fraction=0.2)


# ------------------------------------------------------------------ models

def expand_model(spec: str) -> list[tuple[str, Path]]:
    """``[LABEL=]PATH`` -> [(label, checkpoint)]; a sim2real folder gives one entry per finished row."""
    label, sep, where = spec.partition("=")
    if not sep:
        label, where = "", spec
    p = Path(where)
    if p.is_file():
        return [(label or p.parent.name, p)]
    if (p / "sim2real.json").is_file():
        rows = json.loads((p / "sim2real.json").read_text()).get("runs", {})
        # each row's checkpoint is ROW/checkpoint.pt inside this folder; the path recorded at training time
        # names where the folder was then (a moved or copied folder must not score the original's models)
        found = [(name, p / name / "checkpoint.pt" if (p / name / "checkpoint.pt").is_file() else Path(r["checkpoint"]))
                 for name, r in rows.items() if "checkpoint" in r]
        if not found:
            raise TrainerInputError(f"{p}/sim2real.json has no finished rows with a checkpoint (made before "
                                    "validation thresholds? re-run sim2real)")
        if label:
            return [(label if len(found) == 1 else f"{label} {name}", c) for name, c in found]
        return found
    if (p / "checkpoint.pt").is_file():
        return [(label or p.name, p / "checkpoint.pt")]
    raise TrainerInputError(f"model {where}: not a checkpoint, a run folder with checkpoint.pt or a sim2real folder")


def build_entries(args: BenchmarkOptions, device: torch.device, sets: list[EvalSet]) -> list[ModelEntry]:
    entries, val_set = [], None
    for spec in args.models:
        for label, path in expand_model(spec):
            ckpt = load_checkpoint(path)
            trained = trained_images(ckpt)
            for s in sets:
                check_no_overlap(str(path), trained, s, args.group_pattern)
            scorer = CheckpointScorer(path, device, args.workers, not args.no_progress)
            rec = stored_threshold(ckpt)
            if rec is None and args.val.lower() != "none":
                val_set = val_set or parse_set(args.val, args, args.real_root)
                check_no_overlap(str(path), trained, val_set, args.group_pattern)
                rec = choose_threshold(scorer.histogram(val_set.folder), f"benchmark --val {val_set.name}",
                                       len(val_set.folder))
            thr, src = (rec["threshold"], rec["chosen_on"]) if rec else (0.5, "none stored, --val none: 0.5")
            entries.append(ModelEntry(label, str(path), float(thr), src, scorer))
    return entries


def error_table(entries: list[ModelEntry], sets: list[EvalSet], out: Path, worst: int) -> list[str]:
    """``--errors``: per row (its first model) and set, what it gets wrong (``trainer.experiments.error_overlays``)."""
    firsts = {e.label: e for e in reversed(entries)}
    lines = ["", f"What the first model of each row gets wrong, at its validation threshold (false-positive pixels by the "
             f"shape and darkness of their component; overlays of the {worst} images with the most false positives: "
             "true positives green, false positives red, missed crack blue):", "",
             "| model | set | FP px | images with FP | FP line-like | FP darker than surround | FP brighter | overlays |",
             "|---|---|---|---|---|---|---|---|"]
    record = {}
    for label, e in reversed(list(firsts.items())):
        for s in sets:
            folder = out / "errors" / _slug(label) / s.name
            r = describe_errors(s.folder, e.scorer.probability, e.threshold, folder, worst)
            e.scorer.release()
            record.setdefault(label, {})[s.name] = r
            links = " ".join(f"[{i + 1}]({Path(p).relative_to(out)})" for i, p in enumerate(r["overlays"]))
            lines.append(f"| {label} | {s.name} | {r['fp']} | {r['images_with_fp']} of {r['images']} | "
                         f"{100 * r['fp_line_like']:.0f} % | {100 * r['fp_darker_than_surround']:.0f} % | "
                         f"{100 * r['fp_brighter_than_surround']:.0f} % | {links} |")
    (out / "errors.json").write_text(json.dumps(record, indent=1))
    return lines


def _slug(text: str) -> str:
    return "".join(c if c.isalnum() or c in "-_." else "_" for c in text)


def core_seconds_per_sample(path: str | Path) -> float:
    """Core-seconds one sample cost in a ``crackgen bench --json`` run: mean wall s/sample x the worker's threads."""
    try:
        bench = json.loads(Path(path).read_text())
        seconds, threads = float(bench["mean_total_s"]), int(bench["threads"])
    except FileNotFoundError:
        raise TrainerInputError(f"--cost: {path}: no such file") from None
    except (OSError, ValueError, KeyError, TypeError) as exc:
        raise TrainerInputError(f"--cost: {path}: not a `crackgen bench --json` file "
                                f"(needs mean_total_s and threads: {type(exc).__name__})") from None
    if not (seconds > 0 and threads > 0):
        raise TrainerInputError(f"--cost: {path}: mean_total_s and threads must be > 0, got {seconds} and {threads}")
    return seconds * threads


def parse_costs(specs: list[str] | None, labels: list[str]) -> dict[str, float]:
    """``LABEL=BENCH.json`` options -> label -> core-seconds per sample; every label must name a model row."""
    return _per_label("--cost", "BENCH.json", specs, labels, core_seconds_per_sample)


def parse_renders(specs: list[str] | None, labels: list[str]) -> dict[str, int]:
    """``LABEL=N`` options -> label -> number of training renders; every label must name a model row."""
    def count(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = 0
        if n <= 0:
            raise TrainerInputError(f"--renders: {text!r} is not a whole number of renders > 0")
        return n
    return _per_label("--renders", "N", specs, labels, count)


def _per_label(option: str, what: str, specs: list[str] | None, labels: list[str], read: Callable[[str], T]) -> dict[str, T]:
    found: dict[str, T] = {}
    for spec in specs or []:
        label, sep, value = spec.partition("=")
        if not sep or not label or not value:
            raise TrainerInputError(f"{option} {spec!r}: expected LABEL={what}")
        if label not in labels:
            raise TrainerInputError(f"{option} {spec!r}: no model row is labelled {label!r} (rows: {', '.join(labels)})")
        if label in found:
            raise TrainerInputError(f"{option}: {label!r} given twice")
        found[label] = read(value)
    return found


def run_benchmark(args: BenchmarkOptions) -> dict[str, Any]:
    out = Path(args.out)
    device = pick_device(args.device)
    specs = args.sets or list(DEFAULT_SETS)
    sets = [parse_set(s, args, args.real_root) for s in specs]
    if len({s.name for s in sets}) != len(sets):
        raise TrainerInputError(f"--set names must differ, got {[s.name for s in sets]}")
    entries = build_entries(args, device, sets)
    labels = list(dict.fromkeys(e.label for e in entries))
    costs = parse_costs(args.cost, labels) if args.cost else {}
    renders = parse_renders(args.renders, labels) if args.renders else {}
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    bar = tqdm(total=len(entries) * len(sets), desc="benchmark", disable=args.no_progress)

    def done(row) -> None:
        bar.update(1)
        bar.set_postfix_str(f"{row.label} on {row.set}: F1 {row.f1:.3f}")
        if row.set == sets[-1].name:
            next(e for e in entries if e.path == row.model).scorer.release()

    rows = score_all(entries, sets, done)
    bar.close()
    errors = error_table(entries, sets, out, args.errors) if args.errors > 0 else []
    title = args.title or f"benchmark of {len(entries)} models on {len(sets)} sets"
    write_csv(rows, out / "benchmark.csv")
    md = [f"# {title}", "", *markdown_lines(rows, sets, costs, renders), *errors]
    (out / "benchmark.md").write_text("\n".join(md) + "\n")
    plot_bars(rows, sets, out / "benchmark.png", title)
    if costs:
        plot_cost(rows, sets, costs, out / "cost.png", title)
    if renders:
        plot_volume(rows, sets, renders, out / "volume.png", title)
    result = {"models": len(entries), "labels": len({e.label for e in entries}), "sets": [s.name for s in sets],
              "seconds": round(time.perf_counter() - t0, 1), "out": str(out),
              "core_seconds_per_sample": costs, "renders": renders, "rows": [r.__dict__ for r in rows]}
    (out / "benchmark.json").write_text(json.dumps(result, indent=1))
    return result
