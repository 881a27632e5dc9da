"""Binary segmentation losses on logits: BCE (thesis default), focal, dice, bce+dice."""
from __future__ import annotations

from typing import Callable

import torch
import torch.nn.functional as nnf
from torchvision.ops import sigmoid_focal_loss

from trainer.errors import TrainerInputError

LOSSES = ("bce", "focal", "dice", "bce+dice")


def soft_dice_loss(logits: torch.Tensor, target: torch.Tensor, eps: float = 1.0) -> torch.Tensor:
    """1 - soft Dice over the whole batch (robust to images without cracks)."""
    p = torch.sigmoid(logits.float())
    inter = (p * target).sum()
    return 1 - (2 * inter + eps) / (p.sum() + target.sum() + eps)


def make_loss(name: str) -> Callable[[torch.Tensor, torch.Tensor], torch.Tensor]:
    if name == "bce":
        return lambda lg, t: nnf.binary_cross_entropy_with_logits(lg.float(), t)
    if name == "focal":
        return lambda lg, t: sigmoid_focal_loss(lg.float(), t, alpha=0.25, gamma=2.0, reduction="mean")
    if name == "dice":
        return soft_dice_loss
    if name == "bce+dice":
        return lambda lg, t: nnf.binary_cross_entropy_with_logits(lg.float(), t) + soft_dice_loss(lg, t)
    raise TrainerInputError(f"unknown --loss {name!r}; choose from {', '.join(LOSSES)}")
