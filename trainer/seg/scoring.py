"""Score a trained model: load a checkpoint, predict, and sum confusion counts over a set.

Library code shared by ``seg`` (validation), ``evaluate``, ``predict``, ``sim2real``,
the label-efficiency curve and ``benchmark``, so that every figure comes from the
same forward pass and the same dataset-level histogram (``trainer.seg.metrics``).
"""
from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any, Callable, TypeVar

import numpy as np
import torch
from torch.utils.data import DataLoader
from tqdm import tqdm

from trainer.core.checkpoint import load_checkpoint
from trainer.core.errors import TrainerInputError
from trainer.seg.augment import SampleConfig, sample_to_tensors
from trainer.seg.config import DataArgs
from trainer.seg.metrics import ConfusionHistogram
from trainer.seg.models import SegModel, build_model
from trainer.seg.sources import RealFolder
from trainer.seg.stream import SegStream

D = TypeVar("D", bound=DataArgs)


def load_model(path: str | Path, device: torch.device) -> tuple[SegModel, SampleConfig, dict[str, Any]]:
    """Model + the sample config it was trained with, from a cracktrain checkpoint."""
    ckpt = load_checkpoint(path)
    cfg = SampleConfig(**{**ckpt["sample_config"], "crop": None})
    model = build_model(ckpt["args"]["arch"], cfg.in_channels)
    try:
        model.load_state_dict(ckpt["model"])
    except RuntimeError as exc:
        raise TrainerInputError(f"checkpoint {path}: weights do not fit {ckpt['args']['arch']} ({str(exc)[:120]})") from None
    return model.to(device).eval(), cfg, ckpt["args"]


def predict_probability(model: torch.nn.Module, cfg: SampleConfig, sample: dict[str, Any],
                        device: torch.device) -> np.ndarray:
    """Crack probability of one sample at the native size of its RGB (float32 HxW), as the model's sample
    config prepares it (resize, depth normalisation)."""
    t = sample_to_tensors(sample, cfg)
    with torch.no_grad():
        logits = model(t["image"][None].to(device))
    H, W = sample["rgb"].shape[:2]
    if logits.shape[-2:] != (H, W):
        logits = torch.nn.functional.interpolate(logits, size=(H, W), mode="bilinear", align_corners=False)
    return torch.sigmoid(logits)[0, 0].float().cpu().numpy()


@torch.no_grad()
def evaluate(model: torch.nn.Module, loader: DataLoader, device: torch.device, amp: bool = False,
             progress: bool = False, on_batch: Callable[[dict, torch.Tensor], None] | None = None
             ) -> ConfusionHistogram:
    """Dataset-level histogram of probabilities (summed over DDP ranks)."""
    model.eval()
    hist = ConfusionHistogram.empty()
    for batch in tqdm(loader, desc="eval", disable=not progress, leave=False):
        x = batch["image"].to(device, non_blocking=True)
        target = batch.get("mask_full", batch["mask"]).to(device)
        with torch.autocast(device_type=device.type, dtype=torch.float16, enabled=amp):
            logits = model(x)
        if logits.shape[-2:] != target.shape[-2:]:
            logits = torch.nn.functional.interpolate(logits.float(), size=target.shape[-2:], mode="bilinear",
                                                     align_corners=False)
        prob = torch.sigmoid(logits.float())
        hist.update(prob, target)
        if on_batch is not None:
            on_batch(batch, prob)
    hist.all_reduce()
    return hist


def report(hist: ConfusionHistogram, threshold: float) -> dict[str, Any]:
    """The protocol's three figures of one model on one set: scores at ``threshold`` (chosen on validation),
    at 0.5, and at this set's own best threshold (an oracle: it looks at the labels being scored)."""
    return {"threshold": float(threshold), "at_threshold": hist.at(threshold), "at_0.5": hist.at(0.5),
            "oracle": hist.best(), "pixels": {"crack": int(hist.pos.sum()), "background": int(hist.neg.sum())}}


class CheckpointScorer:
    """A checkpoint scored on real folders (loaded on first use, as ``evaluate`` does)."""

    def __init__(self, path: Path, device: torch.device, workers: int, progress: bool) -> None:
        self.path, self.device, self.workers, self.progress = path, device, workers, progress
        self._model = None

    def _load(self):
        if self._model is None:
            model, cfg, _ = load_model(self.path, self.device)
            if cfg.channels != "rgb":
                raise TrainerInputError(f"{self.path}: an {cfg.channels} model needs depth; the benchmark sets are "
                                        "RGB photos")
            self._model = (model, cfg)
        return self._model

    def histogram(self, folder: RealFolder) -> ConfusionHistogram:
        model, cfg = self._load()
        ds = SegStream(cfg, None, folder, train=False)
        loader = DataLoader(ds, batch_size=1, num_workers=self.workers, pin_memory=self.device.type == "cuda")
        return evaluate(model, loader, self.device,
                        self.device.type == "cuda", progress=self.progress)

    def probability(self, sample: dict[str, Any]) -> np.ndarray:
        """Crack probability of one decoded sample at its native size (for per-image error reports)."""
        model, cfg = self._load()
        return predict_probability(model, cfg, sample, self.device)

    def release(self) -> None:
        self._model = None


def inherit_depth(opts: D, train_args: dict[str, Any], cfg: SampleConfig) -> D:
    """``opts`` with the depth source and channel count of the checkpoint (the model needs them).

    The normalisation (fixed/minmax/relief and its parameters) is in ``cfg``,
    the checkpoint's sample config, so it is never taken from the command line.
    The label member of shards follows the checkpoint unless ``--mask-member`` is given.
    """
    return dataclasses.replace(
        opts, depth=train_args.get("depth", "none") if cfg.channels != "rgb" else "none",
        valid_channel=cfg.channels == "rgbdv",
        mask_member=opts.mask_member if opts.mask_member is not None else train_args.get("mask_member"))
