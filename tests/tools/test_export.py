"""`crackgen export`: shard pixels come back exactly through the trainer's images/ + masks/ folder reader."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from synthetic_shards import write_shards

from crackgen.shards import iter_samples
from crackgen.tools.cli import main
from trainer.core.imageio import read_float_map
from trainer.seg.sources import RealFolder


@pytest.fixture(scope="module")
def dataset(tmp_path_factory) -> Path:
    return write_shards(tmp_path_factory.mktemp("export") / "shards", n_shards=2, per_shard=3)


@pytest.fixture(scope="module")
def truth(dataset) -> dict[str, dict]:
    return {s["__key__"]: s for s in iter_samples(dataset, members=["rgb", "mask", "depth", "tof"])}


def _export(dataset: Path, out: Path, *extra: str) -> int:
    return main(["export", str(dataset), "--to", str(out), "--no-progress", *extra])


def test_export_png16_reads_back_through_the_real_folder_loader(dataset, truth, tmp_path, capsys):
    out = tmp_path / "deepcrack"
    assert _export(dataset, out, "--members", "rgb,mask,depth,tof") == 0
    summary = capsys.readouterr().out.strip().splitlines()[-1]
    assert f"{len(truth)} samples" in summary and f"{4 * len(truth)} files" in summary and str(out) in summary
    folder = RealFolder(out, depth_dir="tof", depth_scale=0.001)
    assert sorted(folder.keys) == sorted(truth)
    for key, s in truth.items():
        got = folder.load(key)
        assert np.array_equal(got["rgb"], s["rgb"]) and np.array_equal(got["mask"], s["mask"])
        tof = s["tof"]
        assert (tof == -1).any() and (tof > 0).any()
        assert np.array_equal(got["depth"] == -1, tof == -1)  # holes stay holes through the loader
        for member in ("depth", "tof"):
            raw = cv2.imread(str(out / member / f"{key}.png"), cv2.IMREAD_UNCHANGED)
            assert raw.dtype == np.uint16 and raw.shape == s[member].shape
            valid = s[member] > 0
            assert np.all(raw[~valid] == 0) and np.all(raw[valid] > 0)
            assert np.abs(raw[valid] / 1000.0 - s[member][valid]).max() <= 0.001


def test_export_exr_keeps_float_metres_and_minus_one(dataset, truth, tmp_path):
    out = tmp_path / "exr"
    assert _export(dataset, out, "--members", "rgb,tof", "--depth-format", "exr") == 0
    assert sorted(p.name for p in out.iterdir()) == ["export.json", "images", "tof"]
    for key, s in truth.items():
        assert np.array_equal(read_float_map(out / "tof" / f"{key}.exr"), s["tof"])


@pytest.mark.parametrize("members, needle", [("rgb,crackmask", "crackmask"), ("rgb,lidar", "lidar"), (",", "--members")])
def test_bad_members_refused_and_nothing_written(dataset, tmp_path, capsys, members, needle):
    out = tmp_path / "out"
    assert _export(dataset, out, "--members", members) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and needle in err[0]
    assert not out.exists() and list(tmp_path.iterdir()) == []  # no partial export left behind


def test_missing_or_non_dataset_dir_refused(tmp_path, capsys):
    assert _export(tmp_path / "nope", tmp_path / "out") == 1
    assert "nope" in capsys.readouterr().err
    plain = tmp_path / "plain"
    plain.mkdir()
    (plain / "notes.txt").write_text("not shards")
    assert _export(plain, tmp_path / "out") == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and "not a dataset" in err[0]
    assert not (tmp_path / "out").exists()


def test_non_empty_target_refused_and_left_alone(dataset, tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    (out / "precious.txt").write_text("mine")
    assert _export(dataset, out) == 1
    assert "not empty" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["precious.txt"] and (out / "precious.txt").read_text() == "mine"
    empty = tmp_path / "empty"
    empty.mkdir()
    assert _export(dataset, empty) == 0 and sorted(p.name for p in empty.iterdir()) == ["export.json", "images", "masks"]
