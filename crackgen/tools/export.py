"""`crackgen export DIR --to OUT --members rgb,mask[,depth,tof,lidar]`: shards -> plain folders.

Why: most crack segmentation code (DeepCrack and its descendants) reads an
``images/`` + ``masks/`` folder pair, not WebDataset tars. The layout written::

    OUT/images/<key>.png     8-bit RGB
    OUT/masks/<key>.png      8-bit, 0 / 255
    OUT/<member>/<key>.png   depth/tof/lidar: 16-bit millimetres, 0 = no measurement (default)
    OUT/<member>/<key>.exr   ... or float32 metres, -1 = no measurement (--depth-format exr)
    OUT/export.json          where the files came from and how depth is encoded

The stem is the sample key in every folder, so files pair up by name.
Only the requested members are decoded. The export is all-or-nothing: files are
written into a hidden sibling folder that is renamed to OUT when every sample is
done, and an OUT that already holds anything is refused (nothing is overwritten).
"""
from __future__ import annotations

import json
import os
import shutil
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from crackgen.errors import CrackgenError
from crackgen.shards import ShardError, iter_samples, open_dataset
from crackgen.shards.codecs import CodecError, encode_exr, encode_png

FOLDERS = {"rgb": "images", "mask": "masks", "depth": "depth", "tof": "tof", "lidar": "lidar"}
DEPTH_MEMBERS = ("depth", "tof", "lidar")
DEPTH_FORMATS = ("png16", "exr")
MM_PER_M = 1000.0
MAX_MM = np.iinfo(np.uint16).max


class ExportError(CrackgenError, ValueError):
    """The export cannot be done as asked (names the member, folder or sample)."""


@dataclass
class ExportResult:
    """What was written: counts per folder, for the closing summary line."""

    out: Path
    samples: int
    files: dict[str, int] = field(default_factory=dict)
    depth_format: str = "png16"

    def summary(self) -> str:
        folders = ", ".join(f"{name}/ ({n})" for name, n in self.files.items())
        return f"exported {self.samples} samples, {sum(self.files.values())} files to {self.out}: {folders}"


def parse_members(text: str) -> list[str]:
    """``"rgb,mask,tof"`` -> ``["rgb", "mask", "tof"]``; unknown or missing names are refused."""
    names = [m.strip() for m in text.split(",") if m.strip()]
    if not names:
        raise ExportError(f"--members: give at least one of {', '.join(FOLDERS)}")
    unknown = [m for m in names if m not in FOLDERS]
    if unknown:
        raise ExportError(f"--members: unknown member {unknown[0]!r}; choose from {', '.join(FOLDERS)}")
    return list(dict.fromkeys(names))


def depth_to_mm(depth: np.ndarray, where: str) -> np.ndarray:
    """float32 metres (-1/0/nan = none) -> uint16 millimetres with 0 = none.

    A real measurement never becomes 0 (it is at least 1 mm), and a depth beyond
    65.535 m is refused rather than clipped, since clipping would silently lie.
    """
    d = np.asarray(depth, np.float32)
    valid = np.isfinite(d) & (d > 0)
    mm = np.zeros(d.shape, np.uint16)
    if valid.any():
        v = np.round(d[valid].astype(np.float64) * MM_PER_M)
        if v.max() > MAX_MM:
            raise ExportError(f"{where}: depth {v.max() / MM_PER_M:.3f} m does not fit a 16-bit mm PNG "
                              "(max 65.535 m); use --depth-format exr")
        mm[valid] = np.maximum(v, 1).astype(np.uint16)
    return mm


def encode_for_export(member: str, value: Any, key: str, depth_format: str) -> tuple[str, bytes]:
    """(file extension, bytes) of one decoded member in the export layout."""
    where = f"{key}.{member}"
    try:
        if member in DEPTH_MEMBERS:
            if depth_format == "exr":
                return "exr", encode_exr(np.asarray(value, np.float32), where)
            return "png", encode_png(depth_to_mm(value, where), where)
        return "png", encode_png(np.asarray(value), where)
    except CodecError as exc:
        raise ExportError(str(exc)) from None


def _check_out(out: Path) -> None:
    if out.exists() and not out.is_dir():
        raise ExportError(f"--to {out}: exists and is not a folder")
    if out.is_dir() and any(out.iterdir()):
        raise ExportError(f"--to {out}: folder is not empty; export into a new or empty folder")


def _open(src: Path) -> Any:
    if not src.is_dir():
        raise ExportError(f"{src}: not a dataset directory")
    try:
        return open_dataset(str(src))
    except ShardError as exc:
        raise ExportError(f"{src}: not a dataset directory ({exc})") from None


def _publish(tmp: Path, out: Path) -> None:
    """Move the finished export to ``out`` (an empty ``out`` that already exists is replaced)."""
    if out.is_dir():
        out.rmdir()  # only succeeds when empty, checked before any work started
    os.replace(tmp, out)


def _write_samples(samples: Iterable[dict[str, Any]], members: list[str], tmp: Path, depth_format: str,
                   total: int | None, progress: bool) -> tuple[int, dict[str, int]]:
    from tqdm import tqdm

    files = {FOLDERS[m]: 0 for m in members}
    seen: set[str] = set()
    for folder in files:
        (tmp / folder).mkdir()
    for s in tqdm(samples, total=total, desc="export", unit="sample", disable=not progress, dynamic_ncols=True):
        key = s["__key__"]
        if key in seen:
            raise ExportError(f"sample key {key!r} appears twice; files would overwrite each other")
        seen.add(key)
        for m in members:
            if m not in s:
                raise ExportError(f"sample {key} ({s['__shard__']}) has no '{m}' member")
            ext, data = encode_for_export(m, s[m], key, depth_format)
            (tmp / FOLDERS[m] / f"{key}.{ext}").write_bytes(data)
            files[FOLDERS[m]] += 1
    return len(seen), files


def _provenance(src: Path, members: list[str], depth_format: str, samples: int) -> dict[str, Any]:
    """What ``export.json`` says: the source, and per folder which member it holds and how it is encoded."""
    depth = {"png16": "uint16 PNG, millimetres, 0 = no measurement",
             "exr": "float32 OpenEXR (channel Z), metres, -1 = no measurement"}[depth_format]
    formats = {"rgb": "8-bit RGB PNG", "mask": "8-bit PNG, 0 / 255"}
    folders = {FOLDERS[m]: {"member": m, "format": formats.get(m, depth)} for m in members}
    return {"source": str(src.resolve()), "samples": samples, "file_stem": "sample key", "folders": folders}


def export(src: str | os.PathLike, out: str | os.PathLike, members: Iterable[str],
           depth_format: str = "png16", progress: bool = True) -> ExportResult:
    """Export the dataset at ``src`` to folders under ``out`` (see module doc)."""
    src, out = Path(src), Path(out)
    members = parse_members(",".join(members))
    if depth_format not in DEPTH_FORMATS:
        raise ExportError(f"--depth-format: unknown format {depth_format!r}; choose from {', '.join(DEPTH_FORMATS)}")
    _check_out(out)
    dataset = _open(src)
    out.parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(tempfile.mkdtemp(prefix=f".{out.name}.partial-", dir=out.parent))
    try:
        samples = iter_samples(dataset.shards, members=members)
        n, files = _write_samples(samples, members, tmp, depth_format, dataset.num_samples, progress)
        if n == 0:
            raise ExportError(f"{src}: dataset has no samples")
        (tmp / "export.json").write_text(json.dumps(_provenance(src, members, depth_format, n), indent=2) + "\n")
        _publish(tmp, out)
    except ShardError as exc:
        shutil.rmtree(tmp, ignore_errors=True)
        raise ExportError(str(exc)) from None
    except BaseException:
        shutil.rmtree(tmp, ignore_errors=True)
        raise
    return ExportResult(out, n, files, depth_format)
