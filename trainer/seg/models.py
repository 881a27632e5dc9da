"""Segmentation models with 3/4/5 input channels and one crack logit.

* ``deeplabv3_resnet50``: the thesis model (torchvision DeepLabV3, ResNet-50,
  output stride 8, ASPP), randomly initialised (weights=None,
  weights_backbone=None: no downloads; the thesis found ImageNet features
  unhelpful for crack texture). Extra input channels replace the first conv.
* ``lraspp_mobilenet_v3_large`` / ``deeplabv3_mobilenet_v3_large``: CPU-sized.
* ``unet``: a small U-Net (4 levels, ``base`` channels) for quick experiments.

All return logits [B,1,H,W] at the input size. Inputs of any size are padded
(replicate) to a multiple of 32 and the output cropped back, so whole real
photos can be predicted without resizing.
"""
from __future__ import annotations

import torch
import torch.nn.functional as nnf
from torch import nn
from torchvision.models import segmentation as tvseg

from trainer.core.errors import TrainerInputError

ARCHS = ("deeplabv3_resnet50", "lraspp_mobilenet_v3_large", "deeplabv3_mobilenet_v3_large", "unet")


def _replace_conv(conv: nn.Conv2d, in_channels: int) -> nn.Conv2d:
    if conv.in_channels == in_channels:
        return conv
    return nn.Conv2d(in_channels, conv.out_channels, conv.kernel_size, conv.stride, conv.padding,
                     conv.dilation, conv.groups, conv.bias is not None)


class _Block(nn.Sequential):
    def __init__(self, cin: int, cout: int) -> None:
        super().__init__(
            nn.Conv2d(cin, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
            nn.Conv2d(cout, cout, 3, padding=1, bias=False), nn.BatchNorm2d(cout), nn.ReLU(inplace=True),
        )


class UNet(nn.Module):
    """Small U-Net (Ronneberger et al. 2015) with BatchNorm and bilinear upsampling."""

    def __init__(self, in_channels: int = 3, base: int = 16, depth: int = 4) -> None:
        super().__init__()
        chans = [base * 2**i for i in range(depth + 1)]
        self.down = nn.ModuleList([_Block(in_channels, chans[0])] + [_Block(chans[i], chans[i + 1]) for i in range(depth)])
        self.up = nn.ModuleList([_Block(chans[i + 1] + chans[i], chans[i]) for i in reversed(range(depth))])
        self.head = nn.Conv2d(chans[0], 1, 1)

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        skips = []
        for i, blk in enumerate(self.down):
            x = blk(x if i == 0 else nnf.max_pool2d(x, 2))
            skips.append(x)
        for blk, skip in zip(self.up, reversed(skips[:-1])):
            x = nnf.interpolate(x, size=skip.shape[-2:], mode="bilinear", align_corners=False)
            x = blk(torch.cat([x, skip], 1))
        return self.head(x)


class SegModel(nn.Module):
    """Wraps a network: pads to a multiple of 32, returns one logit map at input size."""

    def __init__(self, net: nn.Module, arch: str, in_channels: int) -> None:
        super().__init__()
        self.net, self.arch, self.in_channels = net, arch, in_channels

    def forward(self, x: torch.Tensor) -> torch.Tensor:
        h, w = x.shape[-2:]
        ph, pw = (-h) % 32, (-w) % 32
        if ph or pw:
            x = nnf.pad(x, (0, pw, 0, ph), mode="replicate")
        out = self.net(x)
        if isinstance(out, dict):
            out = out["out"]
        return out[..., :h, :w]


def build_model(arch: str, in_channels: int = 3) -> SegModel:
    """A randomly initialised model (no weight downloads) with ``in_channels`` inputs."""
    if in_channels not in (3, 4, 5):
        raise TrainerInputError(f"in_channels must be 3, 4 or 5, got {in_channels}")
    if arch == "deeplabv3_resnet50":
        net = tvseg.deeplabv3_resnet50(weights=None, weights_backbone=None, num_classes=1, aux_loss=False)
        net.backbone.conv1 = _replace_conv(net.backbone.conv1, in_channels)
    elif arch in ("lraspp_mobilenet_v3_large", "deeplabv3_mobilenet_v3_large"):
        net = getattr(tvseg, arch)(weights=None, weights_backbone=None, num_classes=1, **({"aux_loss": False} if arch.startswith("deeplab") else {}))
        first = net.backbone["0"]
        first[0] = _replace_conv(first[0], in_channels)
    elif arch == "unet":
        net = UNet(in_channels)
    else:
        raise TrainerInputError(f"unknown --arch {arch!r}; choose from {', '.join(ARCHS)}")
    return SegModel(net, arch, in_channels)
