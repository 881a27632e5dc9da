"""Relief normalisation survives the checkpoint (train -> evaluate/predict), --mask-member picks the label,
and RGB vs RGB-D runs score the same held-out pixels."""
import json
from pathlib import Path

import cv2
import numpy as np
import OpenEXR
import pytest
import torch
from real_folders import write_real_folder
from synthetic_shards import write_shards

from trainer.cli import main
from trainer.core.errors import TrainerInputError
from trainer.seg.augment import SampleConfig, sample_to_tensors
from trainer.seg.depth import normalise_depth
from trainer.seg.scoring import load_model
from trainer.seg.sources import ShardSource


def _thesis_mask(s: dict) -> np.ndarray:
    """A label that differs from ``mask.png`` everywhere it can: the band 6 px below the crack."""
    return np.roll(s["mask.png"], 6, axis=0)


@pytest.fixture(scope="module")
def shards(tmp_path_factory):
    return write_shards(tmp_path_factory.mktemp("relief") / "shards", extra={"mask_thesis.png": _thesis_mask})


def _seg(shards: Path, out: Path, *extra: str) -> int:
    return main(["seg", "--data", str(shards), "--arch", "unet", "--batch-size", "2", "--crop", "32",
                 "--workers", "0", "--max-steps", "2", "--out", str(out), "--no-progress", *extra])


def test_mask_member_picks_the_label(shards):
    plain = {s["key"]: s["mask"] for i in range(2) for s in ShardSource(shards, "none").iter_shard(i)}
    alt = {s["key"]: s["mask"] for i in range(2)
           for s in ShardSource(shards, "none", mask_member="mask_thesis.png").iter_shard(i)}
    assert plain.keys() == alt.keys() and len(alt) == 8
    for k in alt:
        assert np.array_equal(alt[k], np.roll(plain[k], 6, axis=0)) and not np.array_equal(alt[k], plain[k])


def test_missing_mask_member_is_a_one_line_error_naming_shard_and_member(shards, tmp_path, capsys):
    with pytest.raises(TrainerInputError, match=r"shard-000000\.tar.*mask_visible\.png"):
        ShardSource(shards, "none", mask_member="mask_visible.png")
    assert _seg(shards, tmp_path / "run", "--mask-member", "mask_visible.png") == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "shard-000000.tar" in err[0] and "mask_visible.png" in err[0]


def test_relief_choice_is_stored_and_reused_by_evaluate_and_predict(shards, tmp_path):
    run = tmp_path / "run"
    assert _seg(shards, run, "--depth", "gt", "--depth-norm", "relief", "--relief", "plane",
                "--relief-range-mm", "15", "--mask-member", "mask_thesis.png") == 0
    ckpt = run / "checkpoint.pt"
    model, cfg, train_args = load_model(ckpt, torch.device("cpu"))
    assert (cfg.depth_norm, cfg.relief, cfg.relief_range_mm, cfg.channels) == ("relief", "plane", 15.0, "rgbd")
    assert train_args["mask_member"] == "mask_thesis.png"

    # evaluate: command-line depth flags are ignored, the checkpoint's labels and normalisation are used
    ev = tmp_path / "ev"
    assert main(["evaluate", "-c", str(ckpt), "--data", str(shards), "--depth-norm", "fixed", "--out", str(ev),
                 "--workers", "0", "--no-progress"]) == 0
    m = json.loads((ev / "metrics.json").read_text())
    assert m["input"]["depth_norm"] == "relief" and m["input"]["relief"] == "plane"
    assert m["data"]["mask_member"] == "mask_thesis.png"

    # predict on a real RGB-D folder: same probabilities as the model fed by the relief normalisation
    real = write_real_folder(tmp_path / "real", n=2)
    (real / "depth").mkdir()
    v, u = np.mgrid[0:48, 0:64].astype(np.float32)
    depth = 1.0 / (2.0 + 0.004 * u + 0.002 * v)  # a tilted plane seen in perspective (1/Z linear in u, v)
    depth[20:23, 4:60] += 0.008  # an 8 mm groove
    depth[:, :6] = -1  # a hole band
    for stem in ("000", "001"):
        OpenEXR.File({"type": OpenEXR.scanlineimage}, {"Z": depth}).write(str(real / "depth" / f"{stem}.exr"))
    pred = tmp_path / "pred"
    assert main(["predict", str(real), "-c", str(ckpt), "--real-depth-dir", "depth", "--depth-norm", "fixed",
                 "--out", str(pred), "--no-progress"]) == 0
    rgb = cv2.cvtColor(cv2.imread(str(real / "images/000.png")), cv2.COLOR_BGR2RGB)
    x = sample_to_tensors({"key": "000", "rgb": rgb, "mask": None, "depth": depth}, cfg)["image"]
    d_relief, _ = normalise_depth(depth, mode="relief", relief="plane", relief_range_mm=15.0)
    assert torch.allclose(x[3], torch.from_numpy(d_relief))
    assert d_relief[21, 30] == pytest.approx(-8 / 15, abs=0.01)
    with torch.no_grad():
        prob = torch.sigmoid(model(x[None]))[0, 0].numpy()
    written = cv2.imread(str(pred / "000_prob.png"), cv2.IMREAD_UNCHANGED)
    assert np.abs(written.astype(int) - np.round(prob * 255).astype(int)).max() <= 1


def test_rgb_and_rgbd_runs_score_the_same_held_out_pixels(shards, tmp_path):
    """The README's RGB vs RGB-D recipe: same seed, split and steps -> the same validation labels."""
    totals = []
    for name, extra in (("rgb", ()), ("relief", ("--depth", "gt", "--depth-norm", "relief")),
                        ("tof", ("--depth", "tof", "--depth-norm", "relief"))):
        out = tmp_path / name
        assert _seg(shards, out, "--val-fraction", "0.4", "--seed", "3", *extra) == 0
        a = json.loads((out / "metrics_val.json").read_text())["latest"]["at_threshold"]
        totals.append((a["tp"] + a["fn"], a["tp"] + a["fp"] + a["tn"] + a["fn"]))
    assert totals[0][1] > 0 and totals[0][0] > 0
    assert totals[0] == totals[1] == totals[2]
    cfg = load_model(tmp_path / "tof" / "checkpoint.pt", torch.device("cpu"))[1]
    assert isinstance(cfg, SampleConfig) and cfg.channels == "rgbdv"  # sparse ToF: validity on by default


def test_a_comma_list_trains_several_datasets_together(shards, tmp_path, capsys):
    other = write_shards(tmp_path / "other", n_shards=1, per_shard=3, seed=7)
    both = ShardSource(f"{shards},{other}", "none")
    assert len(both.shards) == 3 and len(both) == 8 + 3
    masks = [s["mask"] for i in range(3) for s in both.iter_shard(i)]
    alone = [s["mask"] for s in ShardSource(other, "none").iter_shard(0)]
    assert all(np.array_equal(a, b) for a, b in zip(masks[8:], alone))  # same keys, other dataset: both kept
    with pytest.raises(TrainerInputError, match="same shard twice"):
        ShardSource(f"{shards},{shards}", "none")
    assert _seg(shards, tmp_path / "run", "--data", f"{shards},{tmp_path / 'missing'}") == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "missing" in err[0]
