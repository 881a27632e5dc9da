"""The confidence CNN of the ToF/LiDAR-stereo fusion (thesis Fig. 3.8 / 4.33, Agresti et al. 2019).

Six convolutions (5x5 -> 64, 3x3 -> 128 three times, 3x3 -> 256, 3x3 -> 2)
with PReLU (initial slope 0.02) between them and border-replicate padding, so
the two output maps (confidence of stereo, confidence of ToF/LiDAR) have the
input's size. No pooling and no striding: a per-pixel score from a 15x15
receptive field. The output is left unbounded, as in the thesis (the MSE
targets exp(-|D - D_GT|) lie in (0, 1]).

``dilations`` (ours, ``cracktrain fusion --dilations wide``) dilates the five 3x3
layers: ``WIDE`` = (2, 4, 8, 4, 1) widens the receptive field to 43x43 at the same
weights and cost. Why: on a real scene the LiDAR fails where its interpolation
crosses an occlusion between scan lines 12 px apart (Middlebury Cones), which a
15 px window barely spans.
"""
from __future__ import annotations

import torch
from torch import nn

from trainer.core.errors import TrainerInputError

LAYERS = ((5, 64), (3, 128), (3, 128), (3, 128), (3, 256), (3, 2))  # (kernel, output channels)
PRELU_INIT = 0.02
IN_CHANNELS = {"tof": 4, "lidar": 3, "lidar4": 4}
THESIS = (1, 1, 1, 1, 1)  # dilation of each 3x3 layer
WIDE = (2, 4, 8, 4, 1)
DILATIONS = {"thesis": THESIS, "wide": WIDE}


def receptive_field(dilations: tuple[int, ...] = THESIS) -> int:
    """Side (px) of the square of input pixels one output pixel sees."""
    return 1 + (LAYERS[0][0] - 1) + sum((k - 1) * d for (k, _), d in zip(LAYERS[1:], dilations))


class ConfidenceCNN(nn.Module):
    """[B,C,H,W] normalised inputs -> [B,2,H,W] confidences (stereo, other sensor)."""

    def __init__(self, in_channels: int = 4, dilations: tuple[int, ...] = THESIS) -> None:
        super().__init__()
        if in_channels not in (3, 4):
            raise TrainerInputError(f"the confidence CNN takes 3 (LiDAR) or 4 (ToF, LiDAR4) input channels, got {in_channels}")
        dilations = tuple(int(d) for d in dilations)
        if len(dilations) != len(LAYERS) - 1 or min(dilations) < 1:
            raise TrainerInputError(f"the confidence CNN needs {len(LAYERS) - 1} dilations >= 1, got {dilations}")
        self.in_channels, self.dilations = in_channels, dilations
        layers: list[nn.Module] = []
        cin = in_channels
        for i, (k, cout) in enumerate(LAYERS):
            d = 1 if i == 0 else dilations[i - 1]
            layers.append(nn.Conv2d(cin, cout, k, padding=d * (k // 2), dilation=d, padding_mode="replicate"))
            if i < len(LAYERS) - 1:
                layers.append(nn.PReLU(cout, init=PRELU_INIT))
            cin = cout
        self.net = nn.Sequential(*layers)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        return self.net(x)
