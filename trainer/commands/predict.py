"""``cracktrain predict``: masks, overlays and crack measurements for real photos."""
from __future__ import annotations

import argparse

NAME = "predict"
HELP = "masks, overlays and crack length/width (px or metres) for real photos"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.seg.predict import add_predict_args

    add_predict_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.core.options import options_from
    from trainer.seg.config import PredictOptions
    from trainer.seg.predict import run_predict

    print(run_predict(options_from(PredictOptions, args)).summary())
    return 0
