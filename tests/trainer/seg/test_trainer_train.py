"""Tiny end-to-end runs: training on shards + a real folder, exact resume, CLI commands."""
import csv
import json
from pathlib import Path

import numpy as np
import pytest
from real_folders import write_real_folder
from synthetic_shards import write_shards

from trainer.cli import main


@pytest.fixture(scope="module")
def data(tmp_path_factory):
    base = tmp_path_factory.mktemp("trainer")
    return {"real": write_real_folder(base / "real"), "shards": write_shards(base / "shards"), "base": base}


def _losses(run: Path) -> dict[int, float]:
    with open(run / "log.csv") as f:
        return {int(r["step"]): float(r["value"]) for r in csv.DictReader(f) if r["name"] == "loss"}


def _seg(data, out, steps, *extra):
    return main(["seg", "--data", str(data["shards"]), "--real", str(data["real"]), "--arch", "unet",
                 "--batch-size", "2", "--crop", "32", "--workers", "2", "--lr", "3e-3", "--max-steps", str(steps),
                 "--out", str(out), "--no-progress", *extra])


def test_train_mixed_loss_decreases_and_resume_is_exact(data):
    a, b = data["base"] / "a", data["base"] / "b"
    assert _seg(data, a, 8) == 0
    la = _losses(a)
    assert sorted(la) == list(range(1, 9))
    assert np.mean([la[7], la[8]]) < np.mean([la[1], la[2]])
    assert _seg(data, b, 3) == 0
    assert _seg(data, b, 8, "--resume", str(b / "checkpoint.pt")) == 0
    lb = _losses(b)
    assert sorted(lb) == list(range(1, 9))
    for step in range(1, 9):  # same batches, same augmentation, same weights -> identical losses
        assert lb[step] == la[step], step


def test_rgbd_train_evaluate_predict(data, tmp_path):
    run = tmp_path / "run"
    rc = main(["seg", "--data", str(data["shards"]), "--depth", "tof", "--valid-channel", "--arch", "unet",
               "--batch-size", "2", "--crop", "32", "--workers", "0", "--max-steps", "2", "--val-fraction", "0.3",
               "--out", str(run), "--no-progress"])
    assert rc == 0
    ck = run / "checkpoint.pt"
    assert ck.is_file() and (run / "best.pt").is_file() and (run / "metrics_val.json").is_file()
    assert main(["evaluate", "-c", str(ck), "--data", str(data["shards"]), "--out", str(tmp_path / "ev"),
                 "--workers", "0", "--no-progress"]) == 0
    m = json.loads((tmp_path / "ev/metrics.json").read_text())
    a = m["at_threshold"]
    assert a["tp"] + a["fp"] + a["tn"] + a["fn"] == 8 * 48 * 48
    assert len(m["pr_curve"]["f1"]) == 101 and (tmp_path / "ev/pr_curve.png").is_file()
    rgb_run = tmp_path / "rgb"
    assert main(["seg", "--real", str(data["real"]), "--arch", "unet", "--batch-size", "2", "--crop", "32",
                 "--workers", "0", "--max-steps", "2", "--out", str(rgb_run), "--no-progress"]) == 0
    assert main(["predict", str(data["real"]), "-c", str(rgb_run / "checkpoint.pt"), "--out", str(tmp_path / "pred"),
                 "--threshold", "0.0", "--no-progress"]) == 0
    rep = json.loads((tmp_path / "pred/000.json").read_text())
    assert rep["crack_pixels"] == 48 * 64 and rep["length_unit"] == "px" and rep["crack_length"] > 0
    assert (tmp_path / "pred/000_overlay.png").is_file()


def test_cli_bad_inputs_exit_nonzero(tmp_path, capsys):
    assert main(["seg", "--real", str(tmp_path / "missing")]) == 1
    assert "missing" in capsys.readouterr().err
    bad = tmp_path / "bad.pt"
    bad.write_bytes(b"garbage")
    assert main(["evaluate", "-c", str(bad), "--real", str(tmp_path)]) == 1
    assert "bad.pt" in capsys.readouterr().err
    (tmp_path / "images").mkdir()
    assert main(["split", str(tmp_path), "--out", str(tmp_path / "s")]) == 1
    assert "no images" in capsys.readouterr().err
