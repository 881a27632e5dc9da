"""Precise BN after a fine-tune: BN running statistics recomputed with the final weights."""

import torch

from trainer.seg.config import SegTrainConfig
from trainer.seg.precise_bn import precise_bn
from trainer.seg.train import precise_bn_batches


def _batches(n, mean, std, seed=0):
    g = torch.Generator().manual_seed(seed)
    return [{"image": mean + std * torch.randn(4, 3, 8, 8, generator=g)} for _ in range(n)]


def test_statistics_are_the_plain_average_over_the_batches_with_the_current_weights():
    model = torch.nn.Sequential(torch.nn.Conv2d(3, 3, 1), torch.nn.BatchNorm2d(3, momentum=0.01))
    bn = model[1]
    bn.running_mean.fill_(100.0)  # lagging statistics, far from what the weights now produce
    bn.running_var.fill_(1e4)
    weights = {k: v.clone() for k, v in model.state_dict().items() if "running" not in k and "num_batches" not in k}
    model.eval()
    batches = _batches(30, mean=2.0, std=3.0)
    assert precise_bn(model, batches, torch.device("cpu"), max_batches=20) == 20
    with torch.no_grad():
        feats = [model[0](b["image"]) for b in batches[:20]]
    want_mean = torch.stack([f.mean(dim=(0, 2, 3)) for f in feats]).mean(0)
    want_var = torch.stack([f.transpose(0, 1).reshape(3, -1).var(dim=1) for f in feats]).mean(0)
    assert torch.allclose(bn.running_mean, want_mean, atol=1e-5)
    assert torch.allclose(bn.running_var, want_var, rtol=1e-4)
    assert bn.momentum == 0.01 and not model.training  # momentum and mode restored
    assert all(torch.equal(v, model.state_dict()[k]) for k, v in weights.items())  # weights untouched


def test_no_batchnorm_no_batches_or_zero_is_a_no_op():
    lin = torch.nn.Sequential(torch.nn.Conv2d(3, 3, 1))
    assert precise_bn(lin, _batches(2, 0.0, 1.0), torch.device("cpu"), 5) == 0
    bn = torch.nn.BatchNorm2d(3)
    bn.running_mean.fill_(7.0)
    assert precise_bn(bn, [], torch.device("cpu"), 5) == 0
    assert precise_bn(bn, _batches(2, 0.0, 1.0), torch.device("cpu"), 0) == 0
    assert torch.all(bn.running_mean == 7.0)


def test_on_by_default_only_for_a_fine_tune():
    assert precise_bn_batches(SegTrainConfig(init=None, precise_bn=None)) == 0
    assert precise_bn_batches(SegTrainConfig(init="pre.pt", precise_bn=None)) == 50
    assert precise_bn_batches(SegTrainConfig(init="pre.pt", precise_bn=0)) == 0
    assert precise_bn_batches(SegTrainConfig(init=None, precise_bn=7)) == 7
