"""Codec round trips are exact, channel order is what other readers expect, bad bytes name the member."""
from __future__ import annotations

import io
import json

import cv2
import numpy as np
import OpenEXR
import pytest
from PIL import Image

from crackgen.shards.codecs import (
    CodecError,
    decode_exr,
    decode_member,
    decode_png,
    encode_exr,
    encode_member,
    encode_png,
    wds_decoder,
)


@pytest.fixture
def rng() -> np.random.Generator:
    return np.random.default_rng(1234)


def bits(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32).view(np.uint32)


def test_png_rgb_roundtrip_exact_and_rgb_order(rng):
    rgb = rng.integers(0, 256, (17, 23, 3), dtype=np.uint8)
    rgb[0, 0] = (255, 0, 0)  # pure red pixel
    data = encode_member("rgb.png", rgb)
    back = decode_member("rgb.png", data)
    assert back.dtype == np.uint8 and back.shape == rgb.shape
    np.testing.assert_array_equal(back, rgb)
    # an independent reader (PIL) sees the same RGB: the BGR swap is handled inside the codec
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(data)).convert("RGB")), rgb)
    assert tuple(cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)[0, 0]) == (0, 0, 255)


def test_png_mask_uint16_and_rgba_roundtrip(rng):
    mask = np.where(rng.random((9, 11)) < 0.3, 255, 0).astype(np.uint8)
    np.testing.assert_array_equal(decode_png(encode_png(mask)), mask)
    assert decode_png(encode_png(mask)).ndim == 2
    g16 = rng.integers(0, 65536, (8, 6), dtype=np.uint16)
    back = decode_png(encode_png(g16))
    assert back.dtype == np.uint16
    np.testing.assert_array_equal(back, g16)
    rgb16 = rng.integers(0, 65536, (5, 7, 3), dtype=np.uint16)
    np.testing.assert_array_equal(decode_png(encode_png(rgb16)), rgb16)
    rgba = rng.integers(0, 256, (5, 7, 4), dtype=np.uint8)
    np.testing.assert_array_equal(decode_png(encode_png(rgba)), rgba)
    np.testing.assert_array_equal(np.asarray(Image.open(io.BytesIO(encode_png(rgba))).convert("RGBA")), rgba)


def test_exr_single_channel_bit_exact(rng):
    z = rng.normal(0.5, 0.2, (13, 19)).astype(np.float32)
    z[0, :5] = [-1.0, 0.0, -0.0, np.finfo(np.float32).tiny / 4, np.finfo(np.float32).max]
    z[1, 0], z[1, 1] = np.inf, np.nan
    for comp in ("zip", "none"):
        back = decode_member("depth.exr", encode_exr(z, compression=comp))
        assert isinstance(back, np.ndarray) and back.dtype == np.float32 and back.shape == z.shape
        np.testing.assert_array_equal(bits(back), bits(z))  # NaN payloads and -0.0 included
    assert (back == -1).sum() == 1


def test_exr_multichannel_dict_and_header(rng):
    zz = rng.random((6, 8)).astype(np.float32)
    aa = (rng.random((6, 8)) * 100).astype(np.float32)
    data = encode_member("tofraw.exr", {"Z": zz, "A": aa})
    back = decode_member("tofraw.exr", data)
    assert set(back) == {"Z", "A"}
    np.testing.assert_array_equal(bits(back["Z"]), bits(zz))
    np.testing.assert_array_equal(bits(back["A"]), bits(aa))
    f = OpenEXR.File(io.BytesIO(data), separate_channels=True)
    assert f.header()["compression"] == OpenEXR.ZIP_COMPRESSION
    assert f.channels()["Z"].pixels.dtype == np.float32  # stored as FLOAT, not HALF


def test_exr_narrows_float64_once_and_zip_compresses_smooth_maps():
    yy, xx = np.mgrid[0:64, 0:64]
    d64 = 0.5 + 0.001 * xx + 0.002 * yy
    back = decode_exr(encode_exr(d64))
    np.testing.assert_array_equal(back, d64.astype(np.float32))
    assert len(encode_exr(d64, compression="zip")) < 0.7 * len(encode_exr(d64, compression="none"))


def test_encodings_are_deterministic(rng):
    z = rng.random((10, 10)).astype(np.float32)
    assert encode_exr(z) == encode_exr(z.copy())
    rgb = rng.integers(0, 256, (10, 10, 3), dtype=np.uint8)
    assert encode_png(rgb) == encode_png(rgb.copy())
    assert encode_member("json", {"b": 1, "a": np.float32(0.5)}) == encode_member("json", {"a": 0.5, "b": 1})


def test_json_numpy_values_and_strictness():
    meta = {"K": np.eye(3), "n": np.int64(3), "x": np.float32(0.25), "names": ("a", "b")}
    back = decode_member("json", encode_member("json", meta))
    assert back == {"K": np.eye(3).tolist(), "n": 3, "x": 0.25, "names": ["a", "b"]}
    with pytest.raises(CodecError, match="000001-00002.json"):
        encode_member("json", {"bad": float("nan")}, name="000001-00002.json")
    with pytest.raises(CodecError, match="meta.json"):
        decode_member("meta.json", b"{not json")


@pytest.mark.parametrize("name", ["rgb.png", "depth.exr"])
def test_garbage_and_truncated_bytes_name_the_member(name, rng):
    with pytest.raises(CodecError, match=name.replace(".", r"\.")):
        decode_member(name, b"garbage bytes")
    good = encode_member(name, rng.integers(0, 256, (32, 32, 3), dtype=np.uint8) if name.endswith("png")
                         else rng.random((32, 32)).astype(np.float32))
    with pytest.raises(CodecError, match=name.replace(".", r"\.")):
        decode_member(name, good[: len(good) // 2])


def test_bad_values_are_refused():
    with pytest.raises(CodecError, match="rgb.png: PNG needs uint8"):
        encode_member("rgb.png", np.zeros((4, 4, 3), np.float32), name="rgb.png")
    with pytest.raises(CodecError, match="2-D"):
        encode_member("depth.exr", np.zeros((4, 4, 3), np.float32))
    with pytest.raises(CodecError, match="differ in shape"):
        encode_exr({"Z": np.zeros((4, 4)), "A": np.zeros((4, 5))})
    with pytest.raises(CodecError, match="no codec"):
        encode_member("x.npy", np.zeros(3))
    with pytest.raises(CodecError, match="compression"):
        encode_exr(np.zeros((2, 2)), compression="lzma")


def test_bytes_pass_through_checked():
    png = encode_png(np.zeros((3, 3), np.uint8))
    assert encode_member("mask.png", png) == png
    with pytest.raises(CodecError):
        encode_member("mask.png", b"not a png")
    assert encode_member("notes.txt", b"hello") == b"hello"
    assert decode_member("notes.txt", b"hello") == b"hello"


def test_wds_decoder_dispatch():
    z = np.full((3, 3), -1, np.float32)
    np.testing.assert_array_equal(wds_decoder("tof.exr", encode_exr(z)), z)
    assert wds_decoder("json", b'{"a": 1}') == {"a": 1}
    assert wds_decoder("txt", b"x") is None
    assert json.loads(encode_member("json", '{"a": 2}')) == {"a": 2}


def test_exr_roundtrip_property():
    """Any float32 map (NaN, inf, -1, denormals) survives the EXR codec bit for bit."""
    hyp = pytest.importorskip("hypothesis")
    from hypothesis import strategies as st
    from hypothesis.extra import numpy as hnp

    @hyp.settings(max_examples=30, deadline=None)
    @hyp.given(hnp.arrays(np.float32, hnp.array_shapes(min_dims=2, max_dims=2, max_side=24),
                          elements=st.floats(width=32, allow_nan=True)))
    def check(z):
        back = decode_member("depth.exr", encode_member("depth.exr", z))
        np.testing.assert_array_equal(bits(back), bits(z))

    check()
