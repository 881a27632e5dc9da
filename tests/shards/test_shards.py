"""Shard writer/reader/manifest: exact round trips, deterministic tars, all-or-nothing writes,
integrity checks that name the bad shard, and interop with tar, webdataset and fsspec/S3."""
from __future__ import annotations

import hashlib
import os
import shutil
import subprocess
import tarfile
import uuid

import numpy as np
import pytest

from crackgen.shards import (
    ShardError,
    ShardWriter,
    iter_samples,
    list_shards,
    load_sample,
    open_dataset,
    sample_key,
    split_shards,
    verify_dataset,
)
from crackgen.shards.manifest import Manifest, ManifestError, ShardInfo

H, W = 12, 16
ALL_MEMBERS = ["crackmap.exr", "depth.exr", "disp_gt.exr", "disp_sgm.exr", "json", "lidar.exr",
               "mask.png", "rgb.png", "right.png", "tof.exr", "tofraw.exr"]


def make_sample(rng: np.random.Generator, key: str) -> dict:
    """Tiny sample with every member; sparse maps use -1 for no value."""
    depth = rng.uniform(0.4, 0.6, (H, W)).astype(np.float32)
    sparse = np.where(rng.random((H, W)) < 0.2, depth, -1).astype(np.float32)
    return {
        "rgb.png": rng.integers(0, 256, (H, W, 3), dtype=np.uint8),
        "mask.png": np.where(rng.random((H, W)) < 0.1, 255, 0).astype(np.uint8),
        "depth.exr": depth,
        "tof.exr": sparse,
        "tofraw.exr": {"Z": rng.random((5, 7)).astype(np.float32), "A": rng.random((5, 7)).astype(np.float32)},
        "lidar.exr": np.where(rng.random((H, W)) < 0.05, depth, -1).astype(np.float32),
        "right.png": rng.integers(0, 256, (H, W, 3), dtype=np.uint8),
        "disp_sgm.exr": np.where(rng.random((H, W)) < 0.8, 30 / depth, -1).astype(np.float32),
        "disp_gt.exr": (30 / depth).astype(np.float32),
        "crackmap.exr": rng.normal(0, 1e-3, (8, 8)).astype(np.float32),
        "json": {"key": key, "K": [[500.0, 0, 8], [0, 500.0, 6], [0, 0, 1]], "crack_length_m": 0.123},
    }


def write_shard(root, index: int, n: int, seed: int = 0, **kw) -> tuple[ShardInfo, list[dict]]:
    rng = np.random.default_rng([seed, index])
    samples = [make_sample(rng, sample_key(index, i)) for i in range(n)]
    with ShardWriter(root, index, **kw) as w:
        for i, s in enumerate(samples):
            w.add(sample_key(index, i), s)
    return w.info, samples


def assert_sample_equal(got: dict, want: dict) -> None:
    for name, value in want.items():
        out = "meta" if name == "json" else name.rsplit(".", 1)[0]
        if isinstance(value, dict) and name != "json":
            assert set(got[out]) == set(value)
            for ch in value:
                np.testing.assert_array_equal(got[out][ch].view(np.uint32), value[ch].view(np.uint32))
        elif isinstance(value, np.ndarray):
            assert got[out].dtype == value.dtype, out
            if value.dtype == np.float32:
                np.testing.assert_array_equal(got[out].view(np.uint32), value.view(np.uint32))  # bit-exact
            else:
                np.testing.assert_array_equal(got[out], value)
        else:
            assert got[out] == value


def make_dataset(root, n_shards: int = 2, per: int = 3) -> tuple[Manifest, dict]:
    m = Manifest(root, recipe_text="[dataset]\nsamples = 6\n", recipe_hash="ab" * 32, num_shards=n_shards,
                 shard_size=per, versions={"bpy": "4.5.15"})
    truth = {}
    for i in range(n_shards):
        info, samples = write_shard(root, i, per)
        m.mark_done(info)
        truth.update({sample_key(i, j): s for j, s in enumerate(samples)})
    m.save()
    return m, truth


# ---------------------------------------------------------------- writer + reader

def test_roundtrip_every_member_exact(tmp_path):
    info, samples = write_shard(tmp_path, 7, 3)
    assert info.name == "shard-000007.tar" and info.index == 7 and info.samples == 3
    got = list(iter_samples(tmp_path / info.name))
    assert [g["__key__"] for g in got] == ["000007-00000", "000007-00001", "000007-00002"]
    for g, s in zip(got, samples):
        assert g["__shard__"].endswith("shard-000007.tar")
        assert_sample_equal(g, s)
        assert g["rgb"].shape == (H, W, 3) and set(np.unique(g["mask"])) <= {0, 255}
        assert (g["tof"] == -1).sum() == (s["tof.exr"] == -1).sum() > 0


def test_tar_is_plain_posix_and_grouped(tmp_path):
    info, _ = write_shard(tmp_path, 0, 2)
    path = tmp_path / info.name
    with tarfile.open(path) as t:
        members = t.getmembers()
    want = [f"{sample_key(0, i)}.{m}" for i in range(2) for m in ALL_MEMBERS]
    assert [m.name for m in members] == want
    for m in members:
        assert (m.mtime, m.uid, m.gid, m.uname, m.gname, m.mode) == (0, 0, 0, "", "", 0o644) and m.isreg()
    if shutil.which("tar"):
        out = subprocess.run(["tar", "tf", str(path)], capture_output=True, text=True, check=True).stdout
        assert out.split() == want
    assert info.bytes == path.stat().st_size
    assert info.sha256 == hashlib.sha256(path.read_bytes()).hexdigest()


def test_identical_content_gives_identical_bytes(tmp_path):
    a, _ = write_shard(tmp_path / "a", 3, 2, seed=5)
    b, _ = write_shard(tmp_path / "b", 3, 2, seed=5)
    c, _ = write_shard(tmp_path / "c", 3, 2, seed=6)
    assert (tmp_path / "a" / a.name).read_bytes() == (tmp_path / "b" / b.name).read_bytes()
    assert a == b and c.sha256 != a.sha256


def test_partial_never_visible_as_final(tmp_path):
    rng = np.random.default_rng(0)
    with pytest.raises(RuntimeError, match="render crashed"):
        with ShardWriter(tmp_path, 4) as w:
            w.add(sample_key(4, 0), make_sample(rng, "k"))
            names = os.listdir(tmp_path)
            assert "shard-000004.tar" not in names
            assert any(n.startswith("shard-000004.tar.") and n.endswith(".partial") for n in names)
            raise RuntimeError("render crashed")
    assert os.listdir(tmp_path) == []
    assert w.info is None
    assert list_shards(tmp_path) == []


def test_bad_sample_is_refused_whole_and_shard_stays_usable(tmp_path):
    rng = np.random.default_rng(1)
    with ShardWriter(tmp_path, 0) as w:
        bad = make_sample(rng, "x")
        bad["mask.png"][0, 0] = 7
        with pytest.raises(ShardError, match=r"000000-00000\.mask\.png: mask values must be 0 or 255"):
            w.add(sample_key(0, 0), bad)
        bad = make_sample(rng, "x")
        bad["depth.exr"] = np.zeros((H + 1, W), np.float32)
        with pytest.raises(ShardError, match="differ in size"):
            w.add(sample_key(0, 0), bad)
        bad = make_sample(rng, "x")
        bad["json"] = {"t": float("inf")}
        with pytest.raises(ShardError, match=r"shard-000000.tar: 000000-00000\.json"):
            w.add(sample_key(0, 0), bad)
        with pytest.raises(ShardError, match="bad sample key"):
            w.add("000000.00001", make_sample(rng, "x"))
        good = make_sample(rng, "ok")
        w.add(sample_key(0, 1), good)
        with pytest.raises(ShardError, match="added twice"):
            w.add(sample_key(0, 1), good)
    got = list(iter_samples(tmp_path))
    assert [g["__key__"] for g in got] == [sample_key(0, 1)]
    assert_sample_equal(got[0], good)


def test_members_and_keys_filters(tmp_path):
    _, samples = write_shard(tmp_path, 0, 3)
    got = list(iter_samples(tmp_path, members={"rgb", "mask.png", "json"}))
    assert [set(g) for g in got] == [{"__key__", "__shard__", "rgb", "mask", "meta"}] * 3
    got = list(iter_samples(tmp_path, keys={sample_key(0, 2)}, members=["depth"]))
    assert len(got) == 1 and got[0]["__key__"] == sample_key(0, 2)
    np.testing.assert_array_equal(got[0]["depth"], samples[2]["depth.exr"])
    s = load_sample(tmp_path, sample_key(0, 1))
    assert_sample_equal(s, samples[1])
    with pytest.raises(ShardError, match="no sample with key"):
        load_sample(tmp_path, "000009-00000")


# ---------------------------------------------------------------- manifest + datasets

def test_manifest_roundtrip_and_states(tmp_path):
    m, _ = make_dataset(tmp_path, 2, 2)
    m.mark_failed(2, [{"key": sample_key(2, 0), "error": "Cycles: out of memory"}])
    m.num_shards = 3
    m.save()
    back = Manifest.load(tmp_path)
    d0, d1 = m.to_dict(), back.to_dict()
    d0.pop("updated"), d1.pop("updated")
    assert d0 == d1
    assert back.versions["bpy"] == "4.5.15" and "numpy" in back.versions
    assert back.recipe_text.startswith("[dataset]") and back.generator_version
    assert back.pending() == [2] and back.num_samples == 4
    assert back.is_done(0) and back.is_done(1) and not back.is_done(2) and not back.is_done(3)
    assert back.shard(2).failures == [{"key": "000002-00000", "error": "Cycles: out of memory"}]
    with pytest.raises(ManifestError, match="not "):
        back.check_recipe("cd" * 32)
    back.check_recipe("ab" * 32)


def test_manifest_for_recipe_stores_recipe_text_and_plan(tmp_path):
    from crackgen.config.recipe import parse_recipe

    text = "[dataset]\nsamples = 10\nshard_size = 4\n"
    recipe = parse_recipe(text)
    m = Manifest.for_recipe(tmp_path, recipe, versions={"bpy": "4.5.15"})
    m.save()
    back = Manifest.load(tmp_path)
    assert back.recipe_text == text and back.recipe_hash == recipe.hash
    assert (back.num_shards, back.shard_size) == (3, 4) and back.pending() == [0, 1, 2]
    assert back.versions["bpy"] == "4.5.15"
    back.check_recipe(recipe.hash)
    assert [f"shard-00000{i}.tar: not recorded in the manifest" for i in range(3)] == verify_dataset(tmp_path)
    assert [n for n in os.listdir(tmp_path)] == ["manifest.json"]  # atomic save leaves no temp files


def test_manifest_errors_name_the_file(tmp_path):
    with pytest.raises(ManifestError, match="manifest.json: no manifest"):
        Manifest.load(tmp_path)
    (tmp_path / "manifest.json").write_text("{oops")
    with pytest.raises(ManifestError, match="manifest.json: not valid JSON"):
        Manifest.load(tmp_path)
    (tmp_path / "manifest.json").write_text('{"format": "crackgen-shards", "format_version": 1}')
    with pytest.raises(ManifestError, match="missing or bad field"):
        Manifest.load(tmp_path)
    with pytest.raises(ShardError, match="manifest.json"):
        list(iter_samples(tmp_path))


def test_is_done_detects_truncation_and_flipped_byte(tmp_path):
    m, _ = make_dataset(tmp_path, 2, 2)
    p = tmp_path / "shard-000001.tar"
    good = p.read_bytes()
    assert verify_dataset(tmp_path) == []

    p.write_bytes(good[:-2048])  # truncated
    assert not m.is_done(1, verify=False) and m.is_done(0)
    problems = verify_dataset(tmp_path)
    assert len(problems) == 1 and problems[0].startswith("shard-000001.tar: size")

    flipped = bytearray(good)
    flipped[700] ^= 0x01  # inside the first member's data, size unchanged
    p.write_bytes(bytes(flipped))
    assert m.is_done(1, verify=False) and not m.is_done(1, verify=True)
    problems = verify_dataset(tmp_path)
    assert len(problems) == 1 and problems[0].startswith("shard-000001.tar: sha256 mismatch")
    with pytest.raises(ShardError, match="shard-000001.tar: sha256 mismatch"):
        list(iter_samples(tmp_path, verify=True))

    p.unlink()
    assert verify_dataset(tmp_path) == [f"shard-000001.tar: missing ({p})"]


def test_reader_names_truncated_or_corrupt_shard_without_manifest(tmp_path):
    info, _ = write_shard(tmp_path, 0, 3)
    p = tmp_path / info.name
    good = p.read_bytes()
    with tarfile.open(p) as t:
        offsets = [(m.offset, m.offset_data, m.size) for m in t.getmembers()]
    cuts = {
        "mid-member": offsets[5][1] + offsets[5][2] // 2,
        "at a header boundary": offsets[12][0],
        "inside a header": offsets[12][0] + 100,
    }
    for what, cut in cuts.items():
        p.write_bytes(good[:cut])
        with pytest.raises(ShardError, match=r"shard-000000\.tar: truncated"):
            list(iter_samples(p))
        problems = verify_dataset(tmp_path)
        assert len(problems) == 1 and "shard-000000.tar: truncated" in problems[0], what
    # a damaged PNG (CRC fails) is reported as an unreadable member of that shard
    rgb = next(o for o, m in zip(offsets, [m for i in range(3) for m in ALL_MEMBERS]) if m == "rgb.png")
    bad = bytearray(good)
    bad[rgb[1] + 60] ^= 0xFF
    p.write_bytes(bytes(bad))
    with pytest.raises(ShardError, match=r"shard-000000\.tar: unreadable member 000000-00000\.rgb\.png"):
        list(iter_samples(p))
    assert "unreadable member" in verify_dataset(tmp_path)[0]


def test_dataset_dir_reads_done_shards_in_order(tmp_path):
    m, truth = make_dataset(tmp_path, 2, 3)
    write_shard(tmp_path, 2, 2)  # on disk but recorded as failed: readers skip it
    m.mark_failed(2, [("000002-00001", "boom")])
    m.num_shards = 3
    m.save()
    got = list(iter_samples(tmp_path))
    assert [g["__key__"] for g in got] == sorted(truth)
    for g in got:
        assert_sample_equal(g, truth[g["__key__"]])
    assert [os.path.basename(s) for s in list_shards(tmp_path)] == ["shard-000000.tar", "shard-000001.tar"]
    assert any("shard-000002.tar: marked failed" in p for p in verify_dataset(tmp_path))
    assert list(iter_samples(tmp_path, verify=True))[-1]["__key__"] == sample_key(1, 2)

    ds = open_dataset(tmp_path)
    assert ds.num_samples == 6 and len(list(ds)) == 6
    # without a manifest every shard-*.tar is read, in name order
    (tmp_path / "manifest.json").unlink()
    assert [g["__key__"][:6] for g in iter_samples(tmp_path)] == ["000000"] * 3 + ["000001"] * 3 + ["000002"] * 2
    with pytest.raises(ShardError, match="not found"):
        list(iter_samples(tmp_path / "nope"))


def test_split_shards_and_shard_indices(tmp_path):
    shards = [f"s{i}" for i in range(7)]
    parts = [split_shards(shards, r, 3) for r in range(3)]
    assert sorted(sum(parts, [])) == sorted(shards) and all(parts)
    assert not set(parts[0]) & set(parts[1])
    with pytest.raises(ValueError):
        split_shards(shards, 3, 3)
    make_dataset(tmp_path, 2, 2)
    assert [g["__key__"] for g in iter_samples(tmp_path, shard_indices=[1])] == [sample_key(1, 0), sample_key(1, 1)]
    ds = open_dataset(tmp_path)
    assert [g["__key__"] for g in ds.split(1, 2)] == [sample_key(1, 0), sample_key(1, 1)]
    assert ds.split(1, 2).num_samples == 2
    # a list of tars still finds the manifest beside them for verification
    assert len(list(iter_samples(list_shards(tmp_path), verify=True))) == 4


def test_webdataset_library_reads_our_shards(tmp_path):
    wds = pytest.importorskip("webdataset")
    from crackgen.shards.codecs import wds_decoder

    _, truth = make_dataset(tmp_path, 2, 2)
    urls = [str(p) for p in list_shards(tmp_path)]
    got = list(wds.WebDataset(urls, shardshuffle=False, empty_check=False).decode(wds_decoder))
    assert [g["__key__"] for g in got] == sorted(truth)
    for g in got:
        assert set(ALL_MEMBERS) <= set(g)
        want = truth[g["__key__"]]
        np.testing.assert_array_equal(g["rgb.png"], want["rgb.png"])
        np.testing.assert_array_equal(g["tof.exr"], want["tof.exr"])
        np.testing.assert_array_equal(g["tofraw.exr"]["A"], want["tofraw.exr"]["A"])
        assert g["json"] == want["json"]


# ---------------------------------------------------------------- fsspec targets

def test_memory_filesystem_target():
    fsspec = pytest.importorskip("fsspec")
    root = f"memory://crackgen-test-{uuid.uuid4().hex}"
    fs = fsspec.filesystem("memory")
    _, truth = make_dataset(root, 2, 2)
    assert sorted(p.rsplit("/", 1)[-1] for p in fs.ls(root.split("://")[1], detail=False)) == [
        "manifest.json", "shard-000000.tar", "shard-000001.tar"]
    got = list(iter_samples(root, verify=True))
    assert [g["__key__"] for g in got] == sorted(truth)
    for g in got:
        assert_sample_equal(g, truth[g["__key__"]])
    assert verify_dataset(root) == [] and Manifest.load(root).is_done(1)
    with pytest.raises(RuntimeError):
        with ShardWriter(root, 5) as w:
            w.add(sample_key(5, 0), make_sample(np.random.default_rng(0), "k"))
            raise RuntimeError("worker died")
    assert not fs.exists(root.split("://")[1] + "/shard-000005.tar")
    fs.rm(root.split("://")[1], recursive=True)


@pytest.fixture(scope="module")
def s3_server():
    try:
        import boto3  # noqa: F401
        import s3fs  # noqa: F401
        from moto.server import ThreadedMotoServer
    except ImportError as exc:
        pytest.skip(f"moto/s3fs not importable: {exc}")
    env = {"AWS_ACCESS_KEY_ID": "testing", "AWS_SECRET_ACCESS_KEY": "testing", "AWS_DEFAULT_REGION": "us-east-1"}
    old = {k: os.environ.get(k) for k in env}
    os.environ.update(env)
    server = ThreadedMotoServer(ip_address="127.0.0.1", port=0, verbose=False)
    server.start()
    host, port = server.get_host_and_port()
    yield f"http://{host}:{port}"
    server.stop()
    for k, v in old.items():
        if v is None:
            os.environ.pop(k, None)
        else:
            os.environ[k] = v


def test_s3_target_via_moto(s3_server, tmp_path):
    import s3fs

    so = {"key": "testing", "secret": "testing", "client_kwargs": {"endpoint_url": s3_server, "region_name": "us-east-1"},
          "skip_instance_cache": True}
    import boto3

    boto3.client("s3", endpoint_url=s3_server, region_name="us-east-1").create_bucket(Bucket="crackgen-bucket")
    s3 = s3fs.S3FileSystem(**so)
    root = "s3://crackgen-bucket/datasets/roads"
    m = Manifest(root, recipe_text="x", recipe_hash="ab" * 32, num_shards=2, shard_size=2, storage_options=so)
    truth = {}
    for i in range(2):
        info, samples = write_shard(root, i, 2, storage_options=so, tmp_dir=tmp_path)
        m.mark_done(info)
        truth.update({sample_key(i, j): s for j, s in enumerate(samples)})
    m.save()
    assert os.listdir(tmp_path) == []  # local temp files are cleaned after upload
    s3.invalidate_cache()
    assert s3.size("crackgen-bucket/datasets/roads/shard-000001.tar") == m.shard(1).bytes
    got = list(iter_samples(root, verify=True, storage_options=so))
    assert [g["__key__"] for g in got] == sorted(truth)
    for g in got:
        assert_sample_equal(g, truth[g["__key__"]])
    assert verify_dataset(root, storage_options=so) == []
    assert Manifest.load(root, storage_options=so).is_done(0)
