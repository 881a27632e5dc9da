"""Encode and decode the members of a shard sample (PNG, OpenEXR, JSON).

One place decides how an array becomes bytes, so the writer, our reader and
the ``webdataset`` decoder (``wds_decoder``) agree exactly. The codec is chosen by
the member's extension; which member uses which extension, and what its value must
be, is the registry's business (``crackgen.shards.members``):

- ``.png``: cv2, lossless. uint8/uint16, H×W (grey) or H×W×3 RGB / H×W×4 RGBA
  (cv2's BGR order is handled here and nowhere else).
- ``.exr``: OpenEXR 3.x, float32, ZIP compression by default. A 2-D array is one
  channel named ``Z``; a dict ``{name: H×W array}`` is a named multi-channel image
  (e.g. ``tofraw.exr`` with ``Z`` and ``A``). Decoding gives the 2-D float32 array
  back for a file whose only channel is ``Z``, else a dict name -> array.
- ``.json`` / ``json``: UTF-8, sorted keys, numpy values turned into lists/numbers,
  strict JSON (NaN/inf refused, so any reader can parse it).

Bad bytes or values raise ``CodecError`` naming the member; nothing leaks a bare
cv2/OpenEXR traceback.
"""
from __future__ import annotations

import io
import json
from typing import Any, Mapping

import cv2
import numpy as np
import OpenEXR

from crackgen.errors import CrackgenError
from crackgen.shards.members import CODEC_EXTS, SINGLE_CHANNEL, member_ext

EXR_COMPRESSION = {
    "none": OpenEXR.NO_COMPRESSION,
    "zip": OpenEXR.ZIP_COMPRESSION,
    "zips": OpenEXR.ZIPS_COMPRESSION,
    "piz": OpenEXR.PIZ_COMPRESSION,
    "rle": OpenEXR.RLE_COMPRESSION,
}
PNG_LEVEL = 3  # zlib level: 3 is ~2x faster than 9 and within a few % in size on renders


class CodecError(CrackgenError, ValueError):
    """A member value or member bytes that cannot be encoded/decoded."""


# ---------------------------------------------------------------- PNG

def encode_png(image: np.ndarray, name: str = "png", level: int = PNG_LEVEL) -> bytes:
    """Lossless PNG of a uint8/uint16 H×W, H×W×3 (RGB) or H×W×4 (RGBA) array."""
    a = np.asarray(image)
    if a.dtype not in (np.uint8, np.uint16):
        raise CodecError(f"{name}: PNG needs uint8 or uint16 pixels, got {a.dtype}")
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim == 3 and a.shape[2] == 3:
        a = cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGB2BGR)
    elif a.ndim == 3 and a.shape[2] == 4:
        a = cv2.cvtColor(np.ascontiguousarray(a), cv2.COLOR_RGBA2BGRA)
    elif a.ndim != 2:
        raise CodecError(f"{name}: PNG needs an H×W, H×W×3 or H×W×4 array, got shape {a.shape}")
    if a.size == 0:
        raise CodecError(f"{name}: empty image {a.shape}")
    ok, buf = cv2.imencode(".png", np.ascontiguousarray(a), [cv2.IMWRITE_PNG_COMPRESSION, level])
    if not ok:
        raise CodecError(f"{name}: cv2 could not encode the PNG")
    return buf.tobytes()


def decode_png(data: bytes, name: str = "png") -> np.ndarray:
    """PNG bytes -> array in RGB(A) order with the stored depth (uint8/uint16)."""
    if not data.startswith(b"\x89PNG\r\n\x1a\n"):
        raise CodecError(f"{name}: not a PNG (bad signature, {len(data)} bytes)")
    img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise CodecError(f"{name}: PNG data is corrupt or truncated ({len(data)} bytes)")
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2RGBA)
    return img


# ---------------------------------------------------------------- EXR

def _float_plane(a: Any, name: str, channel: str) -> np.ndarray:
    arr = np.asarray(a)
    if arr.ndim != 2:
        raise CodecError(f"{name}: EXR channel {channel!r} must be 2-D (H×W), got shape {arr.shape}")
    if arr.size == 0:
        raise CodecError(f"{name}: EXR channel {channel!r} is empty")
    if arr.dtype.kind not in "fiu" or arr.dtype == np.bool_:
        raise CodecError(f"{name}: EXR channel {channel!r} must be numeric, got {arr.dtype}")
    # EXR maps are float32 by contract; wider floats are narrowed here, once.
    return np.ascontiguousarray(arr, dtype=np.float32)


def encode_exr(value: np.ndarray | Mapping[str, np.ndarray], name: str = "exr",
               compression: str = "zip") -> bytes:
    """float32 OpenEXR: a 2-D array -> channel ``Z``; a dict -> named channels."""
    if compression not in EXR_COMPRESSION:
        raise CodecError(f"{name}: unknown EXR compression {compression!r}; use one of {sorted(EXR_COMPRESSION)}")
    if isinstance(value, Mapping):
        if not value:
            raise CodecError(f"{name}: EXR channel dict is empty")
        channels = {}
        for ch, plane in value.items():
            if not isinstance(ch, str) or not ch:
                raise CodecError(f"{name}: EXR channel names must be non-empty strings, got {ch!r}")
            channels[ch] = _float_plane(plane, name, ch)
        shapes = {c.shape for c in channels.values()}
        if len(shapes) != 1:
            raise CodecError(f"{name}: EXR channels differ in shape: { {k: v.shape for k, v in channels.items()} }")
    else:
        channels = {SINGLE_CHANNEL: _float_plane(value, name, SINGLE_CHANNEL)}
    header = {"compression": EXR_COMPRESSION[compression], "type": OpenEXR.scanlineimage}
    buf = io.BytesIO()
    try:
        OpenEXR.File(header, channels).write(buf)
    except Exception as exc:  # OpenEXR raises RuntimeError/TypeError with C++ text
        raise CodecError(f"{name}: OpenEXR could not write the image: {exc}") from None
    return buf.getvalue()


def decode_exr(data: bytes, name: str = "exr") -> np.ndarray | dict[str, np.ndarray]:
    """EXR bytes -> float32 H×W (sole channel ``Z``) or dict channel -> float32 H×W."""
    if not data.startswith(b"\x76\x2f\x31\x01"):
        raise CodecError(f"{name}: not an OpenEXR file (bad magic, {len(data)} bytes)")
    try:
        f = OpenEXR.File(io.BytesIO(data), separate_channels=True)
        chans = {k: c.pixels for k, c in f.channels().items()}
    except Exception as exc:
        raise CodecError(f"{name}: EXR data is corrupt or truncated ({len(data)} bytes): {exc}") from None
    out = {k: np.ascontiguousarray(v, dtype=np.float32) for k, v in chans.items()}
    if list(out) == [SINGLE_CHANNEL]:
        return out[SINGLE_CHANNEL]
    return out


# ---------------------------------------------------------------- JSON

def _json_default(obj: Any) -> Any:
    if isinstance(obj, np.ndarray):
        return obj.tolist()
    if isinstance(obj, np.generic):
        return obj.item()
    if isinstance(obj, (set, frozenset)):
        return sorted(obj)
    raise TypeError(f"{type(obj).__name__} is not JSON serialisable")


def encode_json(value: Any, name: str = "json") -> bytes:
    """Strict, key-sorted JSON so identical metadata gives identical bytes."""
    if isinstance(value, (bytes, bytearray)):
        value = bytes(value)
        decode_json(value, name)  # refuse bytes that would not read back
        return value
    if isinstance(value, str):
        decode_json(value.encode("utf-8"), name)
        return value.encode("utf-8")
    try:
        text = json.dumps(value, sort_keys=True, default=_json_default, allow_nan=False,
                          separators=(",", ":"))
    except (TypeError, ValueError) as exc:
        raise CodecError(f"{name}: cannot encode as JSON: {exc}") from None
    return text.encode("utf-8")


def decode_json(data: bytes, name: str = "json") -> Any:
    try:
        return json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as exc:
        raise CodecError(f"{name}: not valid UTF-8 JSON: {exc}") from None


# ---------------------------------------------------------------- dispatch

def encode_member(ext: str, value: Any, name: str | None = None, exr_compression: str = "zip") -> bytes:
    """Encode ``value`` for a member with extension ``ext`` (``png``/``exr``/``json``).

    ``bytes`` for png/exr are taken as already encoded and checked by decoding;
    for any other extension only ``bytes`` are accepted (stored as they are).
    """
    ext = member_ext(ext)
    label = name or ext
    if ext == "json":
        return encode_json(value, label)
    if isinstance(value, (bytes, bytearray, memoryview)):
        data = bytes(value)
        if ext in CODEC_EXTS:  # json returned above, so png/exr: check it decodes
            decode_member(label if "." in label else f"x.{ext}", data)
        return data
    if ext == "png":
        return encode_png(value, label)
    if ext == "exr":
        return encode_exr(value, label, exr_compression)
    raise CodecError(f"{label}: no codec for extension {ext!r}; pass bytes or use png/exr/json")


def decode_member(name: str, data: bytes) -> Any:
    """Decode member bytes by the extension of ``name``; unknown extensions stay bytes."""
    ext = member_ext(name)
    if ext == "png":
        return decode_png(data, name)
    if ext == "exr":
        return decode_exr(data, name)
    if ext == "json":
        return decode_json(data, name)
    return data


def wds_decoder(key: str, data: bytes) -> Any:
    """A ``webdataset`` ``.decode(...)`` handler: decodes png/exr/json, else passes.

    webdataset calls handlers with the member suffix (``rgb.png``) and the raw
    bytes; returning ``None`` lets the next handler (or the raw bytes) through.
    """
    if member_ext(key) in CODEC_EXTS:
        return decode_member(key, data)
    return None
