"""Target BN (AdaBN): BN statistics from unlabeled site photos; weights, sources and labels untouched."""
import hashlib
import json

import cv2
import numpy as np
import pytest
import torch
from real_folders import train_tiny_model
from synthetic_shards import write_shards

from trainer.adapt.adabn import adapt_checkpoint
from trainer.cli import main
from trainer.core.checkpoint import load_checkpoint
from trainer.core.errors import TrainerInputError
from trainer.seg.augment import SampleConfig
from trainer.seg.models import build_model
from trainer.seg.scoring import load_model
from trainer.seg.target_bn import PhotoCrops, adapt_bn_to_photos, photo_crop_config

CPU = torch.device("cpu")


def _photos(folder, n, level, seed=0):
    """``n`` 40x56 noisy photos around grey ``level``."""
    folder.mkdir(parents=True)
    rng = np.random.default_rng(seed)
    for i in range(n):
        img = np.clip(level + 25 * rng.standard_normal((40, 56, 3)), 0, 255).astype(np.uint8)
        cv2.imwrite(str(folder / f"p{i:02d}.png"), img)
    return sorted(str(p) for p in folder.glob("*.png"))


def _first_bn_input(model, batch):
    return model.net.down[0][0](batch)  # UNet: conv -> BN is the first pair


def test_first_bn_statistics_are_those_of_the_photo_crops(tmp_path):
    photos = _photos(tmp_path / "site", 5, level=200)
    torch.manual_seed(0)
    model = build_model("unet", 3)
    weights = {k: v.clone() for k, v in model.state_dict().items() if "running" not in k and "num_batches" not in k}
    cfg = SampleConfig(channels="rgb")
    used = adapt_bn_to_photos(model, photos, cfg, CPU, crop=32, batches=3, batch_size=4, seed=1)
    assert used == 3 and not model.training
    crops = PhotoCrops(photos, photo_crop_config(cfg, 32), 12, seed=1)
    with torch.no_grad():
        feats = [_first_bn_input(model, torch.stack([crops[4 * b + i]["image"] for i in range(4)])) for b in range(3)]
    bn = model.net.down[0][1]
    want_mean = torch.stack([f.mean(dim=(0, 2, 3)) for f in feats]).mean(0)
    want_var = torch.stack([f.transpose(0, 1).reshape(f.shape[1], -1).var(dim=1) for f in feats]).mean(0)
    assert torch.allclose(bn.running_mean, want_mean, atol=1e-5)
    assert torch.allclose(bn.running_var, want_var, rtol=1e-4)
    assert all(torch.equal(v, model.state_dict()[k]) for k, v in weights.items())  # weights untouched


def test_statistics_follow_the_site_and_are_deterministic(tmp_path):
    bright = _photos(tmp_path / "bright", 4, level=210)
    dark = _photos(tmp_path / "dark", 4, level=50)
    cfg = SampleConfig(channels="rgb")

    def first_mean(photos, seed):
        torch.manual_seed(0)
        model = build_model("unet", 3)
        adapt_bn_to_photos(model, photos, cfg, CPU, crop=24, batches=2, batch_size=2, seed=seed)
        return model.net.down[0][1].running_mean.clone()

    assert torch.equal(first_mean(bright, 3), first_mean(bright, 3))
    assert not torch.equal(first_mean(bright, 3), first_mean(bright, 4))  # other crops
    # the first conv is linear in its input, so the two sites' channel means differ, not just their noise
    assert (first_mean(bright, 3) - first_mean(dark, 3)).abs().max() > 0.05


def test_crops_are_native_scale_and_flip_only():
    cfg = photo_crop_config(SampleConfig(channels="rgb", crop=192, jitter=0.3, rotate_deg=15), 64)
    assert (cfg.crop, cfg.scale_min, cfg.scale_max, cfg.rotate_deg, cfg.jitter) == (64, 1.0, 1.0, 0.0, 0.0)
    with pytest.raises(TrainerInputError, match="RGB model"):
        photo_crop_config(SampleConfig(channels="rgbd"), 64)


def test_photo_smaller_than_the_crop_is_one_line(tmp_path):
    photos = _photos(tmp_path / "small", 1, level=100)  # 56x40
    with pytest.raises(TrainerInputError, match="smaller than the 64-px crop"):
        PhotoCrops(photos, photo_crop_config(SampleConfig(channels="rgb"), 64), 2)[0]


@pytest.fixture(scope="module")
def trained(tmp_path_factory):
    return train_tiny_model(tmp_path_factory.mktemp("tbn"))


def test_adapt_checkpoint_writes_a_new_model_and_leaves_the_source(trained, tmp_path):
    src = trained["ckpt"]
    before = hashlib.sha256(src.read_bytes()).hexdigest()
    photos = _photos(tmp_path / "site", 4, level=180)
    rec = adapt_checkpoint(src, tmp_path / "adapted.pt", photos, CPU, target="site", batches=2, batch_size=2)
    assert hashlib.sha256(src.read_bytes()).hexdigest() == before
    assert rec["photos"] == 4 and rec["batches"] == 2 and rec["crop"] == 32
    a, b = load_checkpoint(src), load_checkpoint(tmp_path / "adapted.pt")
    assert b["target_bn"]["target"] == "site" and b["finished"]
    changed = [k for k in a["model"] if not torch.equal(a["model"][k], b["model"][k])]
    assert changed and all("running" in k or "num_batches" in k for k in changed)
    load_model(tmp_path / "adapted.pt", CPU)  # evaluate/predict read it
    with pytest.raises(TrainerInputError, match="is the source checkpoint"):
        adapt_checkpoint(src, src, photos, CPU, target="site")


def test_cli_adapt_bn_and_its_errors(trained, tmp_path, capsys):
    _photos(tmp_path / "site", 3, level=90)
    out = tmp_path / "a.pt"
    assert main(["adapt-bn", "-c", str(trained["ckpt"]), "--target", str(tmp_path / "site"), "--out", str(out),
                 "--batches", "2", "-b", "2", "-j", "0"]) == 0
    assert "from 3 photos" in capsys.readouterr().out and out.is_file()
    assert main(["adapt-bn", "-c", str(trained["ckpt"]), "--target", str(tmp_path / "nope"), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert "no such folder" in err and len(err.splitlines()) == 1


def test_seg_bn_target_runs_after_training_and_is_recorded(trained, tmp_path):
    _photos(tmp_path / "site", 3, level=220)
    run = tmp_path / "run"
    assert main(["seg", "--real", str(trained["real"]), "--arch", "unet", "-b", "2", "--crop", "32", "-j", "0",
                 "--no-progress", "--max-steps", "2", "--target", str(tmp_path / "site"), "--target-bn",
                 "--target-bn-batches", "2", "--out", str(run)]) == 0
    ckpt = load_checkpoint(run / "checkpoint.pt")
    assert ckpt["target_bn"]["photos"] == 3 and ckpt["target_bn"]["batches"] == 2
    plain = load_checkpoint(trained["ckpt"])  # the same training without --bn-target: same weights, other BN
    w = [k for k in plain["model"] if "running" not in k and "num_batches" not in k]
    assert all(torch.equal(plain["model"][k], ckpt["model"][k]) for k in w)
    assert not torch.equal(plain["model"]["net.down.0.1.running_mean"], ckpt["model"]["net.down.0.1.running_mean"])


def test_seg_bn_target_is_checked_before_training(trained, tmp_path, capsys):
    run = tmp_path / "run"
    assert main(["seg", "--real", str(trained["real"]), "--arch", "unet", "-b", "2", "--crop", "32", "-j", "0",
                 "--no-progress", "--max-steps", "2", "--bn-target", str(tmp_path / "nope"), "--out", str(run)]) == 1
    err = capsys.readouterr().err
    assert "no such folder" in err and "--bn-target is deprecated" in err  # the old spelling still works
    assert not (run / "checkpoint.pt").exists()


@pytest.mark.parametrize("flags, message", [
    (["--target", "photos"], "needs --target-appearance and/or --target-bn"),
    (["--target-bn"], "need --target FOLDER"),
    (["--target", "a", "--target-bn", "--bn-target", "b"], "two site photo folders"),
])
def test_seg_site_target_flags_must_fit_together(trained, tmp_path, capsys, flags, message):
    run = tmp_path / "run"
    assert main(["seg", "--real", str(trained["real"]), "--arch", "unet", "-b", "2", "--crop", "32", "-j", "0",
                 "--no-progress", "--max-steps", "1", *flags, "--out", str(run)]) == 1
    err = [line for line in capsys.readouterr().err.splitlines() if "deprecated" not in line]
    assert len(err) == 1 and message in err[0]
    assert not (run / "checkpoint.pt").exists()


def test_sim2real_bn_row_reuses_the_synthetic_weights(trained, tmp_path):
    shards = write_shards(tmp_path / "shards", per_shard=4)
    out = tmp_path / "s2r"
    assert main(["sim2real", "--data", str(shards), "--real", str(trained["real"]), "--test-fraction",
                 "0.25", "--target", "--max-steps", "2", "--runs", "synthetic,synthetic+bn", "--arch", "unet",
                 "-b", "2", "--crop", "32", "-j", "0", "--no-progress", "--out", str(out)]) == 0
    table = json.loads((out / "sim2real.json").read_text())
    # the training photos only, never the validation or test ones
    assert table["runs"]["synthetic+bn"]["target_bn"]["photos"] == table["real_train_images"] == 4
    syn = load_checkpoint(out / "synthetic" / "checkpoint.pt")["model"]
    bn = load_checkpoint(out / "synthetic+bn" / "checkpoint.pt")["model"]
    assert all(torch.equal(syn[k], bn[k]) for k in syn if "running" not in k and "num_batches" not in k)
