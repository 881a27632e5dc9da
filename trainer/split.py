"""``cracktrain split``: deterministic train/test split of one real folder.

DeepCrack here is a single folder; the sim-to-real study needs a held-out real
test set. The split is a seeded permutation of the sorted stems (independent of
file-system order) and is materialised as two folders of symlinks with the same
layout (images/, masks/, optional depth folder) plus ``split.json``.
"""
from __future__ import annotations

import argparse
import json
import os
from pathlib import Path

from trainer.builders import real_folder
from trainer.errors import TrainerInputError
from trainer.sources import split_fraction


def add_split_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", help="real folder with images/ and masks/")
    p.add_argument("--out", required=True, help="creates OUT/train and OUT/test")
    p.add_argument("--test-fraction", type=float, default=0.2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--image-dir", default="images")
    p.add_argument("--mask-dir", default="masks")
    p.add_argument("--mask-suffix", default="")
    p.add_argument("--extra-dir", action="append", default=[], help="another per-stem subfolder to split (e.g. depth)")


def run_split(args: argparse.Namespace) -> dict[str, list[str]]:
    ns = argparse.Namespace(image_dir=args.image_dir, mask_dir=args.mask_dir, mask_suffix=args.mask_suffix,
                            depth="none", real_depth_dir=None, real_depth_kind="depth", real_depth_scale=1.0,
                            focal_px=None, baseline_m=None)
    folder = real_folder(ns, args.source)
    train, test = split_fraction(folder.keys, args.test_fraction, args.seed)
    if not train or not test:
        raise TrainerInputError(f"{args.source}: --test-fraction {args.test_fraction} leaves an empty side ({len(folder)} images)")
    src, out = Path(args.source).resolve(), Path(args.out)
    for side, stems in (("train", train), ("test", test)):
        for sub in [args.image_dir, args.mask_dir, *args.extra_dir]:
            (out / side / sub).mkdir(parents=True, exist_ok=True)
            files = {p.stem: p for p in (src / sub).iterdir()} if (src / sub).is_dir() else {}
            for stem in stems:
                name = stem + (args.mask_suffix if sub == args.mask_dir else "")
                if name in files:
                    link = out / side / sub / files[name].name
                    if link.is_symlink() or link.exists():
                        link.unlink()
                    os.symlink(files[name], link)
    split = {"source": str(src), "seed": args.seed, "test_fraction": args.test_fraction, "train": train, "test": test}
    (out / "split.json").write_text(json.dumps(split, indent=2))
    return split
