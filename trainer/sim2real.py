"""``cracktrain sim2real``: does synthetic data help on real cracks?

Trains the same architecture with the same step budget on (a) synthetic only,
(b) real only and (c) synthetic + real (real repeated N times, thesis rule),
then evaluates each final model on the same real test set and writes
``sim2real.json`` + ``sim2real.md`` (P/R/F1/IoU at each run's best-F1
threshold, and at 0.5). The real test set is a folder (``--real-test``) or a
deterministic fraction of ``--real`` (``--real-test-fraction``, ``--split-seed``).
Runs whose inputs are missing (e.g. no ``--synthetic``) are listed as skipped.
"""
from __future__ import annotations

import argparse
import json
import logging
from pathlib import Path
from typing import Any

import torch

from trainer.builders import add_data_args, eval_loader, real_folder, sample_config_from_args
from trainer.errors import TrainerInputError
from trainer.evaluate import load_model
from trainer.sources import split_fraction
from trainer.stream import SegStream
from trainer.train import add_seg_args, evaluate
from trainer.train import main as train_seg

log = logging.getLogger(__name__)


def add_sim2real_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--synthetic", default=None, help="synthetic shards")
    p.add_argument("--real", required=True, help="real training folder (or the whole folder with --real-test-fraction)")
    p.add_argument("--real-test", default=None, help="real test folder")
    p.add_argument("--real-test-fraction", type=float, default=0.0)
    p.add_argument("--split-seed", type=int, default=0)
    p.add_argument("--arch", default="lraspp_mobilenet_v3_large")
    p.add_argument("--max-steps", type=int, default=300)
    p.add_argument("--batch-size", "-b", type=int, default=4)
    p.add_argument("--crop", type=int, default=192)
    p.add_argument("--lr", type=float, default=1e-3)
    p.add_argument("--loss", default="bce")
    p.add_argument("--workers", "-j", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--runs", default="synthetic,real,mixed", help="subset of synthetic,real,mixed")
    p.add_argument("--out", default="runs/sim2real")
    p.add_argument("--device", default=None)
    p.add_argument("--no-progress", action="store_true")
    add_data_args(p)


def _seg_args(args: argparse.Namespace, out: Path, data: str | None, real: str | None, stems: list[str] | None) -> argparse.Namespace:
    p = argparse.ArgumentParser()
    add_seg_args(p)
    ns = p.parse_args([])
    for k, v in vars(args).items():
        if hasattr(ns, k) and k not in ("out", "real"):
            setattr(ns, k, v)
    ns.data, ns.real, ns.real_stems, ns.out = data, real, stems, str(out)
    ns.val_fraction, ns.val_data, ns.val_real, ns.resume, ns.test_only = 0.0, None, None, None, False
    return ns


def run_sim2real(args: argparse.Namespace) -> dict[str, Any]:
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    if args.real_test:
        train_stems, test_root, test_stems = None, args.real_test, None
    elif args.real_test_fraction > 0:
        keys = real_folder(args, args.real).keys
        train_stems, test_stems = split_fraction(keys, args.real_test_fraction, args.split_seed)
        test_root = args.real
    else:
        raise TrainerInputError("give a real test set: --real-test FOLDER or --real-test-fraction F")
    test = real_folder(args, test_root, test_stems)
    wanted = [r.strip() for r in args.runs.split(",") if r.strip()]
    plans = {"synthetic": (args.synthetic, None), "real": (None, args.real), "mixed": (args.synthetic, args.real)}
    device = torch.device(args.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    results: dict[str, Any] = {}
    for name in wanted:
        if name not in plans:
            raise TrainerInputError(f"--runs: unknown run {name!r} (synthetic, real, mixed)")
        data, real = plans[name]
        if name in ("synthetic", "mixed") and not args.synthetic:
            results[name] = {"skipped": "no --synthetic shards given"}
            continue
        seg = _seg_args(args, out / name, data, real, train_stems if real else None)
        log.info("sim2real: training '%s'", name)
        info = train_seg(seg)
        model, cfg, _ = load_model(out / name / "checkpoint.pt", device)
        ds = SegStream(cfg, None, test, train=False, seed=args.seed, skip_bad=args.skip_bad)
        hist = evaluate(model, eval_loader(ds, args.workers, device), device, device.type == "cuda")
        s = hist.summary(0.5)
        results[name] = {"steps": info["step"], "train_seconds": round(info["seconds"], 1),
                         "best": s["best"], "at_0.5": s["at_threshold"]}
    table = {"arch": args.arch, "channels": sample_config_from_args(args).channels, "max_steps": args.max_steps,
             "batch_size": args.batch_size, "crop": args.crop, "real_train": args.real,
             "real_train_images": len(train_stems) if train_stems is not None else len(real_folder(args, args.real)),
             "real_test": test_root, "real_test_images": len(test), "synthetic": args.synthetic, "runs": results}
    (out / "sim2real.json").write_text(json.dumps(table, indent=2))
    lines = [f"# Sim-to-real: {args.arch}, {args.max_steps} steps, batch {args.batch_size}, crop {args.crop}", "",
             f"Real test: {test_root} ({len(test)} images). Metrics summed over the test set; "
             "P/R/F1/IoU at each run's best-F1 threshold (F1 at 0.5 in the last column).", "",
             "| training data | threshold | precision | recall | F1 | IoU | F1 @ 0.5 |", "|---|---|---|---|---|---|---|"]
    for name, r in results.items():
        if "skipped" in r:
            lines.append(f"| {name} | skipped: {r['skipped']} | | | | | |")
        else:
            b = r["best"]
            lines.append(f"| {name} | {b['threshold']:.2f} | {b['precision']:.3f} | {b['recall']:.3f} | "
                         f"{b['f1']:.3f} | {b['iou']:.3f} | {r['at_0.5']['f1']:.3f} |")
    (out / "sim2real.md").write_text("\n".join(lines) + "\n")
    return table
