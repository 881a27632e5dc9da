"""``cracktrain curve``: the label-efficiency curve, real-only against synthetic -> fine-tune on N photos."""
from __future__ import annotations

import argparse
from pathlib import Path

NAME = "curve"
HELP = "label-efficiency curve: real-only vs synthetic -> fine-tune on N labelled photos, repeated over seeds"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.experiments.sim2real import add_curve_args

    add_curve_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.core.options import options_from
    from trainer.experiments.config import CurveOptions
    from trainer.experiments.sim2real import run_curve

    res = run_curve(options_from(CurveOptions, args))
    report = Path(res["out"]) / "curve.md"
    print(report.read_text())
    print(f"wrote {res['out']}/curve.csv, curve.md, curve.png, curve.json")
    return 0
