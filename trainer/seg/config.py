"""Typed options of the segmentation commands (``seg``, ``evaluate``, ``predict``).

One field per command-line flag, named by its argparse ``dest`` and defaulting to the parser's default
(``tests/trainer/test_options.py`` holds the two together), so a library call reads the same as a command.
"""
from __future__ import annotations

from dataclasses import dataclass

from trainer.seg.depth import DEFAULT_RELIEF, DEFAULT_RELIEF_RANGE_MM, DEFAULT_RELIEF_SIGMA
from trainer.seg.real_split import DEFAULT_GROUP_PATTERN


@dataclass(kw_only=True)
class DataArgs:
    """Real-folder layout and depth handling (``add_data_args``); ``DataOptions.from_args`` types them once more."""

    image_dir: str = "images"
    mask_dir: str = "masks"
    mask_suffix: str = ""
    ignore_dir: str = "ignore"
    real_depth_dir: str | None = None
    real_depth_kind: str = "depth"
    real_depth_scale: float = 1.0
    focal_px: float | None = None
    baseline_m: float | None = None
    depth: str = "none"
    valid_channel: bool | None = None
    depth_near: float = 0.2
    depth_far: float = 5.0
    depth_norm: str = "fixed"
    relief: str = DEFAULT_RELIEF
    relief_range_mm: float = DEFAULT_RELIEF_RANGE_MM
    relief_sigma: float = DEFAULT_RELIEF_SIGMA
    mask_member: str | None = None
    size: int | None = None
    skip_bad: bool = False


@dataclass(kw_only=True)
class SplitArgs:
    """The grouped train / validation / test split of a real folder (``add_split_args`` with 0.2 / 0.2)."""

    val_fraction: float = 0.2
    test_fraction: float = 0.2
    split_seed: int = 0
    group_pattern: str = DEFAULT_GROUP_PATTERN


@dataclass(kw_only=True)
class SegTrainConfig(DataArgs):
    """One segmentation training (``cracktrain seg``); experiments build it with other settings."""

    data: str | None = None
    real: str | None = None
    real_repeat: int | None = None
    real_stems: list[str] | None = None  # the real folder's training stems (set by experiments, not a flag)
    val_data: str | None = None
    val_real: str | None = None
    val_fraction: float = 0.0
    split_seed: int = 0
    group_pattern: str = DEFAULT_GROUP_PATTERN
    arch: str = "deeplabv3_resnet50"
    loss: str = "bce"
    lr: float = 0.0001
    weight_decay: float = 0.0
    lr_scheduler: str = "none"
    batch_size: int = 16
    epochs: int = 30
    max_steps: int | None = None
    crop: int | None = 256
    rotate_deg: float = 15.0
    jitter: float = 0.3
    workers: int = 2
    seed: int = 0
    device: str | None = None
    no_amp: bool = False
    sync_bn: bool = False
    val_every: int = 0
    log_every: int = 10
    out: str = "runs/seg"
    resume: str | None = None
    init: str | None = None
    init_steps: int | None = None  # steps the --init weights had seen (stored, not a flag)
    precise_bn: int | None = None
    target: str | None = None
    target_appearance: bool = False
    target_bn: bool = False
    adapt_target: str | None = None  # deprecated spelling of --target F --target-appearance
    adapt_targets: tuple[str, ...] | None = None  # appearance-target photo paths (set by experiments)
    adapt_methods: str = "fourier,reinhard,histogram"
    adapt_band: str = "0.005,0.05"
    adapt_prob: float = 1.0
    bn_target: str | None = None  # deprecated spelling of --target F --target-bn
    bn_targets: tuple[str, ...] | None = None  # target-BN photo paths (set by experiments)
    bn_target_batches: int = 50
    test_only: bool = False
    no_progress: bool = False


@dataclass(kw_only=True)
class EvaluateOptions(DataArgs):
    """``cracktrain evaluate``: one checkpoint on shards and/or a real folder."""

    checkpoint: str
    data: str | None = None
    real: str | None = None
    threshold: float | None = None
    out: str | None = None
    workers: int = 2
    device: str | None = None
    seed: int = 0
    no_progress: bool = False


@dataclass(kw_only=True)
class PredictOptions(DataArgs):
    """``cracktrain predict``: masks (and measurements) for a folder or shard set."""

    input: str
    checkpoint: str
    out: str
    threshold: float | None = None
    pixel_size_m: float | None = None
    intrinsics: str | None = None
    min_length: float = 0.0
    device: str | None = None
    no_progress: bool = False
