"""Sample dict -> network tensors, with joint augmentation of RGB, depth and mask.

Why joint: the label and the depth must stay on the same pixels as the photo.
Depth, validity and mask are stacked into one tensor and warped together with
*nearest* interpolation (no bleeding of invalid depth or soft label edges),
while RGB gets the same geometric parameters with bilinear interpolation.
Photometric changes are split: colour jitter touches RGB only,
brightness/contrast touches depth only and only its valid pixels.

Every random draw comes from the ``torch.Generator`` passed in; callers seed
it per sample from (run seed, epoch, sample id), so augmentation does not depend
on worker count or order and a resumed run sees the same images.

Input channels: ``rgb`` (3), ``rgbd`` (4: RGB + depth), ``rgbdv`` (5: RGB +
depth + valid). RGB is normalised with ImageNet mean/std; depth is in [0,1]
(``fixed``/``minmax``) or [-1,1] (``relief``: local relief in mm / range; see
``trainer.seg.depth``) with 0 where invalid; valid is 0/1. Relief depth gets a
contrast change only (a brightness offset would fake a step in the surface).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np
import torch
from torchvision.transforms import InterpolationMode
from torchvision.transforms.v2 import functional as F

from trainer.core.errors import TrainerInputError
from trainer.seg.depth import (
    DEFAULT_FAR_M,
    DEFAULT_NEAR_M,
    DEFAULT_RELIEF,
    DEFAULT_RELIEF_RANGE_MM,
    DEFAULT_RELIEF_SIGMA,
    DEPTH_NORMS,
    RELIEF_METHODS,
    normalise_depth,
)

CHANNELS = {"rgb": 3, "rgbd": 4, "rgbdv": 5}
RGB_MEAN = torch.tensor([0.485, 0.456, 0.406]).view(3, 1, 1)
RGB_STD = torch.tensor([0.229, 0.224, 0.225]).view(3, 1, 1)


@dataclass
class SampleConfig:
    """How samples become tensors; stored in checkpoints so predict/evaluate match training."""

    channels: str = "rgb"
    near_m: float = DEFAULT_NEAR_M
    far_m: float = DEFAULT_FAR_M
    depth_norm: str = "fixed"  # fixed | minmax | relief (see trainer.seg.depth)
    relief: str = DEFAULT_RELIEF  # relief reference: lowpass | plane
    relief_range_mm: float = DEFAULT_RELIEF_RANGE_MM  # +- this many mm map to +-1
    relief_sigma: float = DEFAULT_RELIEF_SIGMA  # low-pass window, fraction of the shorter side
    crop: int | None = None  # training crop size (px); None = keep full image
    size: int | None = None  # resize shorter side to this before anything else (eval and train)
    # augmentation (train only)
    scale_min: float = 0.75
    scale_max: float = 1.5
    rotate_deg: float = 15.0
    hflip: float = 0.5
    vflip: float = 0.5
    jitter: float = 0.3  # brightness/contrast/saturation strength; hue = jitter/6
    depth_bc: float = 0.1  # depth brightness (+-) and contrast (1 +-) strength

    def __post_init__(self) -> None:
        if self.channels not in CHANNELS:
            raise TrainerInputError(f"channels must be one of {sorted(CHANNELS)}, got {self.channels!r}")
        if self.depth_norm not in DEPTH_NORMS:
            raise TrainerInputError(f"--depth-norm must be one of {DEPTH_NORMS}, got {self.depth_norm!r}")
        if self.relief not in RELIEF_METHODS:
            raise TrainerInputError(f"--relief must be one of {RELIEF_METHODS}, got {self.relief!r}")
        if not self.relief_range_mm > 0 or not self.relief_sigma > 0:
            raise TrainerInputError(f"--relief-range-mm ({self.relief_range_mm}) and --relief-sigma "
                                    f"({self.relief_sigma}) must be > 0")

    @property
    def in_channels(self) -> int:
        return CHANNELS[self.channels]


def _u(g: torch.Generator, lo: float, hi: float) -> float:
    return lo + (hi - lo) * float(torch.rand((), generator=g))


def _geo(rgb: torch.Tensor, aux: torch.Tensor, size_hw: tuple[int, int]) -> tuple[torch.Tensor, torch.Tensor]:
    rgb = F.resize(rgb, list(size_hw), interpolation=InterpolationMode.BILINEAR, antialias=True)
    aux = F.resize(aux, list(size_hw), interpolation=InterpolationMode.NEAREST)
    return rgb, aux


def augment(rgb: torch.Tensor, aux: torch.Tensor, cfg: SampleConfig, g: torch.Generator) -> tuple[torch.Tensor, torch.Tensor]:
    """Random resize, rotation, flips, crop (joint); colour jitter (RGB); depth b/c (valid depth).

    ``rgb`` is float [3,H,W] in [0,1]; ``aux`` is [4,H,W] = (depth, valid, mask, ignore).
    Rotation fills 0 (no depth, background, not ignored), as before the ignore channel existed.
    """
    H, W = rgb.shape[-2:]
    s = _u(g, cfg.scale_min, cfg.scale_max)
    if cfg.crop:  # never smaller than the crop, so crops need no padding
        s = max(s, cfg.crop / min(H, W))
    if abs(s - 1.0) > 1e-6:
        rgb, aux = _geo(rgb, aux, (max(1, round(H * s)), max(1, round(W * s))))
    if cfg.rotate_deg > 0:
        angle = _u(g, -cfg.rotate_deg, cfg.rotate_deg)
        rgb = F.rotate(rgb, angle, interpolation=InterpolationMode.BILINEAR, fill=0.0)
        aux = F.rotate(aux, angle, interpolation=InterpolationMode.NEAREST, fill=0.0)
    if float(torch.rand((), generator=g)) < cfg.hflip:
        rgb, aux = F.horizontal_flip(rgb), F.horizontal_flip(aux)
    if float(torch.rand((), generator=g)) < cfg.vflip:
        rgb, aux = F.vertical_flip(rgb), F.vertical_flip(aux)
    if cfg.crop:
        h, w = rgb.shape[-2:]
        top = int(torch.randint(0, h - cfg.crop + 1, (), generator=g))
        left = int(torch.randint(0, w - cfg.crop + 1, (), generator=g))
        rgb = rgb[:, top:top + cfg.crop, left:left + cfg.crop]
        aux = aux[:, top:top + cfg.crop, left:left + cfg.crop]
    if cfg.jitter > 0:
        j = cfg.jitter
        ops = torch.randperm(4, generator=g).tolist()
        factors = [_u(g, 1 - j, 1 + j), _u(g, 1 - j, 1 + j), _u(g, 1 - j, 1 + j), _u(g, -j / 6, j / 6)]
        for op in ops:
            if op == 0:
                rgb = F.adjust_brightness(rgb, factors[0])
            elif op == 1:
                rgb = F.adjust_contrast(rgb, factors[1])
            elif op == 2:
                rgb = F.adjust_saturation(rgb, factors[2])
            else:
                rgb = F.adjust_hue(rgb, factors[3])
        rgb = rgb.clamp(0.0, 1.0)
    if cfg.depth_bc > 0:
        b, c = _u(g, -cfg.depth_bc, cfg.depth_bc), _u(g, 1 - cfg.depth_bc, 1 + cfg.depth_bc)
        depth, valid = aux[0], aux[1] > 0.5
        if valid.any():
            if cfg.depth_norm == "relief":  # scale about the surface (0); no offset
                new = (depth * c).clamp(-1.0, 1.0)
            else:
                mean = depth[valid].mean()
                new = ((depth - mean) * c + mean + b).clamp(0.0, 1.0)
            aux = aux.clone()
            aux[0] = torch.where(valid, new, torch.zeros_like(depth))
    return rgb, aux


def sample_to_tensors(sample: dict[str, Any], cfg: SampleConfig, g: torch.Generator | None = None) -> dict[str, Any]:
    """Numpy sample -> {"image": [C,H,W] float, "mask": [1,H,W] float 0/1, "ignore": [1,H,W] 0/1, "key"}.

    ``sample["ignore"]`` (uint8, > 127 = ignored; optional) marks pixels the loss skips.

    With ``g`` given the sample is augmented (training); without it, it is only
    resized (if ``cfg.size``) and normalised (evaluation/prediction).
    """
    rgb_np = sample["rgb"]
    H, W = rgb_np.shape[:2]
    rgb = torch.from_numpy(np.ascontiguousarray(rgb_np)).permute(2, 0, 1).float().div_(255.0)
    depth_m = sample.get("depth")
    if cfg.channels != "rgb" and depth_m is None:
        raise TrainerInputError(f"{sample.get('path', sample.get('key'))}: model needs depth ({cfg.channels}) but the sample has none")
    if depth_m is not None and cfg.channels != "rgb":
        d, v = normalise_depth(depth_m, cfg.near_m, cfg.far_m, cfg.depth_norm, cfg.relief, cfg.relief_range_mm,
                               cfg.relief_sigma)
    else:
        d = v = np.zeros((H, W), np.float32)
    mask_np = sample.get("mask")
    m = np.zeros((H, W), np.float32) if mask_np is None else (mask_np > 127).astype(np.float32)
    ignore_np = sample.get("ignore")  # pixels left out of the loss (pseudo-labels' uncertain pixels)
    ig = np.zeros((H, W), np.float32) if ignore_np is None else (ignore_np > 127).astype(np.float32)
    aux = torch.from_numpy(np.stack([d, v, m, ig]))
    if cfg.size:
        s = cfg.size / min(H, W)
        rgb, aux = _geo(rgb, aux, (max(1, round(H * s)), max(1, round(W * s))))
    if g is not None:
        rgb, aux = augment(rgb, aux, cfg, g)
    x = (rgb - RGB_MEAN) / RGB_STD
    n = cfg.in_channels
    if n >= 4:
        x = torch.cat([x, aux[0:1]], 0)
    if n == 5:
        x = torch.cat([x, aux[1:2]], 0)
    out = {"image": x.contiguous(), "mask": aux[2:3].contiguous(), "ignore": aux[3:4].contiguous(), "key": sample["key"]}
    if g is None and cfg.size and m.shape != tuple(aux.shape[-2:]):
        out["mask_full"] = torch.from_numpy(m)[None]  # evaluate at the native label resolution
    return out


def sample_generator(seed: int, epoch: int, *ids: int) -> torch.Generator:
    """A torch.Generator for one sample, a pure function of (seed, epoch, sample ids)."""
    state = np.random.SeedSequence([seed, epoch, *ids]).generate_state(2, dtype=np.uint32)
    g = torch.Generator()
    g.manual_seed(int(state[0]) << 31 ^ int(state[1]))
    return g


__all__ = ["SampleConfig", "augment", "sample_to_tensors", "sample_generator", "CHANNELS"]
