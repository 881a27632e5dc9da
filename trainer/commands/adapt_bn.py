"""``cracktrain adapt-bn``: a model's BatchNorm statistics moved to a site's unlabeled photos (AdaBN)."""
from __future__ import annotations

import argparse

from trainer.commands._checkpoint import resolve_checkpoint

NAME = "adapt-bn"
HELP = "move a trained model's BatchNorm statistics to a folder of unlabeled site photos (AdaBN)"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.adapt.adabn import add_adapt_bn_args

    add_adapt_bn_args(p)


def run(args: argparse.Namespace) -> int:
    from trainer.adapt.adabn import adapt_checkpoint
    from trainer.core.device import pick_device
    from trainer.seg.appearance import targets_from_folder

    resolve_checkpoint(args, NAME)
    photos = targets_from_folder(args.target)
    r = adapt_checkpoint(args.checkpoint, args.out, photos, pick_device(args.device), target=str(args.target),
                         batches=args.batches, batch_size=args.batch_size, crop=args.crop, workers=args.workers,
                         seed=args.seed)
    print(f"BN statistics of {r['source']} re-estimated on {r['batches']} batches of {r['crop']}-px crops "
          f"from {r['photos']} photos in {r['target']}; wrote {args.out}")
    return 0
