"""``cracktrain merge-stack``: guided-filter fusion of an exposure or focus stack (was ``fuse-images``)."""
from __future__ import annotations

import argparse

NAME = "merge-stack"
OLD_NAMES = ("fuse-images",)  # kept one release as a hidden alias that prints one deprecation line
HELP = "guided-filter fusion of an exposure or focus stack; prints Q_Y, Q_C, Q_G, Q_MI"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.imagefusion.stack import add_fuse_args

    add_fuse_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.imagefusion.stack import merge_stack

    r = merge_stack(args.images, args.out, args.levels)
    print(f"Q_Y {r['Q_Y']:.4f}  Q_C {r['Q_C']:.4f}  Q_G {r['Q_G']:.4f}  Q_MI {r['Q_MI']:.4f}")
    print(f"fused {r['inputs']} images ({r['levels']}-level) -> {r['out']}")
    return 0
