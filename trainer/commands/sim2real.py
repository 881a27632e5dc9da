"""``cracktrain sim2real``: renders against real photos, row by row, on a grouped real split."""
from __future__ import annotations

import argparse
from pathlib import Path

from crackgen.cli_aliases import deprecation_note

NAME = "sim2real"
HELP = "synthetic (+ adaptation) vs real vs mixed vs fine-tune on a grouped real split"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.experiments.sim2real import add_sim2real_args

    add_sim2real_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.core.options import options_from
    from trainer.experiments.config import ExperimentOptions
    from trainer.experiments.sim2real import run_curve, run_sim2real

    if args.curve:  # the old spelling of `cracktrain curve`
        deprecation_note("cracktrain", "sim2real --curve", "cracktrain curve --sizes")
        res = run_curve(options_from(ExperimentOptions, args))
        report = Path(res["out"]) / "curve.md"
    else:
        run_sim2real(options_from(ExperimentOptions, args))
        report = Path(args.out) / "sim2real.md"
    print(report.read_text())
    print(f"wrote {report.parent}")
    return 0
