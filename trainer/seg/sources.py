"""Where samples come from: real image/mask(/depth) folders and synthetic shards.

Both sources hand out the same plain sample dict, so everything after them
(augmentation, batching, metrics) is source-agnostic::

    {"key": str, "rgb": uint8 HxWx3, "mask": uint8 HxW 0/255,
     "depth": float32 HxW metres with -1 = none, or None}

(real folders add "ignore": uint8 HxW 0/255 or None).

Real folders: ``ROOT/images/STEM.jpg`` + ``ROOT/masks/STEM[suffix].png``
(+ optional ``ROOT/<depth_dir>/STEM.{png,tif,exr,pfm,npy}`` holding depth or
disparity; see ``trainer.seg.depth`` for the conversion and alignment; + optional
``ROOT/ignore/STEM[suffix].png``, pixels the training loss skips, as written by
``cracktrain pseudo-label``). Subfolder names and the mask suffix are configurable.

Shards: WebDataset tars as written by ``crackgen generate``; the key list of
each shard is read from the tar headers only (no decoding), so splits and
per-worker quotas are known before any pixel is decoded.
"""
from __future__ import annotations

import logging
import tarfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator, Sequence

import numpy as np

from trainer.core.errors import TrainerInputError
from trainer.core.holdout import key_in_val, shard_groups
from trainer.core.imageio import DEPTH_EXTS, IMAGE_EXTS, read_float_map, read_mask, read_rgb
from trainer.seg.depth import align_to_rgb, disparity_to_depth, scaled_depth

log = logging.getLogger(__name__)

DEPTH_SOURCES = ("tof", "lidar", "gt", "none")
SPARSE_DEPTHS = ("tof", "lidar")  # shard depth members with holes (-1): the validity channel is on by default
_SHARD_MEMBER = {"tof": "tof", "lidar": "lidar", "gt": "depth"}
DEFAULT_MASK_MEMBER = "mask.png"
MASK_EXTS = (".png", ".bmp", ".jpg", ".tif", ".tiff")


# --------------------------------------------------------------------- real folders

@dataclass
class RealFolder:
    """A folder of real photos + masks (+ optional depth/disparity maps).

    ``stems`` restricts the folder to a subset (e.g. one side of a split).
    ``depth_kind`` is "depth" (raw * ``depth_scale`` = metres) or "disparity"
    (metres = ``focal_px * baseline_m / d``).
    """

    root: Path
    image_dir: str = "images"
    mask_dir: str = "masks"
    mask_suffix: str = ""
    depth_dir: str | None = None
    depth_kind: str = "depth"
    depth_scale: float = 1.0
    focal_px: float | None = None
    baseline_m: float | None = None
    stems: Sequence[str] | None = None
    require_masks: bool = True
    ignore_dir: str | None = "ignore"  # per-pixel "not labelled" masks (value > 127), used when the subfolder exists
    _images: dict[str, Path] = field(default_factory=dict, init=False, repr=False)
    _has_ignore: bool = field(default=False, init=False, repr=False)

    def __post_init__(self) -> None:
        self.root = Path(self.root)
        img_root = self.root / self.image_dir
        if not img_root.is_dir():
            raise TrainerInputError(f"real folder {self.root}: no '{self.image_dir}/' subfolder")
        found = {p.stem: p for p in sorted(img_root.iterdir()) if p.suffix.lower() in IMAGE_EXTS}
        if self.stems is not None:
            missing = sorted(set(self.stems) - set(found))
            if missing:
                raise TrainerInputError(f"{img_root}: no image for stems {missing[:5]}")
            found = {s: found[s] for s in self.stems}
        if not found:
            raise TrainerInputError(f"{img_root}: no images ({', '.join(IMAGE_EXTS)})")
        # Stem order, with or without ``stems``: a split folder ("a.jpg" after "a-1.jpg" by file name)
        # then draws the same samples as the same stems picked from the whole folder.
        self._images = dict(sorted(found.items()))
        if self.require_masks and not (self.root / self.mask_dir).is_dir():
            raise TrainerInputError(f"real folder {self.root}: no '{self.mask_dir}/' subfolder")
        self._has_ignore = bool(self.require_masks and self.ignore_dir and (self.root / self.ignore_dir).is_dir())
        if self.depth_dir is not None and not (self.root / self.depth_dir).is_dir():
            raise TrainerInputError(f"real folder {self.root}: no '{self.depth_dir}/' subfolder")
        if self.depth_kind not in ("depth", "disparity"):
            raise TrainerInputError(f"depth_kind must be 'depth' or 'disparity', got {self.depth_kind!r}")
        if self.depth_kind == "disparity" and self.depth_dir and not (self.focal_px and self.baseline_m):
            raise TrainerInputError("disparity maps need --focal-px and --baseline-m (Z = f*B/d)")

    @property
    def keys(self) -> list[str]:
        return list(self._images)

    def __len__(self) -> int:
        return len(self._images)

    def image_path(self, stem: str) -> Path:
        """The image file of ``stem`` (for reports that must name the file, not just its stem)."""
        return self._images[stem]

    def check_pairs(self) -> None:
        """Every image has a mask and every mask an image (by stem), else one line naming both lists.

        A scored set with a stray mask or a missing one would silently score fewer photos.
        """
        mask_root = self.root / self.mask_dir
        masks = {p.stem for p in mask_root.iterdir() if p.suffix.lower() in MASK_EXTS} if mask_root.is_dir() else set()
        want = {s + self.mask_suffix for s in self._images}
        if self.stems is not None:  # a split side: only its own masks must exist
            masks &= want
        no_mask, no_image = sorted(want - masks), sorted(masks - want)
        if no_mask or no_image:
            parts = []
            if no_mask:
                parts.append(f"{len(no_mask)} image(s) without a mask ({', '.join(no_mask[:3])})")
            if no_image:
                parts.append(f"{len(no_image)} mask(s) without an image ({', '.join(no_image[:3])})")
            raise TrainerInputError(f"{self.root}: image and mask names do not match: {'; '.join(parts)}")

    def _find(self, folder: str, stem: str, exts: Sequence[str]) -> Path:
        for ext in exts:
            for e in (ext, ext.upper()):
                p = self.root / folder / f"{stem}{e}"
                if p.is_file():
                    return p
        raise TrainerInputError(f"{self.root / folder}: no file for '{stem}' ({', '.join(exts)})")

    def mask_path(self, stem: str) -> Path:
        return self._find(self.mask_dir, stem + self.mask_suffix, MASK_EXTS)

    def load(self, stem: str) -> dict[str, Any]:
        """Decode one sample; raises TrainerInputError naming the bad file."""
        img_path = self._images[stem]
        rgb = read_rgb(img_path)
        mask = None
        if self.require_masks:
            mp = self.mask_path(stem)
            mask = read_mask(mp)
            if mask.shape != rgb.shape[:2]:
                raise TrainerInputError(f"{mp}: mask size {mask.shape[::-1]} != image size {rgb.shape[1::-1]} ({img_path.name})")
        ignore = None
        if self._has_ignore:
            ip = self._find(str(self.ignore_dir), stem + self.mask_suffix, (".png", ".bmp", ".tif", ".tiff"))
            ignore = read_mask(ip)
            if ignore.shape != rgb.shape[:2]:
                raise TrainerInputError(f"{ip}: ignore mask size {ignore.shape[::-1]} != image size "
                                        f"{rgb.shape[1::-1]} ({img_path.name})")
        depth = None
        if self.depth_dir is not None:
            dp = self._find(self.depth_dir, stem, DEPTH_EXTS)
            raw = read_float_map(dp)
            if self.depth_kind == "disparity":
                depth = disparity_to_depth(raw, float(self.focal_px), float(self.baseline_m))
            else:
                depth = scaled_depth(raw, self.depth_scale)
            depth = align_to_rgb(depth, rgb.shape[:2])
        return {"key": stem, "rgb": rgb, "mask": mask, "ignore": ignore, "depth": depth, "path": str(img_path)}


# --------------------------------------------------------------------- shards

def list_shards(path: str | Path) -> list[Path]:
    """Finished shard tars of a dataset dir (manifest order), or a single tar.

    ``A,B`` lists several datasets in that order, so renders of different recipes
    train together without being copied into one folder.
    """
    parts = [s.strip() for s in str(path).split(",")]
    if len(parts) > 1:
        if not all(parts):
            raise TrainerInputError(f"shard path list {str(path)!r} has an empty entry")
        found = [s for part in parts for s in _list_one(part)]
        if len(set(found)) != len(found):
            raise TrainerInputError(f"shard path list {str(path)!r} names the same shard twice")
        return found
    return _list_one(path)


def _list_one(path: str | Path) -> list[Path]:
    from crackgen.shards import list_shards as _list  # pure-Python reader

    p = Path(path)
    if not p.exists():
        raise TrainerInputError(f"shard path {p} does not exist")
    try:
        found = [Path(u) for u in _list(str(p))]
    except Exception as exc:  # ShardError/ManifestError: name the folder
        raise TrainerInputError(f"{p}: {exc}") from None
    if not found:
        raise TrainerInputError(f"{p}: no finished shard-*.tar files")
    return found


def shard_members(shard: Path) -> dict[str, set[str]]:
    """Sample key -> member file names (``mask.png``) of one shard, from the tar headers only."""
    found: dict[str, set[str]] = {}
    try:
        with tarfile.open(shard, "r:") as tf:
            for m in tf:
                if m.isfile():
                    key, _, member = m.name.rsplit("/", 1)[-1].partition(".")
                    found.setdefault(key, set()).add(member)
    except (OSError, tarfile.TarError) as exc:
        raise TrainerInputError(f"cannot read shard {shard}: {exc}") from None
    return found


def shard_keys(shard: Path) -> list[str]:
    """Sample keys of one shard from the tar headers (no member is decoded)."""
    return list(shard_members(shard))


def iter_shard(shard: Path, members: Sequence[str], keys: set[str] | None = None) -> Iterator[dict[str, Any]]:
    """Decoded samples of one shard via ``crackgen.shards.iter_samples`` (keys outside ``keys`` are not decoded)."""
    from crackgen.shards import iter_samples  # pure-Python reader; imported lazily

    yield from iter_samples(str(shard), keys=keys, members=list(members))


@dataclass
class ShardSource:
    """Synthetic shards with a chosen depth member, label member and a key-hash validation split.

    ``mask_member`` names the label file of each sample (``mask.png``, or e.g.
    ``mask_thesis.png`` for the thesis eq. 5.5 mask); it is yielded as ``mask``.
    """

    path: Path
    depth: str = "tof"
    val_fraction: float = 0.0
    split: str = "all"  # all | train | val
    seed: int = 0
    mask_member: str = DEFAULT_MASK_MEMBER
    shards: list[Path] = field(default_factory=list, init=False)
    shard_keys: list[list[str]] = field(default_factory=list, init=False)

    def __post_init__(self) -> None:
        if self.depth not in DEPTH_SOURCES:
            raise TrainerInputError(f"--depth must be one of {DEPTH_SOURCES}, got {self.depth!r}")
        base, _, ext = self.mask_member.partition(".")
        if not base or ext not in ("", "png") or "/" in self.mask_member:
            raise TrainerInputError(f"--mask-member must name a PNG label member like mask.png, got {self.mask_member!r}")
        self.shards = list_shards(self.path)
        label = f"{self.label_key}.png"
        groupers: dict[Path, Any] = {}  # one per dataset folder (``A,B`` lists several)
        for s in self.shards:
            members = shard_members(s)
            lacking = [k for k, names in members.items() if label not in names]
            if lacking:  # found from the headers, before any worker starts decoding
                raise TrainerInputError(f"{s}: sample {lacking[0]} has no label member '{label}' "
                                        f"({len(lacking)} of {len(members)} samples lack it; --mask-member)")
            keys = list(members)
            if self.split != "all":
                want_val = self.split == "val"
                if s.parent not in groupers:
                    groupers[s.parent] = shard_groups(s.parent)  # views of one scene stay on one side
                group_of = groupers[s.parent]
                keys = [k for k in keys if key_in_val(group_of(k), self.val_fraction, self.seed) == want_val]
            self.shard_keys.append(keys)
        if sum(map(len, self.shard_keys)) == 0:
            raise TrainerInputError(f"{self.path}: no samples in the '{self.split}' split")

    def __len__(self) -> int:
        return sum(map(len, self.shard_keys))

    @property
    def label_key(self) -> str:
        """Key the label member is decoded under (``mask_thesis.png`` -> ``mask_thesis``)."""
        return self.mask_member.partition(".")[0]

    @property
    def members(self) -> list[str]:
        m = ["rgb", self.label_key]
        if self.depth != "none":
            m.append(_SHARD_MEMBER[self.depth])
        return m

    def iter_shard(self, idx: int, keys: set[str] | None = None) -> Iterator[dict[str, Any]]:
        """Samples of shard ``idx`` (restricted to ``keys``) in the trainer's dict form."""
        shard = self.shards[idx]
        allowed = set(self.shard_keys[idx]) if keys is None else keys
        dm = _SHARD_MEMBER.get(self.depth)
        try:
            for s in iter_shard(shard, self.members, allowed):
                key = s["__key__"]
                if key not in allowed:
                    continue
                if self.label_key not in s:
                    raise TrainerInputError(f"{shard}: sample {key} has no label member "
                                            f"'{self.label_key}.png' (--mask-member {self.mask_member})")
                if "rgb" not in s or (dm and dm not in s):
                    raise TrainerInputError(f"{shard}: sample {key} lacks one of {self.members}")
                mask = np.asarray(s[self.label_key])
                if mask.ndim == 3:
                    mask = mask[..., 0]
                depth = None
                if dm:
                    depth = np.asarray(s[dm], dtype=np.float32)
                    if depth.shape != mask.shape:
                        raise TrainerInputError(f"{shard}: sample {key} {dm} size {depth.shape} != mask size {mask.shape}")
                yield {"key": key, "rgb": np.asarray(s["rgb"])[..., :3], "mask": np.where(mask > 127, 255, 0).astype(np.uint8),
                       "depth": depth, "path": f"{shard}:{key}"}
        except TrainerInputError:
            raise
        except Exception as exc:  # corrupt tar/member: name the shard
            raise TrainerInputError(f"cannot decode shard {shard}: {exc}") from None
