"""``cracktrain split``: grouped, seeded train / validation / test split of a real folder."""
from __future__ import annotations

import argparse

NAME = "split"
HELP = "grouped, seeded train / validation / test split of a real folder"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.experiments.split import add_split_command_args

    add_split_command_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.experiments.split import run_split

    s = run_split(args.source, args.out, val_fraction=args.val_fraction, test_fraction=args.test_fraction,
                  seed=args.split_seed, group_pattern=args.group_pattern, image_dir=args.image_dir,
                  mask_dir=args.mask_dir, mask_suffix=args.mask_suffix, extra_dirs=args.extra_dir)
    print(f"{s.counts()} -> {args.out}/train, val, test and split.json")
    return 0
