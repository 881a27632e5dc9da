"""Self-training on unlabeled site photos: ignore-aware losses, the ignore channel, CBST thresholds, folders."""
import json

import cv2
import numpy as np
import pytest
import torch
from real_folders import train_tiny_model, write_real_folder
from synthetic_shards import write_shards

from trainer.adapt.pseudo_label import RECORD, PseudoSettings, class_thresholds, label_maps, write_pseudo_folder
from trainer.cli import main
from trainer.core.checkpoint import load_checkpoint
from trainer.core.errors import TrainerInputError
from trainer.seg.augment import SampleConfig, sample_generator, sample_to_tensors
from trainer.seg.losses import LOSSES, make_loss
from trainer.seg.sources import RealFolder

CPU = torch.device("cpu")


@pytest.mark.parametrize("name", LOSSES)
def test_ignored_pixels_carry_no_loss_and_no_gradient(name):
    torch.manual_seed(0)
    logits = torch.randn(2, 1, 8, 8, requires_grad=True)
    target = (torch.rand(2, 1, 8, 8) > 0.7).float()
    weight = torch.ones_like(target)
    weight[:, :, :, :4] = 0.0
    f = make_loss(name)
    loss = f(logits, target, weight)
    loss.backward()
    assert torch.all(logits.grad[:, :, :, :4] == 0) and logits.grad[:, :, :, 4:].abs().sum() > 0
    other = logits.detach().clone()
    other[:, :, :, :4] = 50.0 * torch.sign(torch.randn(2, 1, 8, 4))  # anything at ignored pixels
    assert torch.allclose(f(other, target, weight), loss.detach(), atol=1e-6)
    # all-ones weights give the unweighted loss
    assert torch.allclose(f(logits.detach(), target, torch.ones_like(target)), f(logits.detach(), target), atol=1e-6)


def test_weighted_bce_is_the_mean_over_kept_pixels():
    logits = torch.tensor([[[[0.0, 2.0], [-1.0, 5.0]]]])
    target = torch.tensor([[[[1.0, 0.0], [0.0, 1.0]]]])
    weight = torch.tensor([[[[1.0, 1.0], [0.0, 0.0]]]])
    want = (np.log(2.0) + np.log1p(np.exp(2.0))) / 2  # -log(sigmoid(0)), -log(1 - sigmoid(2))
    assert make_loss("bce")(logits, target, weight).item() == pytest.approx(want, rel=1e-6)


def test_ignore_channel_follows_the_geometry_of_the_mask():
    rng = np.random.default_rng(0)
    mask = np.zeros((64, 80), np.uint8)
    mask[20:30, 10:70] = 255
    sample = {"key": "k", "rgb": rng.integers(0, 255, (64, 80, 3), dtype=np.uint8), "mask": mask, "ignore": mask.copy()}
    cfg = SampleConfig(channels="rgb", crop=48, rotate_deg=30)
    for i in range(5):
        out = sample_to_tensors(sample, cfg, sample_generator(0, 0, i))
        assert torch.equal(out["ignore"], out["mask"])  # warped together, nearest
    plain = sample_to_tensors({**sample, "ignore": None}, cfg, sample_generator(0, 0, 1))
    assert plain["ignore"].sum() == 0
    assert torch.equal(plain["image"], sample_to_tensors(sample, cfg, sample_generator(0, 0, 1))["image"])


def test_real_folder_reads_ignore_masks_and_names_a_missing_one(tmp_path):
    root = write_real_folder(tmp_path / "real", n=3)
    stems = RealFolder(root).keys
    plain = RealFolder(root).load(stems[0])
    assert plain["ignore"] is None
    (root / "ignore").mkdir()
    h, w = plain["rgb"].shape[:2]
    ig = np.zeros((h, w), np.uint8)
    ig[:, : w // 2] = 255
    cv2.imwrite(str(root / "ignore" / f"{stems[0]}.png"), ig)
    got = RealFolder(root).load(stems[0])["ignore"]
    assert got.shape == (h, w) and (got[:, : w // 2] == 255).all() and (got[:, w // 2:] == 0).all()
    with pytest.raises(TrainerInputError, match=f"ignore.*{stems[1]}"):
        RealFolder(root).load(stems[1])
    assert RealFolder(root, ignore_dir=None).load(stems[1])["ignore"] is None


def test_class_thresholds_keep_the_most_confident_share_of_each_class():
    p = np.array([0.9, 0.8, 0.7, 0.6, 0.45, 0.3, 0.2, 0.1, 0.05, 0.0], np.float32).reshape(2, 5)
    t_crack, t_back = class_thresholds([p], 0.5)
    mask, ignore = label_maps(p, t_crack, t_back)
    crack, back = mask.ravel() > 0, (mask.ravel() == 0) & (ignore.ravel() == 0)
    assert crack.tolist() == [True, True] + [False] * 8  # top half of the 4 predicted cracks
    assert back.tolist() == [False] * 7 + [True] * 3  # the 3 surest of the 6 backgrounds (median of 6: 0.125)
    assert not (crack & (ignore.ravel() > 0)).any()
    m1, i1 = label_maps(p, *class_thresholds([p], 1.0))
    assert not i1.any() and (m1.ravel() > 0).sum() == 4  # portion 1: every pixel labelled as predicted
    m2, i2 = label_maps(p, *class_thresholds([p], 0.5, background_portion=1.0))
    assert (m2.ravel() > 0).sum() == 2 and i2.ravel().tolist() == [0, 0, 255, 255] + [0] * 6  # all backgrounds kept
    t_none, _ = class_thresholds([np.full((4, 4), 0.2, np.float32)], 0.5)
    assert t_none == float("inf")  # no predicted crack: no positive labels


@pytest.fixture(scope="module")
def teacher(tmp_path_factory):
    return train_tiny_model(tmp_path_factory.mktemp("pl"))


def _site(folder, n=4):
    folder.mkdir(parents=True)
    rng = np.random.default_rng(1)
    for i in range(n):
        img = np.clip(140 + 30 * rng.standard_normal((48, 64, 3)), 0, 255).astype(np.uint8)
        img[20:24, 5:60] = 20  # a dark line
        cv2.imwrite(str(folder / f"s{i}.png"), img)
    return sorted(folder.glob("*.png"))


def test_pseudo_folder_is_a_real_folder_whose_labels_partition_the_pixels(teacher, tmp_path):
    photos = _site(tmp_path / "site")
    settings = PseudoSettings(teacher=str(teacher["ckpt"]), portion=0.6, bn_batches=2, batch_size=2, crop=32)
    out = tmp_path / "labels"
    rec = write_pseudo_folder(photos, out, settings, CPU, progress=False)
    folder = RealFolder(out)
    assert sorted(folder.keys) == [p.stem for p in photos] and rec["photos"] == 4
    n_crack = n_ignore = n = 0
    for k in folder.keys:
        s = folder.load(k)
        assert s["ignore"] is not None and not ((s["mask"] > 0) & (s["ignore"] > 0)).any()
        n_crack += int((s["mask"] > 0).sum())
        n_ignore += int((s["ignore"] > 0).sum())
        n += s["mask"].size
    assert rec["crack_fraction"] == pytest.approx(n_crack / n) and rec["ignored_fraction"] == pytest.approx(n_ignore / n)
    assert json.loads((out / RECORD).read_text())["settings"]["portion"] == 0.6
    # the same settings again: the finished folder is kept; other settings: refused, nothing overwritten
    before = {p: p.read_bytes() for p in out.rglob("*.png")}
    assert write_pseudo_folder(photos, out, settings, CPU, progress=False) == rec
    with pytest.raises(TrainerInputError, match="already exists"):
        write_pseudo_folder(photos, out, PseudoSettings(teacher=str(teacher["ckpt"]), portion=0.3), CPU, progress=False)
    assert {p: p.read_bytes() for p in out.rglob("*.png")} == before


def test_cli_pseudo_label_then_train_on_it(teacher, tmp_path, capsys):
    _site(tmp_path / "site")
    out = tmp_path / "labels"
    assert main(["pseudo-label", "-c", str(teacher["ckpt"]), "--target", str(tmp_path / "site"), "--out", str(out),
                 "--batches", "2", "-b", "2", "-j", "0", "--no-progress"]) == 0
    said = capsys.readouterr().out
    assert "pseudo-labelled 4 photos" in said and str(out) in said
    run = tmp_path / "student"
    assert main(["seg", "--real", str(out), "--init", str(teacher["ckpt"]), "--arch", "unet", "-b", "2", "--crop",
                 "32", "-j", "0", "--no-progress", "--max-steps", "2", "--out", str(run)]) == 0
    assert load_checkpoint(run / "checkpoint.pt")["step"] == 2
    assert main(["pseudo-label", "-c", str(teacher["ckpt"]), "--target", str(tmp_path / "site"), "--out", str(out),
                 "--portion", "1.5"]) == 1
    err = capsys.readouterr().err.strip()
    assert "--portion" in err and len(err.splitlines()) == 1


def test_sim2real_pseudo_row_starts_from_the_synthetic_model(teacher, tmp_path):
    shards = write_shards(tmp_path / "shards", per_shard=4)
    out = tmp_path / "s2r"
    assert main(["sim2real", "--data", str(shards), "--real", str(teacher["real"]), "--test-fraction",
                 "0.25", "--target", "--max-steps", "2", "--self-train-steps", "3", "--runs", "synthetic+pseudo",
                 "--arch", "unet", "-b", "2", "--crop", "32", "-j", "0", "--no-progress", "--out", str(out)]) == 0
    table = json.loads((out / "sim2real.json").read_text())
    row = table["runs"]["synthetic+pseudo"]
    # the training photos only, never the validation or test ones
    assert row["pseudo_labels"]["photos"] == table["real_train_images"] == 4
    assert row["self_train_steps"] == 3 and row["steps"] == 5
    assert load_checkpoint(out / "synthetic+pseudo" / "student" / "checkpoint.pt")["step"] == 3
    assert (out / "synthetic" / "checkpoint.pt").is_file()
