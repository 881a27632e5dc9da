"""Confidence CNN, patch sampler and a short `cracktrain fusion` run on tiny synthetic fusion shards.

The shards hold the members the generator writes with stereo + ToF + LiDAR on
(rgb, right, disp_sgm, disp_tof, tofamp, disp_lidar, disp_gt), made without
Blender: a slanted plane, stereo that is noisy where the image has no texture,
ToF that is noisy where its amplitude is low, so confidence is learnable.
"""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch
from fusion_samples import fusion_sample, write_fusion_shards  # tests/ helper

from crackgen.shards import ShardWriter, sample_key
from trainer.cli import build_parser
from trainer.cli import main as cli_main
from trainer.core.errors import TrainerInputError
from trainer.core.options import options_from
from trainer.depthfusion.config import FusionTrainConfig
from trainer.depthfusion.data import FusionScene, load_shard_scenes, random_patch
from trainer.depthfusion.model import ConfidenceCNN
from trainer.depthfusion.train import make_batch, masked_mse


@pytest.fixture(scope="module")
def fusion_shards(tmp_path_factory):
    return write_fusion_shards(tmp_path_factory.mktemp("fusion_shards"), 3)


@pytest.mark.parametrize("channels,size", [(4, (37, 53)), (3, (16, 16))])
def test_cnn_output_has_the_input_size_and_two_channels(channels, size):
    model = ConfidenceCNN(channels)
    out = model(torch.randn(2, channels, *size))
    assert out.shape == (2, 2, *size)
    assert [m.kernel_size for m in model.modules() if isinstance(m, torch.nn.Conv2d)] == [(5, 5)] + [(3, 3)] * 5
    assert all(m.padding_mode == "replicate" for m in model.modules() if isinstance(m, torch.nn.Conv2d))
    prelu = [m for m in model.modules() if isinstance(m, torch.nn.PReLU)]
    assert len(prelu) == 5 and all(torch.allclose(m.weight, torch.tensor(0.02)) for m in prelu)
    with pytest.raises(TrainerInputError):
        ConfidenceCNN(5)


def test_random_patch_without_augmentation_is_a_crop_and_is_seeded():
    x = np.arange(30 * 40 * 2, dtype=np.float32).reshape(30, 40, 2)
    scene = FusionScene("k", x, x[..., 0].copy())
    p, g = random_patch(scene, 16, np.random.default_rng(0), rotate_deg=0.0, flips=False)
    r0, c0 = np.argwhere(x[..., 0] == p[0, 0, 0])[0]
    np.testing.assert_array_equal(p, x[r0:r0 + 16, c0:c0 + 16])
    np.testing.assert_array_equal(g, p[..., 0])
    a = random_patch(scene, 16, np.random.default_rng(5))
    b = random_patch(scene, 16, np.random.default_rng(5))
    np.testing.assert_array_equal(a[0], b[0])
    # rotated near a border: GT is never invented (-1 outside), inputs replicate
    rot = random_patch(FusionScene("k", x, np.full((30, 40), 5.0, np.float32)), 30, np.random.default_rng(1), 5.0)
    assert set(np.unique(rot[1])) <= {-1.0, 5.0}


def test_masked_mse_ignores_pixels_without_gt():
    pred = torch.tensor([[1.0, 2.0, 3.0]])
    target = torch.tensor([[1.0, float("nan"), 1.0]])
    assert masked_mse(pred, target).item() == pytest.approx(2.0)


def test_missing_members_are_a_one_line_error(tmp_path):
    rng = np.random.default_rng(0)
    with ShardWriter(tmp_path, 0) as w:
        smp = fusion_sample(rng)
        del smp["disp_tof.exr"]
        w.add(sample_key(0, 0), smp)
    with pytest.raises(TrainerInputError, match="disp_tof"):
        load_shard_scenes(tmp_path, "tof", progress=False)


def _args(parser_args: list[str]) -> FusionTrainConfig:
    return options_from(FusionTrainConfig, build_parser().parse_args(parser_args))


def test_a_few_training_steps_reduce_the_loss_then_eval_and_fuse(fusion_shards, tmp_path, capsys):
    torch.set_num_threads(1)
    out = tmp_path / "run"
    common = ["--data", str(fusion_shards), "--val-fraction", "0.34", "--crop", "24", "-b", "4",
              "--optimizer", "adam", "--lr", "0.003", "--no-progress", "--out", str(out)]
    args = _args(["fusion", *common, "--max-steps", "12"])
    scenes = load_shard_scenes(fusion_shards, "tof", progress=False)
    from trainer.depthfusion.data import channel_stats

    mean, std = channel_stats(scenes)
    x, t = make_batch(scenes, args, 10_000, mean, std)  # a fixed batch no training step draws
    torch.manual_seed(args.seed)
    before = masked_mse(ConfidenceCNN(4)(x), t).item()
    assert cli_main(["fusion", *common, "--max-steps", "12"]) == 0
    ckpt = torch.load(out / "last.pt", weights_only=False)
    model = ConfidenceCNN(4)
    model.load_state_dict(ckpt["model"])
    x, t = make_batch(scenes, args, 10_000, ckpt["sample_config"]["mean"], ckpt["sample_config"]["std"])
    with torch.no_grad():
        after = masked_mse(model(x), t).item()
    assert after < 0.5 * before
    assert len(ckpt["val_keys"]) == 2 and not set(ckpt["val_keys"]) & set(ckpt["train_keys"])
    assert "trained 12 steps" in capsys.readouterr().out

    assert cli_main(["fusion-eval", "--checkpoint", str(out / "last.pt"), "--no-progress", "--out", str(tmp_path / "ev")]) == 0
    table = capsys.readouterr().out
    for row in ("| stereo |", "| ToF |", "| fused, max |", "| fused, weighted |", "| fused, max + BM3D after |", "| ToF + BM3D after |"):
        assert row in table
    assert (tmp_path / "ev" / "metrics.json").is_file()

    smp = fusion_sample(np.random.default_rng(9))
    files = {}
    for name, member in (("stereo", "disp_sgm.exr"), ("other", "disp_tof.exr"), ("amplitude", "tofamp.exr"),
                         ("gt", "disp_gt.exr")):
        files[name] = tmp_path / f"{name}.npy"
        np.save(files[name], smp[member])
    import cv2

    for name, member in (("left", "rgb.png"), ("right", "right.png")):
        files[name] = tmp_path / f"{name}.png"
        cv2.imwrite(str(files[name]), smp[member])
    argv = ["fuse", "--checkpoint", str(out / "last.pt"), "--out", str(tmp_path / "fused")]
    argv += [a for k, p in files.items() for a in (f"--{k}", str(p))]
    assert cli_main(argv) == 0
    assert (tmp_path / "fused" / "fused_max.exr").is_file() and "| fused_max |" in capsys.readouterr().out
    assert cli_main([str(tmp_path / "nope.npy") if a == str(files["gt"]) else a for a in argv]) == 1
    assert "nope.npy" in capsys.readouterr().err


def test_median_disparity_reference_makes_the_input_shift_free(fusion_shards, tmp_path, capsys):
    from trainer.depthfusion.data import channel_stats, disparity_reference, relative_input
    from trainer.depthfusion.train import predict_confidence

    scene = load_shard_scenes(fusion_shards, "lidar", progress=False)[0]
    shifted = scene.x.copy()
    shifted[..., :2] += 17.0  # the same scene 17 px nearer in disparity
    ref, ref_shifted = disparity_reference(scene.x, "median"), disparity_reference(shifted, "median")
    assert ref_shifted == pytest.approx(ref + 17.0, abs=1e-4)
    np.testing.assert_allclose(relative_input(shifted, ref_shifted), relative_input(scene.x, ref), atol=1e-4)
    assert disparity_reference(scene.x, "none") == 0.0 and relative_input(scene.x, 0.0) is scene.x
    mean, std = channel_stats([scene], "median")
    assert abs(mean[1]) < 1.0 < abs(channel_stats([scene])[0][1])  # centred on the scene's own level
    torch.manual_seed(0)
    model = ConfidenceCNN(3)
    a = predict_confidence(model, scene.x, mean, std, torch.device("cpu"), "median")
    b = predict_confidence(model, shifted, mean, std, torch.device("cpu"), "median")
    np.testing.assert_allclose(a, b, atol=1e-4)
    assert not np.allclose(predict_confidence(model, shifted, mean, std, torch.device("cpu")), a, atol=1e-3)

    out = tmp_path / "run"
    assert cli_main(["fusion", "--data", str(fusion_shards), "--variant", "lidar", "--disp-ref", "median",
                     "--crop", "16", "-b", "2", "--max-steps", "2", "--no-progress", "--out", str(out)]) == 0
    ckpt = torch.load(out / "last.pt", weights_only=False)
    assert ckpt["sample_config"]["disp_ref"] == "median"
    assert cli_main(["fusion", "--data", str(fusion_shards), "--variant", "lidar", "--crop", "16", "-b", "2",
                     "--max-steps", "3", "--no-progress", "--out", str(out), "--resume", str(out / "last.pt")]) == 1
    assert "disp_ref differ" in capsys.readouterr().err  # resuming without the option is refused


REAL_CONES = Path(__file__).resolve().parents[3].parent / "shared" / "data" / "real" / "stereo" / "middlebury2003_cones"


@pytest.mark.skipif(not REAL_CONES.is_dir(), reason="../shared/data/real is absent")
def test_real_stereo_scene_has_lidar_inputs_and_gt():
    from trainer.depthfusion.real_scenes import SimulatedLidar, real_scene

    args = SimulatedLidar(lines=16, sigma_px=0.25, dropout=0.1, seed=0)
    s = real_scene(REAL_CONES, args, "normconv")
    assert s.x.shape == (375, 450, 3) and s.gt.shape == (375, 450)
    assert (s.x[..., 0] > 0).all() and (s.x[..., 1] > 0).all()  # both candidates dense
    ok = s.gt > 0
    assert np.median(np.abs(s.x[..., 1] - s.gt)[ok]) < 1.0  # interpolated scan lines follow the GT
    with pytest.raises(TrainerInputError, match="neither"):
        real_scene(REAL_CONES.parent, args, "normconv")


def test_skimage_motorcycle_is_a_real_stereo_scene_with_gt():
    """scikit-image's bundled Middlebury 2014 pair loads without files here, and its GT is a disparity: the
    left view matches the right view shifted by it."""
    from fusion.geometry.real_data import load_skimage_motorcycle
    from trainer.depthfusion.real_scenes import SimulatedLidar, real_scene

    s = load_skimage_motorcycle()
    gt, left, right = s["disp_left"], s["left"].astype(np.float32), s["right"].astype(np.float32)
    assert gt.shape == left.shape == (500, 741) and 0.85 < (gt > 0).mean() < 0.99
    ys, xs = np.nonzero(gt > 0)
    xr = np.rint(xs - gt[ys, xs]).astype(int)
    ok = xr >= 0
    err_gt = np.abs(left[ys[ok], xs[ok]] - right[ys[ok], xr[ok]]).mean()
    err_shifted = np.abs(left[ys[ok], xs[ok]] - right[ys[ok], np.clip(xr[ok] + 8, 0, 740)]).mean()
    assert err_gt < 0.5 * err_shifted  # the GT disparity registers the views; 8 px off it does not

    args = SimulatedLidar(lines=16, sigma_px=0.25, dropout=0.1, seed=0)
    scene = real_scene("skimage:motorcycle", args, "normconv")
    assert scene.key == "middlebury2014_motorcycle" and scene.x.shape == (500, 741, 3)
    assert np.median(np.abs(scene.x[..., 1] - scene.gt)[scene.gt > 0]) < 1.0
    with pytest.raises(TrainerInputError, match="not a folder"):
        real_scene("skimage:nothing", args, "normconv")


def test_filled_stereo_holes_take_the_other_sensor_unless_asked(fusion_shards):
    from fusion.depth.inputs import build_inputs
    from trainer.depthfusion.apply import fuse_scene

    smp = fusion_sample(np.random.default_rng(5))
    stereo = smp["disp_sgm.exr"].copy()
    stereo[10:20, 5:25] = -1.0  # an occlusion the stereo matcher left empty
    inp = build_inputs("lidar", stereo, smp["disp_lidar.exr"], smp["rgb.png"], smp["right.png"])
    hole = ~inp.stereo_valid
    assert hole.sum() == 200 and (inp.x[..., 0][hole] > 0).all()  # the CNN still gets a dense map
    torch.manual_seed(0)
    model = ConfidenceCNN(3).eval()
    with torch.no_grad():  # stereo always more confident: the filled value would win everywhere
        model.net[-1].weight.zero_()
        model.net[-1].bias.copy_(torch.tensor([5.0, -5.0]))
    cfg = {"mean": [0.0] * 3, "std": [1.0] * 3}
    dev = torch.device("cpu")
    refused = fuse_scene(model, cfg, inp.x, dev, None, inp.stereo_valid, stereo_holes="other")
    kept = fuse_scene(model, cfg, inp.x, dev, None, inp.stereo_valid)  # the thesis default
    for rule in ("fused_max", "fused_weighted"):
        np.testing.assert_array_equal(refused[rule][hole], inp.x[..., 1][hole])
        np.testing.assert_array_equal(refused[rule][~hole], kept[rule][~hole])
    np.testing.assert_array_equal(kept["fused_max"], inp.x[..., 0])
    with pytest.raises(TrainerInputError, match="--stereo-holes"):
        fuse_scene(model, cfg, inp.x, dev, None, inp.stereo_valid, stereo_holes="both")


def test_lidar_resample_adds_scenes_with_a_redrawn_lidar_and_the_same_stereo(fusion_shards, tmp_path, capsys):
    plain = load_shard_scenes(fusion_shards, "lidar", progress=False)
    more = load_shard_scenes(fusion_shards, "lidar", progress=False, lidar_resample=2, seed=0)
    assert len(more) == 3 * len(plain)
    by_key = {s.key: s for s in more}
    for s in plain:
        for j in range(2):
            r = by_key[f"{s.key}~lidar{j}"]
            np.testing.assert_array_equal(r.x[..., 0], s.x[..., 0])  # stereo untouched
            np.testing.assert_array_equal(r.gt, s.gt)
            assert not np.array_equal(r.x[..., 1], s.x[..., 1])  # a new LiDAR ...
            assert not np.array_equal(r.x[..., 2], s.x[..., 2])  # ... and its own warped grey difference
            assert np.median(np.abs(r.x[..., 1] - s.gt)) < 1.0  # still a LiDAR of this scene
    again = load_shard_scenes(fusion_shards, "lidar", progress=False, lidar_resample=2, seed=0)
    assert all(np.array_equal(a.x, b.x) for a, b in zip(more, again))
    out = tmp_path / "run"
    assert cli_main(["fusion", "--data", str(fusion_shards), "--variant", "lidar", "--lidar-resample", "2",
                     "--crop", "16", "-b", "2", "--max-steps", "2", "--no-progress", "--out", str(out)]) == 0
    assert cli_main(["fusion", "--data", str(fusion_shards), "--lidar-resample", "2", "--max-steps", "1",
                     "--no-progress", "--out", str(tmp_path / "tof")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "--lidar-resample" in err[0] and not (tmp_path / "tof" / "last.pt").exists()


def test_occluders_add_composited_scenes_with_a_nearer_layer_and_exact_gt(fusion_shards, tmp_path, capsys):
    plain = load_shard_scenes(fusion_shards, "lidar", progress=False)
    more = load_shard_scenes(fusion_shards, "lidar", progress=False, occluders=1, seed=0)
    assert len(more) == 2 * len(plain)
    by_key = {s.key: s for s in more}
    gts = [s.gt for s in plain]
    for s in plain:
        o = by_key[f"{s.key}~occluder0"]
        behind = np.isclose(o.gt, s.gt)
        front = ~behind
        assert 0.05 < front.mean() < 0.5  # a blob of another scene in front ...
        assert o.gt[front].min() > s.gt.max() + 1.0  # ... at least 2 px nearer than the background's median
        assert any(np.allclose(o.gt[front] - o.gt[front][0], g[front] - g[front][0], atol=1e-4) for g in gts
                   if g is not s.gt)  # with another training scene's relief
        assert not np.array_equal(o.x[..., 0], s.x[..., 0])  # SGBM re-run on the composited pair
        valid = o.x[..., 1] > 0
        assert np.median(np.abs(o.x[..., 1] - o.gt)[valid]) < 1.0  # a LiDAR of the composited scene
    again = load_shard_scenes(fusion_shards, "lidar", progress=False, occluders=1, seed=0)
    assert all(a.key == b.key and np.array_equal(a.x, b.x) for a, b in zip(more, again))
    out = tmp_path / "run"
    assert cli_main(["fusion", "--data", str(fusion_shards), "--variant", "lidar", "--occluders", "1",
                     "--crop", "16", "-b", "2", "--max-steps", "2", "--no-progress", "--out", str(out)]) == 0
    assert cli_main(["fusion", "--data", str(fusion_shards), "--variant", "lidar", "--occluders", "2", "--max-steps", "3",
                     "--resume", str(out / "last.pt"), "--no-progress", "--out", str(out)]) == 1
    assert cli_main(["fusion", "--data", str(fusion_shards), "--occluders", "1", "--max-steps", "1",
                     "--no-progress", "--out", str(tmp_path / "tof")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and "occluders differ" in err[0] and "--occluders" in err[1]
    assert not (tmp_path / "tof").exists()
