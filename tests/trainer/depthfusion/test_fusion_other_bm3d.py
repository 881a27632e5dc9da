"""--other-bm3d: the CNN decides between stereo and the BM3D-filtered ToF/LiDAR candidate.

What must hold: the filtered candidate is exactly BM3D of the densified map and
closer to the truth on a noisy plane, the channels computed from it follow it,
the stereo channel is untouched, and the checkpoint carries the setting so that
fusion-eval rebuilds the same filtered input it was trained on.
"""
from __future__ import annotations

import argparse
import json

import numpy as np
import pytest
import torch
from fusion_samples import write_fusion_shards

from fusion.depth.densify import interpolate_sparse
from fusion.depth.inputs import FusionInputError, build_inputs
from fusion.depth.metrics import disparity_metrics
from fusion.depth.postfilter import bm3d_disparity
from fusion.geometry.stereo import left_right_difference
from trainer.cli import main as cli_main
from trainer.core.errors import TrainerInputError
from trainer.core.options import options_from
from trainer.depthfusion.config import FusionTrainConfig
from trainer.depthfusion.data import load_shard_scenes
from trainer.depthfusion.train import add_fusion_args
from trainer.depthfusion.train import main as fusion_main

D = 8.0


def _noisy_plane(h: int = 48, w: int = 96):
    rng = np.random.default_rng(3)
    tex = rng.integers(0, 256, (h, w + int(D)), dtype=np.uint8)
    left = np.repeat(tex[:, :w, None], 3, axis=2)
    right = np.repeat(tex[:, int(D):, None], 3, axis=2)
    stereo = np.full((h, w), D, np.float32)
    lidar = np.full((h, w), -1.0, np.float32)
    lidar[::4] = D + rng.normal(0.0, 0.5, (len(range(0, h, 4)), w)).astype(np.float32)
    return left, right, stereo, lidar


def test_the_filtered_candidate_is_bm3d_of_the_densified_map_and_the_lidar_channels_follow_it():
    left, right, stereo, lidar = _noisy_plane()
    raw = build_inputs("lidar", stereo, lidar, left, right)
    filt = build_inputs("lidar", stereo, lidar, left, right, other_bm3d=0.5)
    np.testing.assert_allclose(filt.x[..., 1], bm3d_disparity(interpolate_sparse(lidar, "normconv"), 0.5), atol=2e-3)
    np.testing.assert_array_equal(filt.x[..., 0], raw.x[..., 0])  # stereo untouched
    np.testing.assert_array_equal(filt.x[..., 2], left_right_difference(left, right, filt.x[..., 1]))
    assert np.abs(filt.x[..., 1] - D).mean() < 0.6 * np.abs(raw.x[..., 1] - D).mean()  # denoised
    four = build_inputs("lidar4", stereo, lidar, left, right, other_bm3d=0.5)
    np.testing.assert_allclose(four.x[..., :2], filt.x[..., :2], atol=2e-3)  # BM3D repeats to ~1e-3 px, not bit for bit
    np.testing.assert_array_equal(four.x[..., 2], left_right_difference(left, right, four.x[..., 1]))
    with pytest.raises(FusionInputError, match="other_bm3d"):
        build_inputs("lidar", stereo, lidar, left, right, other_bm3d=-1.0)


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    return write_fusion_shards(tmp_path_factory.mktemp("other_bm3d_shards"), 6)


def test_the_checkpoint_carries_the_filter_and_fusion_eval_rebuilds_the_filtered_input(shards, tmp_path, capsys):
    out = tmp_path / "run"
    assert cli_main(["fusion", "--data", str(shards), "--variant", "lidar", "--other-bm3d", "0.4", "--crop", "24",
                     "-b", "4", "--max-steps", "2", "--val-fraction", "0.34", "--no-progress", "--out", str(out)]) == 0
    ckpt = torch.load(out / "last.pt", weights_only=False)
    assert ckpt["sample_config"]["other_bm3d"] == 0.4
    capsys.readouterr()
    assert cli_main(["fusion-eval", "--checkpoint", str(out / "last.pt"), "--no-progress", "--out", str(tmp_path / "ev")]) == 0
    per_scene = json.loads((tmp_path / "ev" / "metrics.json").read_text())["per_scene"]
    scenes = load_shard_scenes(shards, "lidar", keys=ckpt["val_keys"], progress=False, other_bm3d=0.4)
    raw = load_shard_scenes(shards, "lidar", keys=ckpt["val_keys"], progress=False)
    for s, r in zip(scenes, raw):
        assert per_scene[s.key]["LiDAR"]["mae"] == pytest.approx(disparity_metrics(s.x[..., 1], s.gt)["mae"], abs=1e-4)
        assert not np.allclose(s.x[..., 1], r.x[..., 1], atol=1e-2)  # the filter did something
    p = argparse.ArgumentParser()
    add_fusion_args(p)
    resume = options_from(FusionTrainConfig, p.parse_args(
        ["--data", str(shards), "--variant", "lidar", "--resume", str(out / "last.pt"), "--max-steps", "3",
         "--crop", "24", "-b", "4", "--val-fraction", "0.34", "--no-progress", "--out", str(out)]))
    with pytest.raises(TrainerInputError, match="other_bm3d"):  # a resume must not change the inputs
        fusion_main(resume)
