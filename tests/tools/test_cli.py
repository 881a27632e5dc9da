"""`crackgen` CLI contract: subcommands listed, bad input refused with one line, nothing written."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from crackgen.tools.cli import main

ROOT = Path(__file__).resolve().parents[2]


def test_help_lists_subcommands():
    exe = Path(sys.executable).with_name("crackgen")
    res = subprocess.run([str(exe), "--help"], capture_output=True, text=True, timeout=60)
    assert res.returncode == 0
    for cmd in ("generate", "validate", "inspect", "bench", "show", "verify"):
        assert cmd in res.stdout


@pytest.mark.parametrize("name", ["demo.toml", "roads.toml"])
def test_shipped_recipes_validate(name, capsys):
    assert main(["validate", str(ROOT / "recipes" / name)]) == 0
    assert "OK" in capsys.readouterr().out


def test_roads_recipe_is_thesis_scale():
    from crackgen.config.recipe import load_recipe

    r = load_recipe(ROOT / "recipes" / "roads.toml")
    assert r.dataset.samples == 10_000 and r.camera.width_px >= 512 and r.camera.height_px >= 512
    assert set(r.material.family.support()) == {"asphalt", "concrete"}


def test_generate_bad_recipe_exits_1_and_writes_nothing(tmp_path, capsys):
    bad = tmp_path / "bad.toml"
    bad.write_text("[camera]\nwidth_px = -3\n")
    out = tmp_path / "out"
    assert main(["generate", str(bad), "--out", str(out)]) == 1
    err = capsys.readouterr().err
    assert "camera.width_px" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()


def test_generate_refuses_non_empty_dir_without_resume(tmp_path, capsys):
    out = tmp_path / "out"
    out.mkdir()
    keep = out / "precious.txt"
    keep.write_text("mine")
    assert main(["generate", str(ROOT / "recipes" / "demo.toml"), "--out", str(out)]) == 1
    assert "--resume" in capsys.readouterr().err
    assert keep.read_text() == "mine" and sorted(p.name for p in out.iterdir()) == ["precious.txt"]


@pytest.mark.parametrize("parent", ["broken_link", "file"])
def test_generate_uncreatable_out_is_one_line(tmp_path, capsys, parent):
    """An --out under a dangling link or a file fails with one line naming it, not a traceback."""
    base = tmp_path / "data"
    if parent == "broken_link":
        base.symlink_to(tmp_path / "gone")
    else:
        base.write_text("not a folder")
    out = base / "closeup"
    assert main(["generate", str(ROOT / "recipes" / "demo.toml"), "--out", str(out)]) == 1
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and str(out) in err and "cannot create the output directory" in err
    assert not (tmp_path / "gone").exists()


def test_resume_refuses_foreign_dir_and_other_recipe(tmp_path, capsys):
    from crackgen.config.recipe import load_recipe
    from crackgen.shards.manifest import Manifest

    out = tmp_path / "foreign"
    out.mkdir()
    (out / "notes.txt").write_text("x")
    assert main(["generate", str(ROOT / "recipes" / "demo.toml"), "--out", str(out), "--resume"]) == 1
    assert "not a crackgen dataset" in capsys.readouterr().err

    other = tmp_path / "other"
    roads = load_recipe(ROOT / "recipes" / "roads.toml")
    Manifest.for_recipe(other, roads).save()
    before = (other / "manifest.json").read_bytes()
    assert main(["generate", str(ROOT / "recipes" / "demo.toml"), "--out", str(other), "--resume"]) == 1
    assert "recipe" in capsys.readouterr().err
    assert (other / "manifest.json").read_bytes() == before


def test_bad_storage_options_and_workers(tmp_path, capsys):
    demo = str(ROOT / "recipes" / "demo.toml")
    assert main(["generate", demo, "--out", str(tmp_path / "a"), "--storage-options", "{nope"]) == 1
    assert "--storage-options" in capsys.readouterr().err
    assert main(["generate", demo, "--out", str(tmp_path / "b"), "--workers", "0"]) == 1
    assert "--workers" in capsys.readouterr().err
    assert not (tmp_path / "a").exists() and not (tmp_path / "b").exists()


def test_inspect_and_show_missing_dir(tmp_path, capsys):
    assert main(["inspect", str(tmp_path / "nope")]) == 1
    assert "not found" in capsys.readouterr().err
    assert main(["show", str(tmp_path / "nope"), "000000-00000", "--pointcloud", str(tmp_path / "x.ply")]) == 1
    assert "not found" in capsys.readouterr().err


def test_validate_and_generate_take_set_overrides(tmp_path, capsys):
    demo = str(ROOT / "recipes" / "demo.toml")
    assert main(["validate", demo, "--set", "render.samples=3"]) == 0
    assert "OK" in capsys.readouterr().out
    out = tmp_path / "ds"
    assert main(["generate", demo, "--out", str(out), "--set", "render.sampels=3"]) == 1
    err = capsys.readouterr().err
    assert "render.sampels" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
