"""--dilations wide: the confidence CNN's receptive field, measured, and carried by the checkpoint."""
from __future__ import annotations

import numpy as np
import pytest
import torch
from fusion_samples import write_fusion_shards

from trainer.cli import main as cli_main
from trainer.core.errors import TrainerInputError
from trainer.depthfusion.apply import load_fusion_model
from trainer.depthfusion.model import THESIS, WIDE, ConfidenceCNN, receptive_field


@pytest.mark.parametrize("dilations,side", [(THESIS, 15), (WIDE, 43)])
def test_an_impulse_reaches_exactly_the_receptive_field(dilations, side):
    torch.manual_seed(0)
    model = ConfidenceCNN(3, dilations).eval()
    assert receptive_field(dilations) == side
    n = 101
    x = torch.zeros(1, 3, n, n, requires_grad=True)
    y = model(x)
    assert y.shape == (1, 2, n, n)  # same size as the input
    y[0, :, n // 2, n // 2].sum().backward()
    rows, cols = np.nonzero(x.grad[0].abs().sum(0).numpy())
    assert rows.max() - rows.min() + 1 == side and cols.max() - cols.min() + 1 == side
    with pytest.raises(TrainerInputError):
        ConfidenceCNN(3, (1, 2, 0, 1, 1))


def test_a_wide_checkpoint_rebuilds_the_wide_network(tmp_path):
    data = write_fusion_shards(tmp_path / "shards", 5)
    out = tmp_path / "run"
    assert cli_main(["fusion", "--data", str(data), "--variant", "lidar", "--dilations", "wide", "--crop", "24",
                     "-b", "2", "--max-steps", "2", "--val-fraction", "0.4", "--no-progress", "--out", str(out)]) == 0
    model, cfg, _ = load_fusion_model(out / "last.pt", torch.device("cpu"))
    assert model.dilations == WIDE and cfg["receptive_field_px"] == 43
    assert cli_main(["fusion-eval", "--checkpoint", str(out / "last.pt"), "--no-progress", "--out", str(tmp_path / "ev")]) == 0
