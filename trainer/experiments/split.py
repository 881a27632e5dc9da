"""``cracktrain split``: a grouped, seeded train / validation / test split of one real folder.

DeepCrack here is a single folder; the sim-to-real study needs held-out real
validation and test sets, and tiles of one photo (``NAME-k``) must stay on one
side (``trainer.seg.real_split``). The split is materialised as three folders of
symlinks with the same layout (images/, masks/, optional extra folders) plus
``split.json`` with every group and the side it went to.
"""
from __future__ import annotations

import argparse
import os
from pathlib import Path

from trainer.seg.builders import add_split_args
from trainer.seg.real_split import SIDES, RealSplit, split_groups
from trainer.seg.sources import RealFolder


def add_split_command_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("source", help="real folder with images/ and masks/")
    p.add_argument("--out", required=True, help="creates OUT/train, OUT/val and OUT/test (and OUT/split.json)")
    p.add_argument("--image-dir", default="images")
    p.add_argument("--mask-dir", default="masks")
    p.add_argument("--mask-suffix", default="")
    p.add_argument("--extra-dir", action="append", default=[], help="another per-stem subfolder to split (e.g. depth)")
    add_split_args(p, val_fraction=0.2, test_fraction=0.2)


def link_split(split: RealSplit, source: Path, out: Path, subfolders: list[str], mask_dir: str,
               mask_suffix: str) -> None:
    """Symlink each side's files into OUT/SIDE/SUBFOLDER (a side with no photos gets no folder)."""
    for side in SIDES:
        stems = split.side(side)
        if not stems:
            continue
        for sub in subfolders:
            (out / side / sub).mkdir(parents=True, exist_ok=True)
            files = {p.stem: p for p in (source / sub).iterdir()} if (source / sub).is_dir() else {}
            for stem in stems:
                name = stem + (mask_suffix if sub == mask_dir else "")
                if name in files:
                    link = out / side / sub / files[name].name
                    if link.is_symlink() or link.exists():
                        link.unlink()
                    os.symlink(files[name], link)


def run_split(source: str, out: str, *, val_fraction: float, test_fraction: float, seed: int, group_pattern: str,
              image_dir: str = "images", mask_dir: str = "masks", mask_suffix: str = "",
              extra_dirs: list[str] | None = None) -> RealSplit:
    folder = RealFolder(Path(source), image_dir=image_dir, mask_dir=mask_dir, mask_suffix=mask_suffix)
    split = split_groups(folder.keys, val_fraction=val_fraction, test_fraction=test_fraction, seed=seed,
                         group_pattern=group_pattern, source=str(Path(source).resolve()))
    link_split(split, Path(source).resolve(), Path(out), [image_dir, mask_dir, *(extra_dirs or [])], mask_dir,
               mask_suffix)
    split.write(out)
    return split
