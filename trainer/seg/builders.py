"""Build sources, sample configs and loaders from parsed CLI arguments.

Shared by ``seg``, ``evaluate``, ``predict``, ``sim2real`` and ``bench`` so
every command reads folders and depth the same way.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

import torch
from torch.utils.data import DataLoader

from trainer.core.errors import TrainerInputError
from trainer.seg.augment import SampleConfig
from trainer.seg.depth import (
    DEFAULT_RELIEF,
    DEFAULT_RELIEF_RANGE_MM,
    DEFAULT_RELIEF_SIGMA,
    DEPTH_NORMS,
    RELIEF_METHODS,
)
from trainer.seg.real_split import DEFAULT_GROUP_PATTERN, RealSplit, split_groups
from trainer.seg.sources import DEFAULT_MASK_MEMBER, SPARSE_DEPTHS, RealFolder, ShardSource
from trainer.seg.stream import SegStream


def add_data_args(p: argparse.ArgumentParser) -> None:
    """Flags describing real-folder layout and depth handling."""
    g = p.add_argument_group("real folders and depth")
    g.add_argument("--image-dir", default="images", help="image subfolder of a real folder")
    g.add_argument("--mask-dir", default="masks", help="mask subfolder (mask = value > 127)")
    g.add_argument("--mask-suffix", default="", help="mask file stem = image stem + suffix (e.g. _mask)")
    g.add_argument("--ignore-dir", default="ignore",
                   help="subfolder of per-pixel ignore masks (value > 127: no training loss there; used when it "
                        "exists, e.g. in a `cracktrain pseudo-label` folder)")
    g.add_argument("--real-depth-dir", default=None, help="subfolder with depth or disparity maps (same stems)")
    g.add_argument("--real-depth-kind", choices=("depth", "disparity"), default="depth")
    g.add_argument("--real-depth-scale", type=float, default=1.0, help="raw depth units -> metres (0.001 for mm PNGs)")
    g.add_argument("--focal-px", type=float, default=None, help="focal length (px) of the disparity map, for Z=f*B/d")
    g.add_argument("--baseline-m", type=float, default=None, help="stereo baseline (m), for Z=f*B/d")
    g.add_argument("--depth", choices=("tof", "lidar", "gt", "none"), default="none",
                   help="depth input: shard member tof|lidar|depth(gt), or none for RGB-only models")
    g.add_argument("--valid-channel", action=argparse.BooleanOptionalAction, default=None,
                   help="add a depth-validity channel (5-ch input); default: on for sparse depth "
                        f"({'|'.join(SPARSE_DEPTHS)}), off otherwise")
    g.add_argument("--depth-near", type=float, default=0.2, help="depth (m) mapped to 0 (fixed norm)")
    g.add_argument("--depth-far", type=float, default=5.0, help="depth (m) mapped to 1 (fixed norm)")
    g.add_argument("--depth-norm", choices=DEPTH_NORMS, default="fixed",
                   help="fixed: (Z-near)/(far-near); minmax: per image; relief: height above the local "
                        "surface in mm, clipped to +-range -> [-1, 1] (carries the crack)")
    g.add_argument("--relief", choices=RELIEF_METHODS, default=DEFAULT_RELIEF,
                   help="relief reference: lowpass (local planes, follows curved surfaces) or one robust plane")
    g.add_argument("--relief-range-mm", type=float, default=DEFAULT_RELIEF_RANGE_MM,
                   help="relief (mm) mapped to +-1; larger values clip")
    g.add_argument("--relief-sigma", type=float, default=DEFAULT_RELIEF_SIGMA,
                   help="lowpass window sigma as a fraction of the shorter image side")
    g.add_argument("--mask-member", default=None,
                   help=f"label member of synthetic shards (default {DEFAULT_MASK_MEMBER}; e.g. mask_thesis.png)")
    g.add_argument("--size", type=int, default=None, help="resize the shorter image side to this (px) first")
    g.add_argument("--skip-bad", action="store_true", help="log and skip unreadable/mismatched samples")


def add_split_args(p: argparse.ArgumentParser, *, val_fraction: float, test_fraction: float | None) -> None:
    """How a real folder is split (``trainer.seg.real_split``): by group, seeded, train / validation / test."""
    g = p.add_argument_group("grouped split of a real folder")
    g.add_argument("--val-fraction", type=float, default=val_fraction,
                   help="share of the photos held out for validation (whole groups)")
    if test_fraction is not None:
        g.add_argument("--test-fraction", "--real-test-fraction", dest="test_fraction", type=float,
                       default=test_fraction, help="share of the photos held out for testing (whole groups)")
    g.add_argument("--split-seed", type=int, default=0)
    g.add_argument("--group-pattern", default=DEFAULT_GROUP_PATTERN, metavar="REGEX",
                   help="a file's group is the first capture group of REGEX on its stem (default: the stem up to the "
                        "first '-', DeepCrack's tiles NAME-k); 'none': every file its own group")


def grouped_split(args: argparse.Namespace, root: str | Path, stems: list[str] | None = None) -> RealSplit:
    """The grouped train / validation / test split of a real folder from the split flags."""
    folder = real_folder(args, root, stems)
    return split_groups(folder.keys, val_fraction=args.val_fraction, test_fraction=getattr(args, "test_fraction", 0.0),
                        seed=args.split_seed, group_pattern=args.group_pattern, source=str(Path(root).resolve()))


def resolve_valid_channel(args: argparse.Namespace) -> bool:
    """``--valid-channel`` / ``--no-valid-channel``, else on for sparse depth; stored back as a bool."""
    if args.depth == "none":
        if args.valid_channel:
            raise TrainerInputError("--valid-channel needs a depth input (--depth tof|lidar|gt)")
        args.valid_channel = False
    elif args.valid_channel is None:
        args.valid_channel = args.depth in SPARSE_DEPTHS
    return bool(args.valid_channel)


def channels_from_args(args: argparse.Namespace) -> str:
    valid = resolve_valid_channel(args)
    if args.depth == "none":
        return "rgb"
    return "rgbdv" if valid else "rgbd"


def mask_member(args: argparse.Namespace) -> str:
    return getattr(args, "mask_member", None) or DEFAULT_MASK_MEMBER


def shard_source(args: argparse.Namespace, path: str | Path, fraction: float = 0.0, split: str = "all",
                 seed: int = 0) -> ShardSource:
    """Synthetic shards with the run's depth member and label member."""
    return ShardSource(Path(path), args.depth, fraction, split, seed, mask_member=mask_member(args))


def sample_config_from_args(args: argparse.Namespace) -> SampleConfig:
    return SampleConfig(
        channels=channels_from_args(args), near_m=args.depth_near, far_m=args.depth_far,
        depth_norm=args.depth_norm, relief=args.relief, relief_range_mm=args.relief_range_mm,
        relief_sigma=args.relief_sigma, crop=getattr(args, "crop", None), size=args.size,
        rotate_deg=getattr(args, "rotate_deg", 15.0), jitter=getattr(args, "jitter", 0.3),
    )


def real_folder(args: argparse.Namespace, root: str | Path, stems: list[str] | None = None,
                require_masks: bool = True) -> RealFolder:
    root = Path(root)
    if not root.is_dir():
        raise TrainerInputError(f"real folder {root} does not exist")
    uses_depth = args.depth != "none"
    return RealFolder(
        root, image_dir=args.image_dir, mask_dir=args.mask_dir, mask_suffix=args.mask_suffix,
        depth_dir=args.real_depth_dir if uses_depth else None, depth_kind=args.real_depth_kind,
        depth_scale=args.real_depth_scale, focal_px=args.focal_px, baseline_m=args.baseline_m,
        stems=stems, require_masks=require_masks, ignore_dir=getattr(args, "ignore_dir", "ignore"),
    )


def real_split(args: argparse.Namespace, root: str | Path, fraction: float, seed: int,
               stems: list[str] | None = None) -> tuple[RealFolder, RealFolder | None, RealSplit | None]:
    """(train, validation, split) views of one real folder (optionally restricted to ``stems``): a grouped
    split (``--group-pattern``) holding out ``fraction`` of the photos, or the whole folder when it is 0."""
    full = real_folder(args, root, stems)
    if fraction <= 0:
        return full, None, None
    split = split_groups(full.keys, val_fraction=fraction, test_fraction=0.0, seed=seed,
                         group_pattern=getattr(args, "group_pattern", DEFAULT_GROUP_PATTERN),
                         source=str(Path(root).resolve()))
    return real_folder(args, root, split.train), real_folder(args, root, split.val), split


def eval_loader(ds: SegStream, workers: int, device: torch.device) -> DataLoader:
    return DataLoader(ds, batch_size=1, num_workers=workers, pin_memory=device.type == "cuda")


def eval_stream(args: argparse.Namespace, cfg: SampleConfig, shards: ShardSource | None,
                real: RealFolder | None) -> SegStream | None:
    if shards is None and real is None:
        return None
    return SegStream(cfg, shards, real, train=False, seed=args.seed, skip_bad=args.skip_bad)


def describe(ds: Any) -> str:
    parts = []
    if getattr(ds, "shards", None) is not None:
        parts.append(f"{len(ds.shards)} synthetic")
    if getattr(ds, "real", None) is not None:
        parts.append(f"{len(ds.real)} real x{ds.real_repeat}")
    return " + ".join(parts)
