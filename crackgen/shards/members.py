"""The registry of shard member names: what each member holds and how it is stored.

Why one table: the writer's checks, the reader's output names, the codecs and the
docs all need to know that ``mask`` is an 8-bit 0/255 PNG in the RGB view's pixel
grid and that ``tofraw`` is a two-channel EXR in the ToF's own grid. Saying it once
here keeps them from drifting apart. A member file in a tar is ``KEY.<filename>``
(``000000-00017.rgb.png``; the metadata is plain ``000000-00017.json``).

Members not listed here may still be written (``foo.png``, ``extra.exr``); they are
encoded by extension and get no content checks.
"""
from __future__ import annotations

import enum
import types
from dataclasses import dataclass
from typing import Mapping


class Codec(str, enum.Enum):
    """How a member's value becomes bytes (the file extension follows from it)."""

    PNG_RGB = "png-rgb"            # uint8 H×W×3, sRGB, RGB channel order
    PNG_MASK = "png-mask"          # uint8 H×W, values 0 or 255
    EXR_FLOAT = "exr-float"        # float32 H×W, one channel "Z"
    EXR_CHANNELS = "exr-channels"  # float32 named channels of one size, e.g. Z and A
    JSON = "json"                  # UTF-8 strict JSON object

    @property
    def ext(self) -> str:
        """File extension that selects this codec's family: ``png``, ``exr`` or ``json``."""
        return self.value.split("-", 1)[0]


# Extensions the codecs know; any other extension is stored as given bytes.
CODEC_EXTS: frozenset[str] = frozenset(c.ext for c in Codec)
SINGLE_CHANNEL = "Z"  # the channel name of a one-channel (EXR_FLOAT) map
JSON_MEMBER = "json"  # the metadata member's full name (no base, no dot)
META_KEY = "meta"     # what the reader yields the parsed JSON under


@dataclass(frozen=True)
class Member:
    """One kind of member: its base name, its codec, and where its pixels live."""

    name: str
    codec: Codec
    in_rgb_view: bool  # in the RGB camera's pixel grid, so it must share rgb's H×W
    channels: tuple[str, ...] = ()  # required EXR channel names for EXR_CHANNELS
    doc: str = ""

    @property
    def ext(self) -> str:
        return self.codec.ext

    @property
    def filename(self) -> str:
        """Name after ``KEY.`` in the tar: ``rgb.png``; the metadata is just ``json``."""
        return JSON_MEMBER if self.codec is Codec.JSON else f"{self.name}.{self.ext}"

    @property
    def is_rgb(self) -> bool:
        """An 8-bit RGB image (rendered views), as opposed to labels or measurements."""
        return self.codec is Codec.PNG_RGB

    @property
    def yielded_as(self) -> str:
        """Key of the decoded value in a sample dict from ``iter_samples``."""
        return META_KEY if self.codec is Codec.JSON else self.name


_ALL = (
    Member("rgb", Codec.PNG_RGB, True, doc="rendered RGB"),
    Member("mask", Codec.PNG_MASK, True, doc="GT crack label (0/255), the [label] policy's (visible crack by default)"),
    Member("mask_thesis", Codec.PNG_MASK, True,
           doc="thesis GT mask Z < t (eq. 5.5, 0/255); optional, written when [label] policy = visible"),
    Member("depth", Codec.EXR_FLOAT, True, doc="dense GT planar depth (m)"),
    Member("tof", Codec.EXR_FLOAT, True, doc="sparse ToF depth projected into the RGB view (m, -1 none)"),
    Member("tofraw", Codec.EXR_CHANNELS, False, channels=("Z", "A"),
           doc="ToF native range Z (m) and amplitude A"),
    Member("lidar", Codec.EXR_FLOAT, True, doc="sparse LiDAR depth in the RGB view (m, -1 none)"),
    Member("right", Codec.PNG_RGB, True, doc="rendered right stereo view"),
    Member("disp_sgm", Codec.EXR_FLOAT, True, doc="SGBM disparity in the left view (px, -1 none)"),
    Member("disp_gt", Codec.EXR_FLOAT, True, doc="GT disparity f·B/Z in the left view (px, -1 none)"),
    Member("disp_tof", Codec.EXR_FLOAT, True, doc="ToF disparity in the left view (px, -1 none)"),
    Member("tofamp", Codec.EXR_FLOAT, True, doc="ToF amplitude in the left view (-1 none)"),
    Member("disp_lidar", Codec.EXR_FLOAT, True, doc="LiDAR disparity f·B/Z in the left view (px, -1 none)"),
    Member("crackmap", Codec.EXR_FLOAT, False, doc="crack displacement map in surface coordinates (m)"),
    Member(JSON_MEMBER, Codec.JSON, False, doc="SampleSpec, cameras, seeds, GT crack length, timings"),
)

MEMBERS: Mapping[str, Member] = types.MappingProxyType({m.name: m for m in _ALL})
"""Base name (``rgb``, ``json``) -> Member, in the order the data contract lists them."""

_BY_FILENAME: Mapping[str, Member] = types.MappingProxyType({m.filename: m for m in _ALL})

RGB_VIEW_MEMBERS: tuple[str, ...] = tuple(m.name for m in _ALL if m.in_rgb_view)
RGB_MEMBERS: tuple[str, ...] = tuple(m.name for m in _ALL if m.is_rgb)


def member_ext(filename: str) -> str:
    """Extension that selects the codec: ``rgb.png`` -> ``png``, ``json`` -> ``json``."""
    return filename.rsplit(".", 1)[-1].lower()


def base_name(filename: str) -> str:
    """``rgb.png`` -> ``rgb``; ``json`` -> ``json`` (a name without a dot is its own base)."""
    return filename.rsplit(".", 1)[0]


def out_name(filename: str) -> str:
    """Key a decoded member is yielded under: ``rgb.png`` -> ``rgb``, ``json`` -> ``meta``."""
    return META_KEY if filename == JSON_MEMBER else base_name(filename)


def member_for_file(filename: str) -> Member | None:
    """The registered member stored as exactly ``filename`` (``mask.png``), else None.

    ``mask.exr`` is not the registered mask (wrong codec), so it gets no mask checks.
    """
    return _BY_FILENAME.get(filename)


def member_for_name(name: str) -> Member | None:
    """The registered member with base name ``name`` (``rgb`` or ``rgb.png``), else None."""
    return MEMBERS.get(base_name(name))
