"""Both CLIs refuse an output they cannot create with one line that names the path, never a traceback.

`crackgen generate` checks its --out itself (tests/tools/test_cli.py); the other commands rely on the CLIs'
last-resort handler for an OSError about a path, tested here on one command of each.
"""
from __future__ import annotations

from pathlib import Path

import pytest
from real_folders import write_real_folder

from crackgen.errors import path_error_line
from crackgen.tools.cli import main as crackgen_main
from trainer.cli import main as cracktrain_main


@pytest.fixture
def dangling(tmp_path: Path) -> Path:
    link = tmp_path / "data"
    link.symlink_to(tmp_path / "gone")
    return link


def _one_line(err: str) -> str:
    lines = err.strip().splitlines()
    assert len(lines) == 1, lines
    return lines[0]


def test_cracktrain_split_under_a_dangling_link(tmp_path, dangling, capsys):
    real = write_real_folder(tmp_path / "real", n=10)
    assert cracktrain_main(["split", str(real), "--out", str(dangling / "split")]) == 1
    line = _one_line(capsys.readouterr().err)
    assert line.startswith("cracktrain split: error: ") and str(dangling) in line and "missing target" in line
    assert not (tmp_path / "gone").exists()


def test_cracktrain_split_under_a_file(tmp_path, capsys):
    real = write_real_folder(tmp_path / "real", n=10)
    blocker = tmp_path / "afile"
    blocker.write_text("mine")
    assert cracktrain_main(["split", str(real), "--out", str(blocker / "split")]) == 1
    line = _one_line(capsys.readouterr().err)
    assert str(blocker) in line and "Not a directory" in line
    assert blocker.read_text() == "mine"


def test_crackgen_export_under_a_dangling_link(tmp_path, dangling, capsys):
    from synthetic_shards import write_shards

    shards = write_shards(tmp_path / "shards")
    assert crackgen_main(["export", str(shards), "--to", str(dangling / "export"), "--no-progress"]) == 1
    line = _one_line(capsys.readouterr().err)
    assert str(dangling) in line and "missing target" in line


def test_a_path_error_line_names_the_path_and_why():
    assert path_error_line(FileNotFoundError(2, "No such file or directory", "/nowhere/x")) == \
        "/nowhere/x: No such file or directory"
