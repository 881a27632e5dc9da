"""Typed options of the depth-fusion commands (``fusion``, ``fuse``, ``fusion-eval``).

One field per command-line flag, named by its argparse ``dest`` and defaulting to the parser's default
(``tests/trainer/test_options.py`` holds the two together).
"""
from __future__ import annotations

from dataclasses import dataclass, field


@dataclass(kw_only=True)
class FusionTrainConfig:
    """``cracktrain fusion``: one confidence-CNN training on stereo + ToF or LiDAR shards."""

    data: str
    variant: str = "tof"
    val_fraction: float = 0.2
    split_seed: int = 0
    patch: int = 128  # --crop
    batch_size: int = 32
    steps: int = 2000  # --max-steps
    optimizer: str = "adadelta"
    lr: float = 0.01
    rotate_deg: float = 5.0
    no_flips: bool = False
    densify: str = "normconv"
    other_bm3d: float = 0.0
    dilations: str = "thesis"
    disp_ref: str = "none"
    stereo_failures: float = 0.0
    lidar_resample: int = 0
    occluders: int = 0
    stereo_dir: str | None = None
    other_dir: str | None = None
    val_every: int = 0
    log_every: int = 10
    seed: int = 0
    device: str | None = None
    threads: int = 0
    out: str = "runs/fusion"
    resume: str | None = None
    no_progress: bool = False


@dataclass(kw_only=True)
class FuseOptions:
    """``cracktrain fuse``: one stereo + ToF/LiDAR pair fused with a trained checkpoint."""

    stereo: str
    other: str
    left: str
    right: str
    out: str
    ckpt: str | None = None  # --checkpoint
    amplitude: str | None = None
    gt: str | None = None
    device: str | None = None
    post: str = "none"
    post_stage: str = "after"
    bm3d_sigma: float = 0.5
    clahe_clip: float = 2.0
    stereo_holes: str = "cnn"


@dataclass(kw_only=True)
class FusionEvalOptions:
    """``cracktrain fusion-eval``: a checkpoint against the baselines on shards and real scenes."""

    ckpt: str | None = None  # --checkpoint
    data: str | None = None
    keys: str = "val"
    stereo_dir: str | None = None
    other_dir: str | None = None
    bm3d_sigma: float = 0.5
    all_filters: bool = False
    out: str | None = None
    device: str | None = None
    threads: int = 0
    no_progress: bool = False
    stereo_holes: str = "cnn"
    real_stereo: list[str] = field(default_factory=list)
    lidar_lines: int = 32
    lidar_sigma_px: float = 0.25
    lidar_dropout: float = 0.1
    seed: int = 0
