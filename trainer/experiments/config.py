"""Typed options of the experiment commands (``sim2real``, ``curve``, ``benchmark``, ``bench``).

One field per command-line flag, named by its argparse ``dest`` and defaulting to the parser's default
(``tests/trainer/test_options.py`` holds the two together).
"""
from __future__ import annotations

from dataclasses import dataclass

from trainer.seg.config import DataArgs, SplitArgs


@dataclass(kw_only=True)
class ExperimentOptions(DataArgs, SplitArgs):
    """``cracktrain sim2real`` and ``cracktrain curve``: the same trainings, scored under one protocol."""

    real: str
    synthetic: str | None = None  # --data: the synthetic shards (or an images/ + masks/ folder)
    real_test: str | None = None
    arch: str = "lraspp_mobilenet_v3_large"
    max_steps: int = 300
    batch_size: int = 4
    crop: int = 192
    lr: float = 0.001
    lr_scheduler: str = "none"
    loss: str = "bce"
    workers: int = 2
    seed: int = 0
    precise_bn: int = 50
    target: str | None = None
    adapt_band: str = "0.005,0.05"
    adapt_prob: float = 1.0
    finetune_lr: float | None = None
    plain_pretrain: bool = False
    pretrained: str | None = None
    real_root: str = "../shared/data/real"
    out: str = "runs/sim2real"
    device: str | None = None
    no_progress: bool = False
    # sim2real's rows
    runs: str | None = None
    finetune_fraction: float = 0.5
    self_train_steps: int | None = None
    pseudo_portion: float = 0.5
    pseudo_background_portion: float | None = None
    # the label-efficiency curve (``cracktrain curve --sizes``; sim2real's deprecated --curve)
    curve: str | None = None
    repeats: int = 3
    curve_steps: int | None = None
    pretrain_steps: int | None = None
    cross: list[str] | None = None


@dataclass(kw_only=True)
class BenchmarkOptions(SplitArgs):
    """``cracktrain benchmark``: models x real sets under the evaluation protocol."""

    models: list[str]
    out: str
    sets: list[str] | None = None
    val: str = "deepcrack_val=deepcrack_train@val"
    real_root: str = "../shared/data/real"
    title: str | None = None
    errors: int = 0
    cost: list[str] | None = None
    renders: list[str] | None = None
    workers: int = 2
    device: str | None = None
    no_progress: bool = False
    image_dir: str = "images"
    mask_dir: str = "masks"
    mask_suffix: str = ""


@dataclass(kw_only=True)
class BenchOptions(DataArgs):
    """``cracktrain bench``: loader and model throughput."""

    data: str | None = None
    real: str | None = None
    workers: str = "0,1,2"
    samples: int = 64
    crop: int = 256
    arch: str = "lraspp_mobilenet_v3_large"
    model_size: int = 256
    batch_size: int = 4
    steps: int = 5
    device: str | None = None
    seed: int = 0
    json: bool = False
    no_model: bool = False
    fusion: str | None = None


@dataclass(kw_only=True)
class CurveOptions(ExperimentOptions):
    """``cracktrain curve``: the label-efficiency curve (its own output folder and sizes)."""

    out: str = "runs/curve"
    curve: str | None = "0,10,30,60,120,180"  # --sizes
