"""Stereo-failure augmentation of the LiDAR/stereo confidence CNN: what it changes and what it keeps."""
from __future__ import annotations

import numpy as np
import pytest

from fusion.depth.confidence import confidence_target
from trainer.cli import main as cli_main
from trainer.depthfusion.augment import FAILURE_KINDS, corrupt_stereo


def _patch(size: int = 48) -> np.ndarray:
    yy, xx = np.mgrid[:size, :size]
    stereo = (20.0 + 0.05 * xx).astype(np.float32)
    lidar = stereo + 0.1
    diff = np.random.default_rng(0).normal(0, 3, (size, size)).astype(np.float32)
    return np.stack([stereo, lidar, diff], axis=-1)


def test_only_the_stereo_channel_changes_inside_the_regions_and_stays_positive():
    x = _patch()
    kinds = set()
    for seed in range(60):
        y, info = corrupt_stereo(x, np.random.default_rng(seed), 1.0)
        kinds.add(info["kind"])
        assert np.array_equal(y[..., 1:], x[..., 1:])  # LiDAR and the LiDAR-warped difference untouched
        changed = y[..., 0] != x[..., 0]
        assert info["pixels"] >= changed.sum() > 0 or info["kind"] == "flat"
        assert (y[..., 0] > 0).all()
    assert kinds == set(FAILURE_KINDS)
    assert np.array_equal(x, _patch())  # the input is never modified in place


def test_probability_zero_is_the_identity_and_draws_are_seeded():
    x = _patch()
    y, info = corrupt_stereo(x, np.random.default_rng(1), 0.0)
    assert y is x and info == {"kind": "none", "pixels": 0}
    a, _ = corrupt_stereo(x, np.random.default_rng(5), 0.7)
    b, _ = corrupt_stereo(x, np.random.default_rng(5), 0.7)
    assert np.array_equal(a, b)
    untouched = sum(corrupt_stereo(x, np.random.default_rng(s), 0.5)[1]["kind"] == "none" for s in range(400))
    assert 160 < untouched < 240  # about half the patches stay clean at p = 0.5


def test_targets_follow_the_corrupted_map():
    """The label is exp(-|D - GT|) of what the CNN is shown: a pasted 1-8 px step lowers it."""
    x = _patch()
    gt = x[..., 0].copy()
    for seed in range(40):
        y, info = corrupt_stereo(x, np.random.default_rng(seed), 1.0)
        if info["kind"] == "offset":
            break
    region = y[..., 0] != x[..., 0]
    t = confidence_target(y[..., 0], gt)
    assert t[~region].min() == pytest.approx(1.0)
    assert t[region].max() <= np.exp(-1.0) + 1e-6


@pytest.mark.parametrize("extra,message", [(["--variant", "tof", "--stereo-failures", "0.5"], "needs --variant lidar"),
                                           (["--variant", "lidar", "--stereo-failures", "2"], "probability in [0, 1]")])
def test_bad_options_are_a_one_line_error_before_anything_is_written(tmp_path, capsys, extra, message):
    with pytest.raises(ValueError, match="probability"):
        corrupt_stereo(_patch(), np.random.default_rng(0), 1.5)
    rc = cli_main(["fusion", "--data", str(tmp_path), *extra, "--max-steps", "1", "--out", str(tmp_path / "r"), "--no-progress"])
    err = capsys.readouterr().err.strip()
    assert rc == 1 and message in err and len(err.splitlines()) == 1
    assert not (tmp_path / "r").exists()
