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
    from trainer.adapt.pseudo_label import run_pseudo_label

    resolve_checkpoint(args, NAME)
    r = run_pseudo_label(args)
    s = r["settings"]
    print(f"pseudo-labelled {r['photos']} photos with {s['teacher']} (target BN {'on' if s['target_bn'] else 'off'}, "
          f"portion {s['portion']}): crack {100 * r['crack_fraction']:.2f}% of pixels (p >= {r['threshold_crack']:.3f}), "
          f"background {100 * r['background_fraction']:.1f}%, ignored {100 * r['ignored_fraction']:.1f}%; wrote "
          f"{args.out} (images/, masks/, ignore/, pseudo_labels.json); train on it with seg --real")
    return 0
