"""One CLI style across crackgen and cracktrain: the same exit code for bad input, old spellings kept
as hidden aliases that print one deprecation line, and the renamed commands."""
from __future__ import annotations

from pathlib import Path

import pytest

from crackgen.tools.cli import build_parser as crackgen_parser
from crackgen.tools.cli import main as crackgen_main
from trainer.cli import build_parser as cracktrain_parser
from trainer.cli import main as cracktrain_main

ROOT = Path(__file__).resolve().parents[2]


@pytest.mark.parametrize("argv, dest, value, old", [
    (["fusion", "--data", "d", "--steps", "7"], "steps", 7, "--steps"),
    (["fusion", "--data", "d", "--patch", "48"], "patch", 48, "--patch"),
    (["fuse", "--ckpt", "m.pt", "--stereo", "s", "--other", "o", "--left", "l", "--right", "r", "--out", "x"],
     "ckpt", "m.pt", "--ckpt"),
    (["fusion-eval", "--ckpt", "m.pt"], "ckpt", "m.pt", "--ckpt"),
    (["sim2real", "--synthetic", "shards", "--real", "r"], "synthetic", "shards", "--synthetic"),
])
def test_old_cracktrain_flags_still_parse_and_say_so(argv, dest, value, old, capsys):
    args = cracktrain_parser().parse_args(argv)
    assert getattr(args, dest) == value
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 1 and old in err[0] and "deprecated" in err[0]


def test_new_cracktrain_flags_are_silent(capsys):
    args = cracktrain_parser().parse_args(["fusion", "--data", "d", "--max-steps", "7", "--crop", "48"])
    assert (args.steps, args.patch) == (7, 48)
    args = cracktrain_parser().parse_args(["fusion-eval", "-c", "m.pt"])
    assert args.ckpt == "m.pt"
    assert capsys.readouterr().err == ""


@pytest.mark.parametrize("command", ["stats", "measure-check"])
def test_old_crackgen_json_flag_still_parses(command, capsys):
    args = crackgen_parser().parse_args([command, "data", "--json", "out.json"])
    assert args.json == "out.json" and "--json-out" in capsys.readouterr().err
    assert crackgen_parser().parse_args([command, "data", "--json-out", "o.json"]).json == "o.json"


def test_old_names_are_hidden_from_help(capsys):
    with pytest.raises(SystemExit):
        cracktrain_parser().parse_args(["--help"])
    top = capsys.readouterr().out
    assert "merge-stack" in top and "curve" in top and "fuse-images" not in top and "SUPPRESS" not in top
    with pytest.raises(SystemExit):
        cracktrain_parser().parse_args(["fuse", "--help"])
    fuse = capsys.readouterr().out
    assert "--checkpoint" in fuse and "--ckpt" not in fuse


def test_bad_input_exits_1_in_both_tools(tmp_path, capsys):
    assert crackgen_main(["validate", str(tmp_path / "missing.toml")]) == 1
    assert cracktrain_main(["split", str(tmp_path / "missing"), "--out", str(tmp_path / "s")]) == 1
    err = capsys.readouterr().err.strip().splitlines()
    assert len(err) == 2 and all("missing" in line for line in err)


def test_renamed_command_and_positional_checkpoint_still_work(tmp_path, capsys):
    # fuse-images -> merge-stack: the old name runs the same command after one deprecation line
    assert cracktrain_main(["fuse-images", str(tmp_path / "a.png"), str(tmp_path / "b.png"),
                            "--out", str(tmp_path / "f.png")]) == 1
    err = capsys.readouterr().err
    assert "fuse-images is deprecated" in err and "merge-stack" in err and "a.png" in err
    # adapt-bn CHECKPOINT (positional) -> adapt-bn --checkpoint CHECKPOINT
    rc = cracktrain_main(["adapt-bn", str(tmp_path / "m.pt"), "--target", str(tmp_path), "--out", str(tmp_path / "n.pt")])
    err = capsys.readouterr().err
    assert rc == 1 and "deprecated" in err and "no photos" in err
    rc = cracktrain_main(["adapt-bn", str(tmp_path / "m.pt"), "-c", str(tmp_path / "other.pt"), "--target",
                          str(tmp_path), "--out", str(tmp_path / "n.pt")])
    assert rc == 1 and "two checkpoints given" in capsys.readouterr().err
    assert cracktrain_main(["pseudo-label", "--target", str(tmp_path), "--out", str(tmp_path / "o")]) == 1
    assert "--checkpoint is required" in capsys.readouterr().err


def test_bench_component_runs_one_component_alone(tmp_path, capsys):
    assert crackgen_main(["bench", "--component", "shards", "--component-args", "--size 32 --samples 1"]) == 0
    assert '"bytes_per_sample"' in capsys.readouterr().out
    assert crackgen_main(["bench", str(ROOT / "recipes" / "demo.toml"), "--component", "core"]) == 1
    assert "not both" in capsys.readouterr().err
    assert crackgen_main(["bench"]) == 1
    assert crackgen_main(["bench", "--component", "core", "--component-args=--no-such-flag"]) == 1
