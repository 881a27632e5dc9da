"""The lidar4 fusion input: the LiDAR variant plus the grey difference warped by the stereo disparity.

What must hold: the first three channels are the thesis's LiDAR variant, the
fourth is the stereo-warped difference, it shows a wrong stereo match on a
textured scene, and a pasted stereo failure recomputes it from the corrupted map.
"""
from __future__ import annotations

import numpy as np
import pytest
import torch
from fusion_samples import write_fusion_shards

from fusion.depth.inputs import build_inputs
from fusion.geometry.stereo import left_right_difference
from trainer.cli import main as cli_main
from trainer.depthfusion.augment import corrupt_scene_stereo
from trainer.depthfusion.data import load_shard_scenes

D = 8.0  # the true disparity of the hand-made pair


def _pair(h: int = 48, w: int = 96) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """(left, right, stereo, lidar): a textured fronto-parallel pair at disparity D, right = left shifted by D."""
    rng = np.random.default_rng(0)
    tex = rng.integers(0, 256, (h, w + int(D)), dtype=np.uint8)
    left = np.repeat(tex[:, :w, None], 3, axis=2)
    right = np.repeat(tex[:, int(D):, None], 3, axis=2)  # right(u - D) = left(u)
    stereo = np.full((h, w), D, np.float32)
    lidar = np.where(np.arange(h)[:, None] % 6 == 0, D, -1.0).astype(np.float32) * np.ones((1, w), np.float32)
    return left, right, stereo, lidar


def test_lidar4_is_the_lidar_variant_plus_the_stereo_warped_difference():
    left, right, stereo, lidar = _pair()
    stereo[10:20, 30:50] += 3.0  # a wrong match
    three = build_inputs("lidar", stereo, lidar, left, right)
    four = build_inputs("lidar4", stereo, lidar, left, right)
    assert four.x.shape == (*stereo.shape, 4)
    np.testing.assert_array_equal(four.x[..., :3], three.x)
    np.testing.assert_array_equal(four.stereo_valid, three.stereo_valid)
    np.testing.assert_array_equal(four.x[..., 3], left_right_difference(left, right, four.x[..., 0]))
    ok = np.zeros(stereo.shape, bool)
    ok[:, 12:] = True  # pixels whose match lies inside the right image
    wrong = np.zeros(stereo.shape, bool)
    wrong[10:20, 30:50] = True
    assert np.abs(four.x[..., 3][ok & ~wrong]).max() < 1.0  # right match: the views agree
    assert np.abs(four.x[..., 3][wrong]).mean() > 30.0  # wrong match: only this channel shows it
    assert np.abs(three.x[..., 2][wrong]).mean() < 1.0  # the LiDAR-warped difference cannot


def test_a_pasted_stereo_failure_recomputes_the_stereo_difference_from_the_corrupted_map():
    left, right, stereo, lidar = _pair()
    x = build_inputs("lidar4", stereo, lidar, left, right).x
    grey = (left[..., 0], right[..., 0])
    x0, y0, size = 40, 8, 32
    kinds = set()
    for seed in range(40):
        y, info = corrupt_scene_stereo(x, grey, x0, y0, size, np.random.default_rng(seed), 1.0)
        if info["kind"] == "none":
            continue
        kinds.add(info["kind"])
        changed = y[..., 0] != x[..., 0]
        assert changed.any() and not changed[:y0].any() and not changed[:, :x0].any()  # only inside the window
        assert not changed[y0 + size:].any() and not changed[:, x0 + size:].any()
        np.testing.assert_array_equal(y[..., 1:3], x[..., 1:3])  # LiDAR and its difference untouched
        np.testing.assert_array_equal(y[..., 3], left_right_difference(*grey, y[..., 0]))
        if info["kind"] == "offset":  # a 1-8 px step on texture: the views disagree where it was pasted
            assert np.abs(y[..., 3][changed]).mean() > 10 * max(np.abs(y[..., 3][~changed & (np.arange(96) >= 12)]).mean(), 0.1)
    assert {"offset", "flat"} <= kinds
    assert np.array_equal(x, build_inputs("lidar4", stereo, lidar, left, right).x)  # never in place
    same, _ = corrupt_scene_stereo(x, grey, x0, y0, size, np.random.default_rng(1), 0.0)
    assert same is x


@pytest.fixture(scope="module")
def lidar_shards(tmp_path_factory):
    return write_fusion_shards(tmp_path_factory.mktemp("lidar4_shards"), 7)


def test_lidar4_trains_with_stereo_failures_and_evaluates(lidar_shards, tmp_path, capsys):
    scenes = load_shard_scenes(lidar_shards, "lidar4", progress=False, lidar_resample=1, seed=0)
    assert all(s.x.shape[-1] == 4 and s.grey is not None for s in scenes)
    resampled = [s for s in scenes if "~lidar" in s.key]
    assert resampled and all(np.array_equal(s.x[..., 3], scenes[0].x[..., 3]) for s in resampled
                             if s.key.startswith(scenes[0].key))  # the stereo difference is the sample's own
    out = tmp_path / "run"
    assert cli_main(["fusion", "--data", str(lidar_shards), "--variant", "lidar4", "--stereo-failures", "0.5",
                     "--crop", "24", "-b", "4", "--max-steps", "3", "--val-fraction", "0.34", "--no-progress",
                     "--out", str(out)]) == 0
    ckpt = torch.load(out / "last.pt", weights_only=False)
    assert ckpt["sample_config"]["in_channels"] == 4
    assert ckpt["sample_config"]["channels"][-1] == "lr_diff_stereo"
    capsys.readouterr()
    assert cli_main(["fusion-eval", "--checkpoint", str(out / "last.pt"), "--no-progress", "--out", str(tmp_path / "ev")]) == 0
    assert "| LiDAR |" in (tmp_path / "ev" / "table.md").read_text()
