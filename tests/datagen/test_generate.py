"""`crackgen generate`: shards readable two ways, manifest, determinism, crashes and resume.

One tiny reference dataset (6 samples, 3 shards, 64x48 px, 2 spp) is made once with
one worker; every other run (again, two workers, killed and resumed, corrupted and
redone) is compared with it key by key (mask, depth, sensors, metadata), so "0 lost,
0 duplicated, identical content" is checked against an uninterrupted run, and then
shard by shard: same sha256 in both manifests and equal bytes on disk.
"""
from __future__ import annotations

import json
import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from run_watch import done_shards, wait_for
from tiny_recipes import tiny_recipe

from crackgen.config.recipe import parse_recipe
from crackgen.datagen.generate import GenerateError, GenerateOptions, effective_recipe, generate, plan_shards
from crackgen.datagen.pipeline import Sample
from crackgen.datagen.tasks import ShardTask, run_shard
from crackgen.shards import iter_samples, verify_dataset
from crackgen.shards.manifest import Manifest

pytestmark = [pytest.mark.blender, pytest.mark.slow]

TINY = tiny_recipe(11, name="tiny", samples=6, shard_size=2, spp=2, stereo=True)
COMPARE = ("mask", "depth", "tof", "tofraw", "lidar", "disp_gt", "crackmap", "rgb", "right", "disp_sgm")


def tiny_recipe_file(tmp: Path) -> Path:
    p = tmp / "tiny.toml"
    p.write_text(TINY)
    return p


def content(root) -> dict[str, dict]:
    """key -> comparable content (arrays + meta); fails on duplicate keys."""
    out = {}
    for s in iter_samples(str(root)):
        assert s["__key__"] not in out, f"duplicated sample {s['__key__']}"
        out[s["__key__"]] = {**{k: s[k] for k in COMPARE if k in s}, "meta": s["meta"], "rgb": s["rgb"]}
    return out


def assert_same(a: dict, b: dict) -> None:
    assert sorted(a) == sorted(b)
    for key in a:
        for name in COMPARE:
            x, y = a[key].get(name), b[key].get(name)
            if isinstance(x, dict):
                for ch in x:
                    np.testing.assert_array_equal(x[ch], y[ch], err_msg=f"{key}.{name}.{ch}")
            else:
                np.testing.assert_array_equal(x, y, err_msg=f"{key}.{name}")
        assert a[key]["meta"] == b[key]["meta"], key


def assert_same_bytes(a: Path, b: Path) -> None:
    """Every shard of dataset ``b`` is byte for byte the one of ``a``: same sha256 in both
    manifests, and equal bytes on disk (so the manifests are not just agreeing with themselves)."""
    ma, mb = Manifest.load(a), Manifest.load(b)
    assert [r.name for r in ma.done()] == [r.name for r in mb.done()] == [f"shard-{i:06d}.tar" for i in range(3)]
    for ra, rb in zip(ma.done(), mb.done()):
        assert ra.sha256 == rb.sha256, f"{ra.name}: sha256 differs between the two runs"
        assert (a / ra.name).read_bytes() == (b / rb.name).read_bytes(), ra.name
    assert sorted(p.name for p in a.glob("shard-*.tar")) == sorted(p.name for p in b.glob("shard-*.tar"))


@pytest.fixture(scope="module")
def tmp_mod(tmp_path_factory):
    return tmp_path_factory.mktemp("gen")


@pytest.fixture(scope="module")
def reference(tmp_mod):
    recipe_path = tiny_recipe_file(tmp_mod)
    out = tmp_mod / "ref"
    summary = generate(parse_recipe(TINY), GenerateOptions(out=str(out), workers=1, progress=False))
    assert summary.ok, summary.lines()
    return {"out": out, "recipe": recipe_path, "content": content(out), "summary": summary}


def cli(*args: str, **kw) -> subprocess.Popen:
    exe = Path(sys.executable).with_name("crackgen")
    return subprocess.Popen([str(exe), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            start_new_session=True, **kw)


# ---------------------------------------------------------------- planning (no rendering)

def test_plan_covers_every_sample_once():
    r = effective_recipe(parse_recipe(TINY), 7)
    plan = plan_shards(r)
    assert [len(t.samples) for t in plan] == [2, 2, 2, 1]
    assert sorted(i for t in plan for i in t.samples) == list(range(7))
    assert r.hash != parse_recipe(TINY).hash  # --samples is part of what the dataset is


# ---------------------------------------------------------------- a tiny dataset

def test_tiny_dataset_readable_and_manifest_complete(reference):
    out = reference["out"]
    c = reference["content"]
    assert sorted(c) == ["000000-00000", "000000-00001", "000001-00002", "000001-00003", "000002-00004", "000002-00005"]
    s = next(iter_samples(str(out)))
    assert s["rgb"].dtype == np.uint8 and s["rgb"].shape == (48, 64, 3)
    assert set(np.unique(s["mask"])) <= {0, 255}
    assert s["depth"].dtype == np.float32 and (s["depth"] > 0).all()
    assert set(s["tofraw"]) == {"Z", "A"} and s["tofraw"]["Z"].shape == (24, 32)
    for name in ("tof", "lidar", "disp_sgm", "disp_gt", "right", "crackmap"):
        assert name in s, name
    meta = s["meta"]
    assert {"rgb", "right", "tof", "lidar"} <= set(meta["cameras"])
    assert meta["spec"]["index"] == 0 and meta["crack"]["length_m"] > 0
    # timings vary run to run: they live in the manifest, per shard, never in a sample's JSON
    assert all("timings" not in c[k]["meta"] for k in c)
    # GT mask only where the surface is seen, and its crack fraction is what the meta says
    assert meta["crack"]["pixel_fraction"] == pytest.approx((s["mask"] > 0).mean())

    import webdataset as wds

    from crackgen.shards.codecs import wds_decoder

    urls = sorted(str(p) for p in out.glob("shard-*.tar"))
    ds = wds.WebDataset(urls, shardshuffle=False).decode(wds_decoder)
    wkeys = []
    for w in ds:
        wkeys.append(w["__key__"])
        np.testing.assert_array_equal(w["mask.png"], c[w["__key__"]]["mask"])
    assert sorted(wkeys) == sorted(c)

    m = Manifest.load(out)
    assert m.num_shards == 3 and len(m.done()) == 3 and m.num_samples == 6
    assert all(not r.failures for r in m.shards)
    for r in m.shards:
        assert {"render", "crackmap", "tof", "encode_write"} <= set(r.timings), r.timings
        assert all(v >= 0 for v in r.timings.values()) and r.timings["render"] > 0
    summary_t = reference["summary"].timings
    assert summary_t["render"] == pytest.approx(sum(r.timings["render"] for r in m.shards), abs=1e-5)
    assert m.recipe_text.strip() == TINY.strip() and m.recipe_hash == parse_recipe(TINY).hash
    assert verify_dataset(str(out)) == []
    assert reference["summary"].samples == 6 and reference["summary"].bytes == sum(r.bytes for r in m.shards)


def test_same_recipe_twice_gives_byte_identical_shards(reference, tmp_path):
    summary = generate(parse_recipe(TINY), GenerateOptions(out=str(tmp_path / "again"), workers=1, progress=False))
    assert summary.ok
    assert_same(content(tmp_path / "again"), reference["content"])
    assert_same_bytes(reference["out"], tmp_path / "again")


def test_two_workers_give_byte_identical_shards(reference, tmp_path):
    summary = generate(parse_recipe(TINY), GenerateOptions(out=str(tmp_path / "w2"), workers=2, progress=False))
    assert summary.ok
    assert_same(content(tmp_path / "w2"), reference["content"])
    assert_same_bytes(reference["out"], tmp_path / "w2")


def test_worker_replaced_after_each_shard_gives_byte_identical_shards(reference, tmp_path):
    """--worker-max-shards 1: every shard runs in a fresh process (3 shards, 3 processes on one worker
    slot), and a rebuilt scene renders exactly what the reused one did."""
    summary = generate(parse_recipe(TINY), GenerateOptions(out=str(tmp_path / "fresh"), workers=1, progress=False,
                                                           worker_max_shards=1))
    assert summary.ok and summary.worker_processes == 3
    assert reference["summary"].worker_processes == 1  # without it one process does every shard
    assert_same(content(tmp_path / "fresh"), reference["content"])
    assert_same_bytes(reference["out"], tmp_path / "fresh")
    with pytest.raises(GenerateError, match="--worker-max-shards"):
        generate(parse_recipe(TINY), GenerateOptions(out=str(tmp_path / "bad"), worker_max_shards=-1, progress=False))
    assert not (tmp_path / "bad").exists()


# ---------------------------------------------------------------- crashes and resume

def test_kill_one_worker_mid_shard_then_resume(reference, tmp_path):
    import psutil

    out = tmp_path / "killw"
    proc = cli("generate", str(reference["recipe"]), "--out", str(out), "--workers", "2", "--no-progress")
    driver = psutil.Process(proc.pid)

    def worker_mid_shard():
        # a shard is in progress when its .partial exists; workers are the spawn children
        if not list(out.glob("*.partial")):
            return None
        kids = [k for k in driver.children() if "spawn_main" in " ".join(k.cmdline())]
        return kids[0] if kids else None

    victim = wait_for(worker_mid_shard, 240, "a worker writing a shard")
    victim.send_signal(signal.SIGKILL)
    try:
        _, err = proc.communicate(timeout=120)  # must not hang
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        raise AssertionError("driver hung after a worker was killed")
    assert proc.returncode != 0
    assert "worker process died" in err, err[-2000:]
    assert not list(out.glob("*.partial")) or True  # partials are cleaned by --resume
    m = Manifest.load(out)
    assert len(m.done()) < 3
    summary = generate(parse_recipe(TINY), GenerateOptions(out=str(out), workers=2, resume=True, progress=False))
    assert summary.ok and summary.skipped_shards == len(m.done())
    assert not list(out.glob("*.partial"))
    assert_same(content(out), reference["content"])
    assert_same_bytes(reference["out"], out)


def test_kill_whole_run_then_resume(reference, tmp_path):
    out = tmp_path / "killall"
    proc = cli("generate", str(reference["recipe"]), "--out", str(out), "--workers", "1", "--no-progress")
    wait_for(lambda: done_shards(out) >= 1, 240, "the first finished shard")
    os.killpg(proc.pid, signal.SIGKILL)  # driver and workers at once
    proc.wait(timeout=30)
    m = Manifest.load(out)
    n_done = len(m.done())
    assert 1 <= n_done < 3
    p = cli("generate", str(reference["recipe"]), "--out", str(out), "--resume", "--no-progress")
    stdout, stderr = p.communicate(timeout=300)
    assert p.returncode == 0, stderr[-2000:]
    assert f"({n_done} already done)" in stdout
    assert_same(content(out), reference["content"])
    assert_same_bytes(reference["out"], out)
    # shards kept from the killed run keep their recorded timings; redone ones get new ones
    assert all(r.timings.get("render", 0) > 0 for r in Manifest.load(out).done())


def test_workers_exit_when_the_driver_is_killed_alone_then_resume(reference, tmp_path):
    """A driver killed on its own (SIGTERM from a scheduler) must not leave workers writing shards."""
    import psutil

    out = tmp_path / "killdriver"
    proc = cli("generate", str(reference["recipe"]), "--out", str(out), "--workers", "2", "--no-progress")
    driver = psutil.Process(proc.pid)
    kids = wait_for(lambda: [k for k in driver.children() if "spawn_main" in " ".join(k.cmdline())] if list(
        out.glob("*.partial")) else None, 240, "workers writing shards")
    proc.send_signal(signal.SIGTERM)  # the driver only, not its process group
    proc.wait(timeout=30)
    _, alive = psutil.wait_procs(kids, timeout=10)
    assert not alive, f"{len(alive)} worker(s) outlived the driver"
    before = sorted(p.name for p in out.iterdir())
    time.sleep(1.0)
    assert sorted(p.name for p in out.iterdir()) == before  # nothing writes into the dataset any more
    summary = generate(parse_recipe(TINY), GenerateOptions(out=str(out), workers=2, resume=True, progress=False))
    assert summary.ok and not list(out.glob("*.partial"))
    assert_same(content(out), reference["content"])
    assert_same_bytes(reference["out"], out)


def test_truncated_and_corrupted_shards_are_named_and_redone(reference, tmp_path):
    out = tmp_path / "bad"
    shutil.copytree(reference["out"], out)
    s1, s2 = out / "shard-000001.tar", out / "shard-000002.tar"
    with open(s1, "r+b") as f:
        f.truncate(s1.stat().st_size // 2)
    data = bytearray(s2.read_bytes())
    data[700] ^= 0xFF  # same size, different bytes
    s2.write_bytes(bytes(data))
    problems = verify_dataset(str(out))
    assert any("shard-000001.tar" in p and "truncated" in p for p in problems), problems
    assert any("shard-000002.tar" in p and "sha256" in p for p in problems), problems
    assert not any("shard-000000.tar" in p for p in problems)
    summary = generate(parse_recipe(TINY), GenerateOptions(out=str(out), workers=1, resume=True, progress=False))
    assert summary.ok and summary.shards == 2 and summary.skipped_shards == 1
    assert sorted(n.split(":")[0] for n in summary.redone) == ["shard-000001.tar", "shard-000002.tar"]
    assert verify_dataset(str(out)) == []
    assert_same(content(out), reference["content"])
    assert_same_bytes(reference["out"], out)


def test_resume_refuses_other_recipe(reference, tmp_path):
    from crackgen.datagen.generate import GenerateError

    out = tmp_path / "other"
    shutil.copytree(reference["out"], out)
    other = parse_recipe(TINY.replace("seed = 11", "seed = 12"))
    with pytest.raises(GenerateError, match="recipe"):
        generate(other, GenerateOptions(out=str(out), resume=True, progress=False))
    assert verify_dataset(str(out)) == []  # nothing touched


def test_resume_across_a_schema_that_gained_a_field(reference, tmp_path):
    """A dataset begun by a crackgen without ``stereo.sgbm_input``: other hash, same recipe -> resumes."""
    from crackgen.datagen.generate import GenerateError

    out = tmp_path / "older"
    shutil.copytree(reference["out"], out)
    manifest = json.loads((out / "manifest.json").read_text())
    assert manifest["recipe_canonical"]["stereo"]["sgbm_input"] == "clean"
    del manifest["recipe_canonical"]["stereo"]["sgbm_input"]
    manifest["recipe_hash"] = "0" * 64  # the older schema hashed to something else
    (out / "manifest.json").write_text(json.dumps(manifest))
    said = []
    summary = generate(parse_recipe(TINY), GenerateOptions(out=str(out), resume=True, progress=False), log=said.append)
    assert summary.ok and summary.shards == 0 and summary.skipped_shards == 3
    assert any("new fields at their defaults: stereo.sgbm_input" in s for s in said), said
    other = parse_recipe(TINY.replace("seed = 11", "seed = 12"))
    with pytest.raises(GenerateError, match=r"dataset.seed: 11 -> 12"):
        generate(other, GenerateOptions(out=str(out), resume=True, progress=False))
    assert verify_dataset(str(out)) == []


# ---------------------------------------------------------------- failure policy (no rendering)

class _Replay:
    """Producer that replays reference samples, failing some on purpose."""

    def __init__(self, ref: Path, always_fail: set[int], fail_once: set[int]):
        self.samples = {s["meta"]["index"]: s for s in iter_samples(str(ref))}
        self.always_fail, self.fail_once, self.calls = always_fail, set(fail_once), []

    def make(self, index: int) -> Sample:
        self.calls.append(index)
        if index in self.always_fail:
            raise RuntimeError(f"boom at {index}\nsecond line")
        if index in self.fail_once:
            self.fail_once.discard(index)
            raise OSError("transient")
        s = self.samples[index]
        members = {"rgb.png": s["rgb"], "mask.png": s["mask"], "depth.exr": s["depth"]}
        return Sample(index, members, dict(s["meta"]), timings={"render": 0.25 * (index + 1), "crackmap": 0.5})


def test_failed_sample_retried_once_then_recorded(reference, tmp_path):
    prod = _Replay(reference["out"], always_fail={2}, fail_once={3})
    res = run_shard(prod, str(tmp_path), ShardTask(1, (2, 3)))
    assert prod.calls == [2, 2, 3, 3]  # each failing sample gets exactly one retry
    assert res.info is not None and res.info["samples"] == 1
    assert res.failures == [{"key": "000001-00002", "error": "RuntimeError: boom at 2"}]
    keys = [s["__key__"] for s in iter_samples(str(tmp_path / "shard-000001.tar"))]
    assert keys == ["000001-00003"]
    # only the written sample's timings count, and they stay out of its JSON
    assert res.timings["render"] == 1.0 and res.timings["crackmap"] == 0.5 and res.timings["encode_write"] > 0
    (written,) = iter_samples(str(tmp_path / "shard-000001.tar"))
    assert "timings" not in written["meta"]
