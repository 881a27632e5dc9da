"""Target BatchNorm (AdaBN): a model's BN statistics re-estimated on unlabeled site photos.

Why: a network trained on renders normalises every layer with the renders' feature
statistics. On real photos those statistics differ (texture, noise, colour), so every
BN layer shifts and scales the features wrongly, even where the learned filters would
transfer. Li et al. 2016 ("Revisiting Batch Normalization for practical domain
adaptation") replace the statistics with the target domain's; no labels and no
gradient step are needed, only photos of the site. The weights are untouched.

The photos are seen as the trained model sees its inputs: random crops of the
training crop size at native scale (no resize, rotation or colour jitter), normalised
with the model's own sample config. Crops are a pure function of (seed, index).
"""
from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import torch
from torch.utils.data import DataLoader, Dataset

from trainer.core.errors import TrainerInputError
from trainer.core.imageio import read_rgb
from trainer.seg.augment import SampleConfig, sample_generator, sample_to_tensors
from trainer.seg.precise_bn import precise_bn

DEFAULT_BATCHES = 50  # batches of crops averaged per re-estimate (400 crops at batch 8)


def photo_crop_config(cfg: SampleConfig, crop: int | None) -> SampleConfig:
    """The model's sample config with only flips and a native-scale crop left as augmentation."""
    if cfg.channels != "rgb":
        raise TrainerInputError(f"target BN needs an RGB model; this one takes {cfg.channels} (photos have no depth)")
    return replace(cfg, crop=crop, scale_min=1.0, scale_max=1.0, rotate_deg=0.0, jitter=0.0, depth_bc=0.0)


class PhotoCrops(Dataset):
    """``length`` crops of unlabeled photos: index i is photo ``order[i % n]``, crop seeded by (seed, i)."""

    def __init__(self, paths: Sequence[str | Path], cfg: SampleConfig, length: int, seed: int = 0) -> None:
        if not paths:
            raise TrainerInputError("target BN: no target photos")
        self.paths = [str(p) for p in paths]
        self.cfg, self.length, self.seed = cfg, int(length), int(seed)
        self.order = np.random.default_rng(np.random.SeedSequence([self.seed, 7])).permutation(len(self.paths))

    def __len__(self) -> int:
        return self.length

    def __getitem__(self, i: int) -> dict[str, Any]:
        path = self.paths[int(self.order[i % len(self.paths)])]
        rgb = read_rgb(path)
        h, w = rgb.shape[:2]
        if self.cfg.crop and min(h, w) < self.cfg.crop:
            raise TrainerInputError(f"target BN: {path} is {w}x{h}, smaller than the {self.cfg.crop}-px crop")
        sample = {"key": Path(path).stem, "rgb": rgb, "mask": None}
        out = sample_to_tensors(sample, self.cfg, sample_generator(self.seed, 0, 9, i))
        return {"image": out["image"]}


def adapt_bn_to_photos(model: torch.nn.Module, paths: Sequence[str | Path], cfg: SampleConfig, device: torch.device,
                       *, crop: int | None, batches: int = DEFAULT_BATCHES, batch_size: int = 8, workers: int = 0,
                       seed: int = 0) -> int:
    """Replace ``model``'s BN running statistics by their average over ``batches`` batches of photo crops.
    Returns the number of batches used; the model is left in eval mode."""
    if batches <= 0:
        raise TrainerInputError(f"target BN: batches must be > 0, got {batches}")
    ds = PhotoCrops(paths, photo_crop_config(cfg, crop), batches * batch_size, seed)
    loader = DataLoader(ds, batch_size=batch_size, num_workers=workers, shuffle=False,
                        prefetch_factor=2 if workers > 0 else None)
    used = precise_bn(model, loader, device, batches)
    model.eval()
    return used


__all__ = ["PhotoCrops", "adapt_bn_to_photos", "photo_crop_config", "DEFAULT_BATCHES"]
