"""``cracktrain evaluate``: thesis 5.4.1 metrics of a checkpoint on a dataset.

Confusion counts are summed over the whole set (not averaged per image);
reports accuracy/P/R/F1/IoU at the model's operating threshold (``--threshold``, else the
one chosen on validation and stored in the checkpoint, else 0.5) and at the best-F1
threshold of the 0.00..1.00 sweep (an oracle: it is chosen on the labels being scored), and writes ``metrics.json`` + ``pr_curve.png``.
Depth handling (channels, near/far, normalisation, resize) comes from the
checkpoint, so evaluation always matches training.
"""
from __future__ import annotations

import argparse
import json
from pathlib import Path
from typing import Any

from trainer.core.checkpoint import load_checkpoint
from trainer.core.device import pick_device
from trainer.core.errors import TrainerInputError
from trainer.seg.builders import DataOptions, add_data_args, eval_loader, real_folder, shard_source
from trainer.seg.config import EvaluateOptions
from trainer.seg.metrics import plot_pr_curve
from trainer.seg.scoring import evaluate, inherit_depth, load_model
from trainer.seg.stream import SegStream
from trainer.seg.threshold import operating_threshold


def add_eval_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", "-c", required=True)
    p.add_argument("--data", default=None, help="synthetic shards to evaluate on")
    p.add_argument("--real", default=None, help="real image/mask folder to evaluate on")
    p.add_argument("--threshold", type=float, default=None,
                   help="operating threshold (default: the one chosen on validation and stored in the checkpoint, "
                        "else 0.5)")
    p.add_argument("--out", default=None, help="output folder (default: next to the checkpoint)")
    p.add_argument("--workers", "-j", type=int, default=2)
    p.add_argument("--device", default=None)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--no-progress", action="store_true")
    add_data_args(p)


def run_evaluate(args: EvaluateOptions) -> dict[str, Any]:
    device = pick_device(args.device)
    model, cfg, train_args = load_model(args.checkpoint, device)
    args = inherit_depth(args, train_args, cfg)
    if not args.data and not args.real:
        raise TrainerInputError("give evaluation data: --data SHARDS and/or --real FOLDER")
    opts = DataOptions.from_args(args)
    shards = shard_source(opts, args.data) if args.data else None
    real = real_folder(opts, args.real) if args.real else None
    ds = SegStream(cfg, shards, real, train=False, seed=args.seed, skip_bad=args.skip_bad)
    amp = device.type == "cuda"
    hist = evaluate(model, eval_loader(ds, args.workers, device), device, amp, progress=not args.no_progress)
    threshold, source = operating_threshold(load_checkpoint(args.checkpoint), args.threshold)
    summary = hist.summary(threshold) | {"threshold_source": source}
    out = Path(args.out) if args.out else Path(args.checkpoint).parent / "eval"
    out.mkdir(parents=True, exist_ok=True)
    summary["checkpoint"] = str(args.checkpoint)
    summary["data"] = {"shards": args.data, "real": args.real, "samples": len(ds),
                       "mask_member": shards.mask_member if shards is not None else None}
    summary["input"] = {"channels": cfg.channels, "depth": args.depth, "depth_norm": cfg.depth_norm,
                        **({"relief": cfg.relief, "relief_range_mm": cfg.relief_range_mm,
                            "relief_sigma": cfg.relief_sigma} if cfg.depth_norm == "relief" else {})}
    (out / "metrics.json").write_text(json.dumps(summary, indent=2))
    plot_pr_curve(hist, out / "pr_curve.png", title=f"{train_args['arch']} ({cfg.channels})")
    summary["out"] = str(out)
    return summary
