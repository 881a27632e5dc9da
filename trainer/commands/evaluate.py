"""``cracktrain evaluate``: dataset-level metrics of a checkpoint at its validation threshold."""
from __future__ import annotations

import argparse

NAME = "evaluate"
HELP = "dataset-level metrics + PR curve of a checkpoint"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.seg.evaluate import add_eval_args

    add_eval_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.core.options import options_from
    from trainer.seg.config import EvaluateOptions
    from trainer.seg.evaluate import run_evaluate

    s = run_evaluate(options_from(EvaluateOptions, args))
    a, b = s["at_threshold"], s["best"]
    print(f"@{a['threshold']:.2f} ({s['threshold_source']}): acc {a['accuracy']:.4f} P {a['precision']:.4f} "
          f"R {a['recall']:.4f} F1 {a['f1']:.4f} IoU {a['iou']:.4f}")
    print(f"oracle, best on these labels @{b['threshold']:.2f}: acc {b['accuracy']:.4f} P {b['precision']:.4f} "
          f"R {b['recall']:.4f} F1 {b['f1']:.4f} IoU {b['iou']:.4f}")
    print(f"wrote {s['out']}/metrics.json and pr_curve.png")
    return 0
