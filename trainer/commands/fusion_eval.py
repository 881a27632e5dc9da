"""``cracktrain fusion-eval``: the thesis-style depth-fusion table of a confidence CNN."""
from __future__ import annotations

import argparse

from trainer.commands._checkpoint import resolve_checkpoint

NAME = "fusion-eval"
HELP = "thesis-style table: stereo, ToF/LiDAR, fused max/weighted, + BM3D"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.depthfusion.evaluate import add_fusion_eval_args

    add_fusion_eval_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.core.options import options_from
    from trainer.depthfusion.config import FusionEvalOptions
    from trainer.depthfusion.evaluate import run_fusion_eval

    resolve_checkpoint(args, NAME, dest="ckpt")
    res = run_fusion_eval(options_from(FusionEvalOptions, args))
    print(f"{res['variant']} fusion, {res['scenes']} {'held-out ' if res['keys'] == 'val' else ''}scenes of "
          f"{res['data']} (disparity px, mean over scenes)")
    print(res["table"])
    if args.out:
        print(f"wrote {args.out}/metrics.json and table.md")
    return 0
