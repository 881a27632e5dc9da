"""Binary segmentation losses on logits: BCE (thesis default), focal, dice, bce+dice.

Each loss takes an optional per-pixel ``weight`` (0 = ignored, e.g. the uncertain
pixels of a pseudo-label); without it the plain, unweighted form runs, so training
without ignore regions is bit-for-bit what it was.
"""
from __future__ import annotations

from typing import Callable, Optional

import torch
import torch.nn.functional as nnf
from torchvision.ops import sigmoid_focal_loss

from trainer.core.errors import TrainerInputError

LOSSES = ("bce", "focal", "dice", "bce+dice")


Weight = Optional[torch.Tensor]
Loss = Callable[..., torch.Tensor]  # (logits, target, weight=None) -> scalar


def soft_dice_loss(logits: torch.Tensor, target: torch.Tensor, weight: Weight = None, eps: float = 1.0) -> torch.Tensor:
    """1 - soft Dice over the whole batch (robust to images without cracks); weight 0 drops a pixel."""
    p = torch.sigmoid(logits.float())
    if weight is not None:
        p, target = p * weight, target * weight
    inter = (p * target).sum()
    return 1 - (2 * inter + eps) / (p.sum() + target.sum() + eps)


def _weighted_mean(per_pixel: torch.Tensor, weight: torch.Tensor) -> torch.Tensor:
    return (per_pixel * weight).sum() / weight.sum().clamp_min(1.0)


def bce_loss(logits: torch.Tensor, target: torch.Tensor, weight: Weight = None) -> torch.Tensor:
    if weight is None:
        return nnf.binary_cross_entropy_with_logits(logits.float(), target)
    return _weighted_mean(nnf.binary_cross_entropy_with_logits(logits.float(), target, reduction="none"), weight)


def focal_loss(logits: torch.Tensor, target: torch.Tensor, weight: Weight = None) -> torch.Tensor:
    if weight is None:
        return sigmoid_focal_loss(logits.float(), target, alpha=0.25, gamma=2.0, reduction="mean")
    return _weighted_mean(sigmoid_focal_loss(logits.float(), target, alpha=0.25, gamma=2.0, reduction="none"), weight)


def bce_dice_loss(logits: torch.Tensor, target: torch.Tensor, weight: Weight = None) -> torch.Tensor:
    return bce_loss(logits, target, weight) + soft_dice_loss(logits, target, weight)


def make_loss(name: str) -> Loss:
    losses = {"bce": bce_loss, "focal": focal_loss, "dice": soft_dice_loss, "bce+dice": bce_dice_loss}
    if name not in losses:
        raise TrainerInputError(f"unknown --loss {name!r}; choose from {', '.join(LOSSES)}")
    return losses[name]
