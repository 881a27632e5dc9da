"""Every architecture runs forward and backward with 3, 4 and 5 input channels."""
import pytest
import torch

from trainer.seg.losses import LOSSES, make_loss
from trainer.seg.models import build_model

CASES = [(a, c) for a in ("lraspp_mobilenet_v3_large", "deeplabv3_mobilenet_v3_large", "unet") for c in (3, 4, 5)]
CASES.append(("deeplabv3_resnet50", 4))  # the thesis model, once (RGB-D)


@pytest.mark.parametrize("arch,channels", CASES)
def test_forward_backward(arch, channels):
    torch.manual_seed(0)
    model = build_model(arch, channels).train()
    x = torch.randn(2, channels, 64, 64)
    y = (torch.rand(2, 1, 64, 64) > 0.8).float()
    out = model(x)
    assert out.shape == (2, 1, 64, 64)
    make_loss("bce")(out, y).backward()
    first = next(p for p in model.parameters() if p.ndim == 4)
    assert first.shape[1] == channels and first.grad is not None and first.grad.abs().sum() > 0


def test_odd_sizes_are_padded_and_cropped():
    model = build_model("unet", 3).eval()
    with torch.no_grad():
        assert model(torch.randn(1, 3, 50, 70)).shape == (1, 1, 50, 70)


def test_resnet50_output_stride_8():
    net = build_model("deeplabv3_resnet50", 3).net
    with torch.no_grad():
        feats = net.backbone(torch.randn(1, 3, 64, 64))["out"]
    assert feats.shape[-2:] == (8, 8)


@pytest.mark.parametrize("name", LOSSES)
def test_losses_prefer_correct_logits(name):
    y = (torch.rand(1, 1, 16, 16, generator=torch.Generator().manual_seed(0)) > 0.7).float()
    good, bad = (y * 2 - 1) * 4, (1 - 2 * y) * 4
    f = make_loss(name)
    assert f(good, y) < f(bad, y)
