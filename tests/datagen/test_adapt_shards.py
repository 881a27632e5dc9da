"""`crackgen adapt` on rendered shards: labels byte-identical, deterministic, resumable, same as [adapt]."""
from __future__ import annotations

import tarfile

import cv2
import numpy as np
import pytest
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.datagen.adapt_shards import AdaptShardsError, adapt_dataset, adapt_section
from crackgen.datagen.generate import GenerateOptions, generate
from crackgen.shards import Manifest, ShardWriter, iter_samples, sample_key
from crackgen.tools.bench_shards import synthetic_sample
from crackgen.tools.cli import main

MEMBERS = ("rgb.png", "right.png", "mask.png", "depth.exr", "tof.exr", "tofraw.exr", "json")


def _dataset(root, shards=2, per_shard=3):
    rng = np.random.default_rng(7)
    m = Manifest(root, recipe_text=tiny_recipe(11), recipe_hash="h" * 64, num_shards=shards, shard_size=per_shard)
    for s in range(shards):
        with ShardWriter(root, s) as w:
            for i in range(per_shard):
                smp = synthetic_sample(rng, 48, 16)
                smp["right.png"] = np.ascontiguousarray(smp["rgb.png"][:, ::-1])
                smp["json"] = {**smp["json"], "index": s * per_shard + i}
                w.add(sample_key(s, s * per_shard + i), {k: smp[k] for k in MEMBERS})
        m.mark_done(w.info)
    m.save()
    return root


def _photos(folder):
    folder.mkdir()
    rng = np.random.default_rng(1)
    for i in range(4):
        cv2.imwrite(str(folder / f"p{i}.png"), np.clip(rng.normal(60 + 30 * i, 25, (30, 40, 3)), 0, 255).astype(np.uint8))
    return folder


def _members(path):
    out = {}
    for p in sorted(path.glob("shard-*.tar")):
        with tarfile.open(p) as t:
            for ti in t.getmembers():
                out[ti.name] = t.extractfile(ti).read()
    return out


def test_labels_byte_identical_rgb_adapted_deterministic(tmp_path):
    src = _dataset(tmp_path / "src")
    photos = _photos(tmp_path / "photos")
    sec = adapt_section(str(photos), "fourier,reinhard,histogram", None, "0.01,0.05", 1.0)
    adapt_dataset(str(src), str(tmp_path / "a"), sec, progress=False)
    adapt_dataset(str(src), str(tmp_path / "b"), sec, progress=False)
    before, after, again = _members(src), _members(tmp_path / "a"), _members(tmp_path / "b")
    assert before.keys() == after.keys()
    assert after == again  # deterministic per seed: byte-identical shards
    for name in before:
        kind = name.split(".", 1)[1]
        if kind in ("rgb.png", "right.png"):
            assert before[name] != after[name], name
        elif kind != "json":
            assert before[name] == after[name], name  # mask, depth, ToF: the very same bytes
    methods = set()
    for s in iter_samples(str(tmp_path / "a")):
        a = s["meta"]["adapt"]
        assert a["applied"] and a["target"] in {f"p{i}.png" for i in range(4)} and a["views"] == ["rgb", "right"]
        methods.add(a["method"])
        # one transform for both views: the right view is the mirrored left, so it stays mirrored
        if a["method"] != "fourier":
            assert np.array_equal(s["right"], s["rgb"][:, ::-1])
    assert len(methods) >= 2
    m = Manifest.load(str(tmp_path / "a"))
    assert len(m.done()) == 2 and "crackgen adapt" in m.recipe_text


def test_bad_inputs_and_resume(tmp_path, capsys):
    src = _dataset(tmp_path / "src", shards=2)
    photos = _photos(tmp_path / "photos")
    out = tmp_path / "out"
    assert main(["adapt", str(src), "--target", str(tmp_path / "none"), "--out", str(out), "--no-progress"]) == 1
    assert "no such folder" in capsys.readouterr().err and not out.exists()
    assert main(["adapt", str(tmp_path / "photos"), "--target", str(photos), "--out", str(out)]) == 1
    assert "not a finished crackgen dataset" in capsys.readouterr().err
    assert main(["adapt", str(src), "--target", str(photos), "--out", str(out), "--method", "fda"]) == 1
    assert "adapt method" in capsys.readouterr().err
    with pytest.raises(AdaptShardsError, match="probability"):
        adapt_section(str(photos), "fourier", None, "0.01", 1.5)
    assert main(["adapt", str(src), "--target", str(photos), "--out", str(out), "--no-progress"]) == 0
    assert "6 samples (6 adapted) in 2 shards" in capsys.readouterr().out
    first = (out / "shard-000000.tar").read_bytes()
    assert main(["adapt", str(src), "--target", str(photos), "--out", str(out)]) == 1  # not empty, no --resume
    assert "--resume" in capsys.readouterr().err
    (out / "shard-000001.tar").write_bytes(b"broken")
    assert main(["adapt", str(src), "--target", str(photos), "--out", str(out), "--resume", "--no-progress"]) == 0
    assert "3 samples (3 adapted) in 1 shards (1 already done)" in capsys.readouterr().out
    assert (out / "shard-000000.tar").read_bytes() == first
    assert main(["adapt", str(src), "--target", str(photos), "--out", str(out), "--resume", "--probability", "0.5",
                 "--no-progress"]) == 1  # other options: not the same dataset
    assert "cannot resume" in capsys.readouterr().err


@pytest.mark.blender
@pytest.mark.slow
def test_same_rgb_as_rendering_with_the_adapt_table(tmp_path):
    photos = _photos(tmp_path / "photos")
    base = tiny_recipe(21, samples=2, shard_size=2, width=64, height=48, lidar=False)
    table = f'[adapt]\ntarget = "{photos}"\nmethod = {{choices = ["fourier", "reinhard"]}}\nband = {{min = 0.01, max = 0.05}}\n'
    generate(parse_recipe(base), GenerateOptions(out=str(tmp_path / "plain"), progress=False))
    generate(parse_recipe(base + table), GenerateOptions(out=str(tmp_path / "baked"), progress=False))
    sec = adapt_section(str(photos), "fourier,reinhard", None, "0.01,0.05", 1.0)
    adapt_dataset(str(tmp_path / "plain"), str(tmp_path / "later"), sec, progress=False)
    baked = {s["__key__"]: s for s in iter_samples(str(tmp_path / "baked"))}
    later = {s["__key__"]: s for s in iter_samples(str(tmp_path / "later"))}
    assert baked.keys() == later.keys() and len(baked) == 2
    for k in baked:
        assert np.array_equal(baked[k]["rgb"], later[k]["rgb"]), k
        assert np.array_equal(baked[k]["mask"], later[k]["mask"]), k
        for f in ("method", "target", "band"):
            assert baked[k]["meta"]["adapt"].get(f) == later[k]["meta"]["adapt"].get(f)
