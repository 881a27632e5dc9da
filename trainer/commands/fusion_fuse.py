"""``cracktrain fuse``: fuse a stereo and a ToF/LiDAR disparity file with a trained confidence CNN."""
from __future__ import annotations

import argparse

from trainer.commands._checkpoint import resolve_checkpoint

NAME = "fuse"
HELP = "fuse a stereo and a ToF/LiDAR disparity file with a trained confidence CNN"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.depthfusion.apply import add_fuse_args

    add_fuse_args(p)


def run(args: argparse.Namespace) -> int:
    from fusion.depth.metrics import format_table
    from trainer.core.options import options_from
    from trainer.depthfusion.apply import run_fuse
    from trainer.depthfusion.config import FuseOptions

    resolve_checkpoint(args, NAME, dest="ckpt")
    res = run_fuse(options_from(FuseOptions, args))
    if "metrics" in res:
        print(format_table(res["metrics"]))
    print(f"wrote {', '.join(res['written'])} to {res['out']}")
    return 0
