"""Build sources, sample configs and loaders from the data flags, typed once as ``DataOptions``.

Shared by ``seg``, ``evaluate``, ``predict``, ``sim2real`` and ``bench`` so
every command reads folders and depth the same way.
"""
from __future__ import annotations

import argparse
import dataclasses
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch.utils.data import DataLoader

from trainer.core.errors import TrainerInputError
from trainer.seg.augment import SampleConfig
from trainer.seg.config import DataArgs
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


def resolve_valid_channel(depth: str, valid_channel: bool | None) -> bool:
    """``--valid-channel`` / ``--no-valid-channel``, else on for sparse depth."""
    if depth == "none":
        if valid_channel:
            raise TrainerInputError("--valid-channel needs a depth input (--depth tof|lidar|gt)")
        return False
    return depth in SPARSE_DEPTHS if valid_channel is None else bool(valid_channel)


@dataclass(kw_only=True)
class DataOptions(DataArgs):
    """How real folders and shards are read and turned into network input: the data flags, resolved (the
    validity channel and the label member decided, the photo-group rule added)."""

    valid_channel: bool = False
    mask_member: str = DEFAULT_MASK_MEMBER
    group_pattern: str = DEFAULT_GROUP_PATTERN

    @property
    def channels(self) -> str:
        if self.depth == "none":
            return "rgb"
        return "rgbdv" if self.valid_channel else "rgbd"

    @classmethod
    def from_args(cls, args: DataArgs) -> DataOptions:
        """The options a command's data flags (``add_data_args``) give; the one place that resolves them."""
        flags = {f.name: getattr(args, f.name) for f in dataclasses.fields(DataArgs)}
        return cls(**flags | {"valid_channel": resolve_valid_channel(args.depth, args.valid_channel),
                              "mask_member": args.mask_member or DEFAULT_MASK_MEMBER,
                              "group_pattern": getattr(args, "group_pattern", DEFAULT_GROUP_PATTERN)})


def grouped_split(opts: DataOptions, root: str | Path, *, val_fraction: float, test_fraction: float,
                  seed: int, stems: list[str] | None = None) -> RealSplit:
    """The grouped train / validation / test split of a real folder."""
    folder = real_folder(opts, root, stems)
    return split_groups(folder.keys, val_fraction=val_fraction, test_fraction=test_fraction, seed=seed,
                        group_pattern=opts.group_pattern, source=str(Path(root).resolve()))


def shard_source(opts: DataOptions, path: str | Path, fraction: float = 0.0, split: str = "all",
                 seed: int = 0) -> ShardSource:
    """Synthetic shards with the run's depth member and label member."""
    return ShardSource(Path(path), opts.depth, fraction, split, seed, mask_member=opts.mask_member)


def sample_config(opts: DataOptions, *, crop: int | None = None, rotate_deg: float = 15.0,
                  jitter: float = 0.3) -> SampleConfig:
    return SampleConfig(
        channels=opts.channels, near_m=opts.depth_near, far_m=opts.depth_far, depth_norm=opts.depth_norm,
        relief=opts.relief, relief_range_mm=opts.relief_range_mm, relief_sigma=opts.relief_sigma, crop=crop,
        size=opts.size, rotate_deg=rotate_deg, jitter=jitter,
    )


def real_folder(opts: DataOptions, root: str | Path, stems: list[str] | None = None,
                require_masks: bool = True) -> RealFolder:
    root = Path(root)
    if not root.is_dir():
        raise TrainerInputError(f"real folder {root} does not exist")
    uses_depth = opts.depth != "none"
    return RealFolder(
        root, image_dir=opts.image_dir, mask_dir=opts.mask_dir, mask_suffix=opts.mask_suffix,
        depth_dir=opts.real_depth_dir if uses_depth else None, depth_kind=opts.real_depth_kind,
        depth_scale=opts.real_depth_scale, focal_px=opts.focal_px, baseline_m=opts.baseline_m,
        stems=stems, require_masks=require_masks, ignore_dir=opts.ignore_dir,
    )


def real_split(opts: DataOptions, root: str | Path, fraction: float, seed: int,
               stems: list[str] | None = None) -> tuple[RealFolder, RealFolder | None, RealSplit | None]:
    """(train, validation, split) views of one real folder (optionally restricted to ``stems``): a grouped
    split (``--group-pattern``) holding out ``fraction`` of the photos, or the whole folder when it is 0."""
    full = real_folder(opts, root, stems)
    if fraction <= 0:
        return full, None, None
    split = split_groups(full.keys, val_fraction=fraction, test_fraction=0.0, seed=seed,
                         group_pattern=opts.group_pattern, source=str(Path(root).resolve()))
    return real_folder(opts, root, split.train), real_folder(opts, root, split.val), split


def eval_loader(ds: SegStream, workers: int, device: torch.device) -> DataLoader:
    return DataLoader(ds, batch_size=1, num_workers=workers, pin_memory=device.type == "cuda")


def eval_stream(cfg: SampleConfig, shards: ShardSource | None, real: RealFolder | None, *, seed: int,
                skip_bad: bool) -> SegStream | None:
    if shards is None and real is None:
        return None
    return SegStream(cfg, shards, real, train=False, seed=seed, skip_bad=skip_bad)


def describe(ds: Any) -> str:
    parts = []
    if getattr(ds, "shards", None) is not None:
        parts.append(f"{len(ds.shards)} synthetic")
    if getattr(ds, "real", None) is not None:
        parts.append(f"{len(ds.real)} real x{ds.real_repeat}")
    return " + ".join(parts)
