"""Labelled real sets to score models on, named on the command line as ``NAME=FOLDER[@SIDE]``.

``FOLDER@test`` (or ``@val``, ``@train``) is one side of the folder's grouped split
(``trainer.seg.real_split``) made with the command's split flags, so the DeepCrack
test split is named without a split folder on disk. A relative folder is looked
up under ``--real-root`` first (``../shared/data/real``). The cross-domain sets are
for evaluation only: nothing is trained, adapted or chosen on them.

A model is never scored on a set that holds a photo group it was trained on
(``check_no_overlap``), whatever folders or symlinks the two came through.
"""
from __future__ import annotations

import logging
from pathlib import Path
from typing import Any

from trainer.core.checkpoint import load_checkpoint
from trainer.core.errors import TrainerInputError
from trainer.experiments.config import BenchmarkOptions, ExperimentOptions
from trainer.experiments.scoreboard import EvalSet
from trainer.seg.real_split import SIDES, compile_group_pattern, group_of, split_groups
from trainer.seg.sources import RealFolder

log = logging.getLogger(__name__)

DEFAULT_REAL_ROOT = "../shared/data/real"
DEEPCRACK_TEST = "deepcrack_test=deepcrack_train@test"
DEEPCRACK_VAL = "deepcrack_val=deepcrack_train@val"
CROSS_DOMAIN_SETS = ("masonry_dais=crossdomain/masonry_dais", "shadowcrack_test=crossdomain/shadowcrack_test",
                     "aiglern_test=crossdomain/aiglern_test")


def parse_set(spec: str, args: BenchmarkOptions | ExperimentOptions, real_root: str | Path = DEFAULT_REAL_ROOT) -> EvalSet:
    """``NAME=FOLDER[@SIDE]`` -> a checked set (every image has its mask, by name); ``args`` gives the folder
    layout and the grouped split that ``@val`` / ``@test`` name."""
    name, sep, where = spec.partition("=")
    if not sep or not name.strip() or not where.strip():
        raise TrainerInputError(f"set {spec!r}: expected NAME=FOLDER or NAME=FOLDER@test")
    side = None
    if "@" in where and where.rsplit("@", 1)[1] in SIDES:
        where, side = where.rsplit("@", 1)
    root = Path(where)
    if not root.is_absolute() and (Path(real_root) / root).is_dir():
        root = Path(real_root) / root
    if not root.is_dir():
        raise TrainerInputError(f"set {name}: folder {root} does not exist")
    def folder_of(stems: list[str] | None) -> RealFolder:  # RGB photos and masks: sets carry no depth
        return RealFolder(root, image_dir=args.image_dir, mask_dir=args.mask_dir, mask_suffix=args.mask_suffix,
                          stems=stems, ignore_dir=None)

    if side is None:
        folder, desc = folder_of(None), str(root)
    else:
        split = split_groups(folder_of(None).keys, val_fraction=args.val_fraction,
                             test_fraction=args.test_fraction, seed=args.split_seed,
                             group_pattern=args.group_pattern, source=str(root))
        folder = folder_of(split.side(side))
        desc = (f"{root}, {side} side of the grouped split (seed {args.split_seed}, val {args.val_fraction:g}, "
                f"test {args.test_fraction:g}, groups `{split.group_pattern}`)")
    folder.check_pairs()
    return EvalSet(name.strip(), folder, desc)


def cross_domain_sets(specs: list[str] | None, args: BenchmarkOptions | ExperimentOptions, real_root: str | Path) -> list[EvalSet]:
    """``--cross`` sets: the given specs, none for ``['none']``, else the three cross-domain sets."""
    if specs and [s.lower() for s in specs] == ["none"]:
        return []
    return [parse_set(s, args, real_root) for s in (specs or CROSS_DOMAIN_SETS)]


def trained_images(ckpt: dict[str, Any], seen: set[str] | None = None) -> list[Path]:
    """Resolved image files a checkpoint (and its ``--init`` chain) trained on from real folders."""
    seen = set() if seen is None else seen
    a = ckpt.get("args", {})
    files: list[Path] = []
    real = a.get("real")
    if real and Path(real).is_dir():
        try:
            f = RealFolder(Path(real), image_dir=a.get("image_dir", "images"), mask_dir=a.get("mask_dir", "masks"),
                           stems=a.get("real_stems"), require_masks=False)
            files += [f.image_path(k).resolve() for k in f.keys]
        except TrainerInputError as exc:
            log.warning("cannot list the training photos of %s: %s", real, exc)
    init = a.get("init")
    if init and Path(init).is_file() and init not in seen:
        seen.add(init)
        files += trained_images(load_checkpoint(init), seen)
    return files


def check_no_overlap(model: str, trained: list[Path], s: EvalSet, pattern_text: str | None) -> None:
    """Refuse to score a model on a set that shares a photo group with its training photos."""
    if not trained:
        return
    pattern = compile_group_pattern(pattern_text)
    groups = {(p.parent, group_of(p.stem, pattern)) for p in trained}
    hits = sorted({group_of(k, pattern) for k in s.folder.keys
                   if (s.folder.image_path(k).resolve().parent, group_of(k, pattern)) in groups})
    if hits:
        raise TrainerInputError(f"{model} was trained on photos of {len(hits)} group(s) of set {s.name} "
                                f"({', '.join(hits[:4])}): its scores there would not be held out")
