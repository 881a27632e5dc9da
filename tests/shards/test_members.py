"""The member registry agrees with the codecs, the writer's checks and the reader's output."""
from __future__ import annotations

import numpy as np
import pytest

from crackgen.shards import (
    MEMBERS,
    RGB_MEMBERS,
    RGB_VIEW_MEMBERS,
    Codec,
    ShardError,
    ShardWriter,
    iter_samples,
    member_for_file,
    member_for_name,
    sample_key,
)
from crackgen.shards.codecs import decode_member, encode_member

H, W = 10, 14


def value_for(kind, rng: np.random.Generator):
    """A valid value for a registered member, in the RGB view's size where it lives there."""
    h, w = (H, W) if kind.in_rgb_view else (6, 9)
    if kind.codec is Codec.PNG_RGB:
        return rng.integers(0, 256, (h, w, 3), dtype=np.uint8)
    if kind.codec is Codec.PNG_MASK:
        return np.where(rng.random((h, w)) < 0.2, 255, 0).astype(np.uint8)
    if kind.codec is Codec.EXR_FLOAT:
        return rng.uniform(-1, 2, (h, w)).astype(np.float32)
    if kind.codec is Codec.EXR_CHANNELS:
        return {ch: rng.random((h, w)).astype(np.float32) for ch in kind.channels}
    return {"seed": 7, "K": [[1.0, 0, 0], [0, 1.0, 0], [0, 0, 1]]}


def test_registry_names_are_keyable_and_filenames_resolve_back():
    assert list(MEMBERS) == ["rgb", "mask", "mask_thesis", "depth", "tof", "tofraw", "lidar", "right", "disp_sgm",
                             "disp_gt", "disp_tof", "tofamp", "disp_lidar", "crackmap", "json"]
    for name, kind in MEMBERS.items():
        assert kind.name == name and "." not in name
        assert member_for_file(kind.filename) is kind
        assert member_for_name(kind.filename) is kind and member_for_name(name) is kind
        assert kind.filename.endswith(kind.ext)
    assert member_for_file("mask.exr") is None  # a mask stored as EXR is not the registered mask
    assert member_for_file("extra.png") is None
    assert set(RGB_MEMBERS) == {"rgb", "right"} <= set(RGB_VIEW_MEMBERS)
    assert "tofraw" not in RGB_VIEW_MEMBERS and "crackmap" not in RGB_VIEW_MEMBERS
    assert MEMBERS["tofraw"].channels == ("Z", "A")


@pytest.mark.parametrize("name", list(MEMBERS))
def test_codec_of_each_member_gives_back_its_contract_type(name):
    kind = MEMBERS[name]
    value = value_for(kind, np.random.default_rng(3))
    got = decode_member(kind.filename, encode_member(kind.filename, value))
    if kind.codec is Codec.PNG_RGB:
        assert got.dtype == np.uint8 and got.shape == value.shape
    elif kind.codec is Codec.PNG_MASK:
        assert got.dtype == np.uint8 and got.ndim == 2 and set(np.unique(got)) <= {0, 255}
    elif kind.codec is Codec.EXR_FLOAT:
        assert got.dtype == np.float32 and got.shape == value.shape
    elif kind.codec is Codec.EXR_CHANNELS:
        assert set(got) == set(kind.channels)
    else:
        assert got == value
    np.testing.assert_equal(got, value)


def test_reader_yields_every_member_under_its_registered_key(tmp_path):
    rng = np.random.default_rng(0)
    sample = {k.filename: value_for(k, rng) for k in MEMBERS.values()}
    with ShardWriter(tmp_path, 0) as w:
        w.add(sample_key(0, 0), sample)
    (got,) = iter_samples(tmp_path / "shard-000000.tar")
    assert set(got) - {"__key__", "__shard__"} == {k.yielded_as for k in MEMBERS.values()}


@pytest.mark.parametrize("name", [n for n in RGB_VIEW_MEMBERS if n != "rgb"])
def test_every_rgb_view_member_must_match_the_rgb_size(tmp_path, name):
    rng = np.random.default_rng(1)
    kind = MEMBERS[name]
    small = value_for(kind, rng)
    small = small[:-2] if not isinstance(small, dict) else small
    with ShardWriter(tmp_path, 0) as w:
        with pytest.raises(ShardError, match="differ in size"):
            w.add(sample_key(0, 0), {"rgb.png": value_for(MEMBERS["rgb"], rng), kind.filename: small})


def test_members_outside_the_rgb_view_may_have_their_own_size(tmp_path):
    rng = np.random.default_rng(2)
    sample = {"rgb.png": value_for(MEMBERS["rgb"], rng),
              "tofraw.exr": {"Z": np.ones((3, 4), np.float32), "A": np.ones((3, 4), np.float32)},
              "crackmap.exr": np.zeros((5, 5), np.float32)}
    with ShardWriter(tmp_path, 0) as w:
        w.add(sample_key(0, 0), sample)
    assert w.info.samples == 1


def test_multichannel_member_needs_its_registered_channels(tmp_path):
    with ShardWriter(tmp_path, 0) as w:
        with pytest.raises(ShardError, match="tofraw.exr: must be a dict with channels 'Z' and 'A'"):
            w.add(sample_key(0, 0), {"tofraw.exr": {"Z": np.ones((3, 4), np.float32)}})
