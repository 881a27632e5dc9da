"""`crackgen stats`: one table of crack and image statistics, for shards or a real images/ + masks/ folder.

Why: to set a recipe so its renders look like a user's real photos (crack widths, how much of
an image is crack, how many pieces, how bright, contrasty and sharp), the two must be measured
the same way. Per image:
- crack-pixel fraction: share of mask pixels > 127;
- crack width (px), sampled on the mask skeleton (skimage): ``dt(p) + dt(q)``, with ``dt`` the
  Euclidean distance to the nearest background pixel and ``q`` the largest-``dt`` 8-neighbour of
  ``p`` off the skeleton. This is "2 x the distance transform" made exact for straight lines of any
  integer width (plain ``2 * dt`` overstates by one pixel, and an even width's skeleton is off centre);
- connected crack components (8-connected);
- brightness and contrast: mean and std of luminance (0-255, OpenCV's BT.601 grey);
- sharpness: variance of the Laplacian of the luminance;
- label contrast: how dark the labelled crack is against the surface right next to it,
  (median ring luma - median inside luma) / median ring luma with a 2-px ring
  (``crackgen.sim.visibility.label_contrast``, the check the renderer's ``[label]`` rule uses):
  1 is a black crack, 0 an invisible one. Real datasets differ most here: DeepCrack's cracks
  are dark and wide, hairlines on pavement and bridge concrete are faint.
Widths pool every skeleton pixel of every image; the other rows are percentiles over images
(label contrast over the images that have a labelled crack).
"""
from __future__ import annotations

import json
import os
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Iterator

import cv2
import numpy as np

from crackgen.errors import CrackgenError
from crackgen.sim.visibility import label_contrast

IMAGE_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


class StatsError(CrackgenError, ValueError):
    """A path that is neither a dataset nor an images/ + masks/ folder, or holds no usable pair."""


def crack_widths(mask: np.ndarray) -> np.ndarray:
    """Local crack widths (px), one per skeleton pixel of ``mask`` (bool or 0/255)."""
    from skimage.morphology import skeletonize

    m = np.asarray(mask) > 0 if np.asarray(mask).dtype == bool else np.asarray(mask) > 127
    if not m.any():
        return np.zeros(0, np.float32)
    skel = skeletonize(m)
    dt = cv2.distanceTransform(m.astype(np.uint8), cv2.DIST_L2, cv2.DIST_MASK_PRECISE)
    off = np.where(skel, 0.0, dt).astype(np.float32)
    neighbour = cv2.dilate(off, np.ones((3, 3), np.uint8))
    return (dt + neighbour)[skel].astype(np.float32)


def count_components(mask: np.ndarray) -> int:
    m = (np.asarray(mask) > 127).astype(np.uint8)
    n, _ = cv2.connectedComponents(m, connectivity=8)
    return int(n - 1)


@dataclass
class ImageStats:
    fraction: float
    components: int
    brightness: float
    contrast: float
    sharpness: float
    label_contrast: float | None  # None without a labelled crack (or its ring)
    size: tuple[int, int]  # (width, height)
    widths: np.ndarray = field(repr=False)


def image_stats(rgb: np.ndarray, mask: np.ndarray) -> ImageStats:
    """The statistics of one RGB (H x W x 3, uint8) + mask (H x W, 0/255) pair."""
    rgb = np.asarray(rgb)
    grey = cv2.cvtColor(rgb, cv2.COLOR_RGB2GRAY) if rgb.ndim == 3 else rgb
    grey = grey.astype(np.float64)
    m = np.asarray(mask)
    if m.ndim == 3:
        m = m[..., 0]
    return ImageStats(
        fraction=float((m > 127).mean()),
        components=count_components(m),
        brightness=float(grey.mean()),
        contrast=float(grey.std()),
        sharpness=float(cv2.Laplacian(grey, cv2.CV_64F).var()),
        label_contrast=label_contrast(rgb if rgb.ndim == 3 else np.dstack([rgb] * 3), m > 127),
        size=(int(rgb.shape[1]), int(rgb.shape[0])),
        widths=crack_widths(m),
    )


# ---- sources ------------------------------------------------------------------------------------

def _is_folder(path: Path) -> bool:
    return (path / "images").is_dir() and (path / "masks").is_dir()


def _pairs(root: Path) -> tuple[list[tuple[Path, Path]], int]:
    def listing(d: Path) -> dict[str, Path]:
        return {p.stem: p for p in sorted(d.iterdir()) if p.suffix.lower() in IMAGE_EXTS}

    images, masks = listing(root / "images"), listing(root / "masks")
    stems = sorted(set(images) & set(masks))
    return [(images[s], masks[s]) for s in stems], len(set(images) ^ set(masks))


def _read(path: Path, flags: int) -> np.ndarray:
    img = cv2.imread(str(path), flags)
    if img is None:
        raise StatsError(f"{path}: cannot read image")
    return img


def _folder_samples(root: Path, limit: int | None) -> tuple[Iterator[tuple[np.ndarray, np.ndarray]], int, str]:
    pairs, unpaired = _pairs(root)
    if not pairs:
        raise StatsError(f"{root}: no image in images/ has a mask of the same name in masks/")
    pairs = pairs[:limit] if limit else pairs
    note = f"folder, {unpaired} files without a partner skipped" if unpaired else "folder"

    def gen() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        for img, msk in pairs:
            yield cv2.cvtColor(_read(img, cv2.IMREAD_COLOR), cv2.COLOR_BGR2RGB), _read(msk, cv2.IMREAD_GRAYSCALE)

    return gen(), len(pairs), note


def _shard_samples(root: Path, limit: int | None) -> tuple[Iterator[tuple[np.ndarray, np.ndarray]], int | None, str]:
    from crackgen.shards import ShardError, iter_samples, open_dataset

    try:
        ds = open_dataset(str(root))
    except ShardError as exc:
        raise StatsError(f"{root}: neither a crackgen dataset nor an images/ + masks/ folder ({exc})") from None
    if not ds.shards:
        raise StatsError(f"{root}: neither a crackgen dataset nor an images/ + masks/ folder (no shards)")
    total = ds.num_samples
    if limit:
        total = min(total, limit) if total else limit

    def gen() -> Iterator[tuple[np.ndarray, np.ndarray]]:
        try:
            for i, s in enumerate(iter_samples(ds.shards, members=["rgb", "mask"])):
                if limit and i >= limit:
                    return
                if "rgb" not in s or "mask" not in s:
                    raise StatsError(f"{root}: sample {s['__key__']} has no rgb or mask member")
                yield s["rgb"], s["mask"]
        except ShardError as exc:
            raise StatsError(str(exc)) from None

    return gen(), total, "shards"


# ---- the table ----------------------------------------------------------------------------------

ROWS = (  # key, label
    ("fraction_pct", "crack-pixel fraction (%)"),
    ("width_px", "crack width (px)"),
    ("components", "components per image"),
    ("brightness", "brightness (mean luma, 0-255)"),
    ("contrast", "contrast (luma std)"),
    ("sharpness", "sharpness (Laplacian var)"),
    ("label_contrast", "label contrast (ring vs crack)"),
)


def _summary(values: np.ndarray) -> dict[str, float | None]:
    if values.size == 0:
        return {"p10": None, "p50": None, "p90": None, "mean": None}
    p10, p50, p90 = np.percentile(values, [10, 50, 90])
    return {"p10": float(p10), "p50": float(p50), "p90": float(p90), "mean": float(values.mean())}


def compute_stats(path: str | os.PathLike, limit: int | None = None, progress: bool = True) -> dict[str, Any]:
    """Statistics of the dataset or images/ + masks/ folder at ``path`` (see module doc)."""
    from tqdm import tqdm

    root = Path(path)
    if not root.is_dir():
        raise StatsError(f"{root}: not a folder")
    if limit is not None and limit < 1:
        raise StatsError(f"--limit must be >= 1, got {limit}")
    samples, total, kind = (_folder_samples if _is_folder(root) else _shard_samples)(root, limit)
    per: list[ImageStats] = [image_stats(rgb, m) for rgb, m in tqdm(
        samples, total=total, desc="stats", unit="image", disable=not progress, dynamic_ncols=True)]
    if not per:
        raise StatsError(f"{root}: no samples")
    widths = np.concatenate([p.widths for p in per])
    rows = {
        "fraction_pct": _summary(100 * np.array([p.fraction for p in per])),
        "width_px": _summary(widths),
        "components": _summary(np.array([p.components for p in per], float)),
        "brightness": _summary(np.array([p.brightness for p in per])),
        "contrast": _summary(np.array([p.contrast for p in per])),
        "sharpness": _summary(np.array([p.sharpness for p in per])),
        "label_contrast": _summary(np.array([p.label_contrast for p in per if p.label_contrast is not None])),
    }
    sizes = Counter(f"{w}x{h}" for w, h in (p.size for p in per))
    free = sum(p.fraction == 0 for p in per)
    return {"path": str(root), "source": kind, "images": len(per), "rows": rows,
            "crack_free": free, "crack_free_pct": 100.0 * free / len(per),
            "sizes": dict(sizes.most_common())}


def format_stats(s: dict[str, Any]) -> str:
    def cell(v: float | None) -> str:
        return f"{'-':>9}" if v is None else f"{v:9.3g}" if abs(v) < 1e4 else f"{v:9.0f}"

    lines = [f"{s['path']} ({s['source']}): {s['images']} images",
             f"{'statistic':<30}{'p10':>9}{'p50':>9}{'p90':>9}{'mean':>9}"]
    for key, label in ROWS:
        r = s["rows"][key]
        lines.append(f"{label:<30}" + "".join(cell(r[c]) for c in ("p10", "p50", "p90", "mean")))
    lines.append(f"crack-free images: {s['crack_free_pct']:.1f} % ({s['crack_free']} of {s['images']})")
    sizes = ", ".join(f"{k} ({v})" for k, v in list(s["sizes"].items())[:4])
    more = f", {len(s['sizes']) - 4} more" if len(s["sizes"]) > 4 else ""
    lines.append(f"image size (WxH): {sizes}{more}")
    return "\n".join(lines)


def _column_title(r: dict[str, Any], width: int) -> str:
    name = Path(r["path"]).name or str(r["path"])
    tail = f" ({r['images']})"
    return name[: width - 1 - len(tail)] + tail


def format_side_by_side(results: list[dict[str, Any]]) -> str:
    """Several datasets or folders in one table (p10 / p50 / p90 of each), to hold renders against real photos."""
    def cell(v: float | None) -> str:
        return f"{'-':>9}" if v is None else f"{v:9.3g}" if abs(v) < 1e4 else f"{v:9.0f}"

    width = 27
    head = f"{'':<30}" + "".join(f"{_column_title(r, width):>{width}}"
                                 for r in results)
    lines = [head, f"{'statistic':<30}" + "".join(f"{'p10':>9}{'p50':>9}{'p90':>9}" for _ in results)]
    for key, label in ROWS:
        lines.append(f"{label:<30}" + "".join(cell(r["rows"][key][c]) for r in results for c in ("p10", "p50", "p90")))
    lines.append(f"{'crack-free images (%)':<30}" + "".join(f"{r['crack_free_pct']:>27.1f}" for r in results))
    return "\n".join(lines)


def write_json(s: dict[str, Any] | list[dict[str, Any]], out: str | os.PathLike) -> Path:
    p = Path(out)
    try:
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(json.dumps(s, indent=1) + "\n", encoding="utf-8")
    except OSError as exc:
        raise StatsError(f"--json {p}: cannot write: {exc}") from None
    return p
