"""``cracktrain pseudo-label``: a site's unlabeled photos labelled with a model's confident predictions."""
from __future__ import annotations

import argparse

from trainer.commands._checkpoint import resolve_checkpoint

NAME = "pseudo-label"
HELP = "label a folder of unlabeled site photos with a model's confident predictions (self-training data)"


def add_args(p: argparse.ArgumentParser) -> None:
    from trainer.adapt.pseudo_label import add_pseudo_label_args

    add_pseudo_label_args(p)


def run(args: argparse.Namespace) -> int:
    from pathlib import Path

    from trainer.adapt.pseudo_label import PseudoSettings, write_pseudo_folder
    from trainer.core.device import pick_device
    from trainer.core.errors import TrainerInputError
    from trainer.seg.appearance import targets_from_folder

    resolve_checkpoint(args, NAME)
    if not Path(args.checkpoint).is_file():
        raise TrainerInputError(f"checkpoint {args.checkpoint} does not exist")
    settings = PseudoSettings(teacher=str(args.checkpoint), portion=args.portion,
                              background_portion=args.background_portion, target_bn=args.target_bn,
                              bn_batches=args.batches, batch_size=args.batch_size, crop=args.crop, seed=args.seed)
    r = write_pseudo_folder(targets_from_folder(args.target), args.out, settings, pick_device(args.device),
                            workers=args.workers, progress=not args.no_progress)
    s = r["settings"]
    print(f"pseudo-labelled {r['photos']} photos with {s['teacher']} (target BN {'on' if s['target_bn'] else 'off'}, "
          f"portion {s['portion']}): crack {100 * r['crack_fraction']:.2f}% of pixels (p >= {r['threshold_crack']:.3f}), "
          f"background {100 * r['background_fraction']:.1f}%, ignored {100 * r['ignored_fraction']:.1f}%; wrote "
          f"{args.out} (images/, masks/, ignore/, pseudo_labels.json); train on it with seg --real")
    return 0
