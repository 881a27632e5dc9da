"""`cracktrain predict --skip-bad`: skipped inputs are counted apart from predictions and listed with reasons."""
import json
from pathlib import Path

import cv2
import numpy as np

from trainer.cli import main
from trainer.core.checkpoint import save_checkpoint
from trainer.seg.augment import SampleConfig
from trainer.seg.models import build_model


def _untrained_checkpoint(path: Path) -> Path:
    """A valid cracktrain checkpoint of an untrained RGB U-Net (predict only needs it to load and run)."""
    model = build_model("unet", 3)
    save_checkpoint(path, {"model": model.state_dict(), "args": {"arch": "unet", "depth": "none"},
                           "sample_config": SampleConfig(channels="rgb").__dict__})
    return path


def _folder_one_good_one_corrupt(root: Path) -> tuple[Path, Path]:
    (root / "images").mkdir(parents=True)
    good = root / "images" / "good.png"
    cv2.imwrite(str(good), np.full((32, 48, 3), 120, np.uint8))
    bad = root / "images" / "broken.jpg"
    bad.write_bytes(b"this is not a JPEG at all \x00\x01\x02" * 8)
    return good, bad


def test_predict_skip_bad_reports_predicted_and_skipped_separately(tmp_path, capsys):
    ckpt = _untrained_checkpoint(tmp_path / "untrained.pt")
    good, bad = _folder_one_good_one_corrupt(tmp_path / "photos")
    out = tmp_path / "pred"
    rc = main(["predict", str(tmp_path / "photos"), "-c", str(ckpt), "--out", str(out), "--skip-bad", "--no-progress"])
    assert rc == 0
    printed = capsys.readouterr().out.strip().splitlines()[-1]
    report = out / "report.json"
    assert printed.startswith("1 predicted, 1 skipped") and str(report) in printed
    rep = json.loads(report.read_text())
    assert [r["image"] for r in rep["predicted"]] == [str(good)]
    assert len(rep["skipped"]) == 1
    skipped = rep["skipped"][0]
    assert skipped["image"] == str(bad) and str(bad) in skipped["reason"] and "\n" not in skipped["reason"]
    assert (out / "good_mask.png").is_file() and not list(out.glob("broken*"))


def test_predict_without_skip_bad_stops_on_the_corrupt_file(tmp_path, capsys):
    ckpt = _untrained_checkpoint(tmp_path / "untrained.pt")
    _, bad = _folder_one_good_one_corrupt(tmp_path / "photos")
    rc = main(["predict", str(tmp_path / "photos"), "-c", str(ckpt), "--out", str(tmp_path / "pred"), "--no-progress"])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and str(bad) in err[0]


def test_predict_skip_bad_with_nothing_readable_fails_with_report(tmp_path, capsys):
    ckpt = _untrained_checkpoint(tmp_path / "untrained.pt")
    (tmp_path / "photos").mkdir()
    (tmp_path / "photos" / "broken.jpg").write_bytes(b"garbage")
    out = tmp_path / "pred"
    rc = main(["predict", str(tmp_path / "photos"), "-c", str(ckpt), "--out", str(out), "--skip-bad", "--no-progress"])
    assert rc == 1 and "report.json" in capsys.readouterr().err
    rep = json.loads((out / "report.json").read_text())
    assert rep["predicted"] == [] and len(rep["skipped"]) == 1


def test_predict_intrinsics_and_depth_give_metres(tmp_path, capsys):
    ckpt = _untrained_checkpoint(tmp_path / "untrained.pt")
    root = tmp_path / "site"
    (root / "images").mkdir(parents=True)
    (root / "depth").mkdir()
    cv2.imwrite(str(root / "images" / "a.png"), np.full((32, 48, 3), 120, np.uint8))
    cv2.imwrite(str(root / "depth" / "a.png"), np.full((32, 48), 1500, np.uint16))  # 1.5 m in mm
    K = tmp_path / "K.json"
    K.write_text(json.dumps({"fx": 600.0, "fy": 600.0, "cx": 23.5, "cy": 15.5}))
    out = tmp_path / "pred"
    rc = main(["predict", str(root), "-c", str(ckpt), "--out", str(out), "--threshold", "0.0", "--no-progress",
               "--intrinsics", str(K), "--real-depth-dir", "depth", "--real-depth-scale", "0.001"])
    assert rc == 0
    rep = json.loads((out / "a.json").read_text())
    # threshold 0: the whole 48 x 32 image is crack; a fronto-parallel plane at 1.5 m with f = 600 px
    # has 2.5 mm pixels: the longest path lies between the long side (47 px between pixel centres)
    # and the diagonal.
    assert rep["length_unit"] == "m"
    assert 0.0025 * 47 * 0.99 <= rep["crack_length"] <= 0.0025 * np.hypot(47, 31)
    assert rep["crack_length"] == rep["measurement"]["longest_path"]
    assert set(rep["measurement"]) >= {"longest_path", "total_length", "mean_width", "max_width"}
    # --intrinsics without depth: one line naming the image
    rc = main(["predict", str(root), "-c", str(ckpt), "--out", str(out), "--no-progress", "--intrinsics", str(K)])
    err = capsys.readouterr().err.strip().splitlines()
    assert rc == 1 and len(err) == 1 and "needs depth" in err[0]


def test_predict_on_shards_uses_each_samples_depth_and_k(tmp_path):
    from crackgen.shards import ShardWriter, sample_key

    ckpt = _untrained_checkpoint(tmp_path / "untrained.pt")
    K = [[600.0, 0, 23.5], [0, 600.0, 15.5], [0, 0, 1]]
    with ShardWriter(tmp_path / "ds", 0) as w:
        w.add(sample_key(0, 0), {"rgb.png": np.full((32, 48, 3), 90, np.uint8), "mask.png": np.zeros((32, 48), np.uint8),
                                 "depth.exr": np.full((32, 48), 1.5, np.float32), "json": {"cameras": {"rgb": {"K": K}}}})
    out = tmp_path / "pred"
    assert main(["predict", str(tmp_path / "ds"), "-c", str(ckpt), "--out", str(out), "--threshold", "0.0",
                 "--no-progress"]) == 0
    rep = json.loads((out / "000000-00000.json").read_text())
    assert rep["length_unit"] == "m" and 0.0025 * 47 * 0.99 <= rep["crack_length"] <= 0.0025 * np.hypot(47, 31)
