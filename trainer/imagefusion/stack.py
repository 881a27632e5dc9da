"""``cracktrain merge-stack``: guided-filter fusion of an exposure or focus stack, with its quality scores.

Reads N registered images of one size (8- or 16-bit, grey or colour), fuses them with
``fusion.image.fuse`` (2-level, or the thesis's 3-level), writes the fused image (8-bit, or
16-bit when every input is) and returns Q_Y, Q_C, Q_G and Q_MI of the fusion.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np

from trainer.core.errors import TrainerInputError


def add_fuse_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("images", nargs="+", metavar="IMG", help="two or more registered images of the same scene")
    p.add_argument("--out", required=True, metavar="FUSED.png", help="fused image (any OpenCV format)")
    p.add_argument("--levels", type=int, choices=(2, 3), default=3, help="2-level (Li et al.) or 3-level (thesis)")


def _read(path: str) -> tuple[np.ndarray, int]:
    p = Path(path)
    if not p.is_file():
        raise TrainerInputError(f"image {p} does not exist")
    img = cv2.imread(str(p), cv2.IMREAD_UNCHANGED)
    if img is None:
        raise TrainerInputError(f"image {p} cannot be read as an image")
    if img.dtype not in (np.uint8, np.uint16):
        raise TrainerInputError(f"image {p}: 8- or 16-bit images only, got {img.dtype}")
    if img.ndim == 3 and img.shape[2] == 4:
        img = img[..., :3]
    if img.ndim == 3:
        img = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    return img.astype(np.float64) / np.iinfo(img.dtype).max, np.iinfo(img.dtype).max


def merge_stack(images: Sequence[str], out: str | Path, levels: int = 3) -> dict[str, Any]:
    """Fuse ``images`` (an exposure or focus stack) into ``out``; returns the four quality scores."""
    from fusion.image.fuse import ImageFusionError, fuse_images
    from fusion.image.metrics import fusion_quality

    if len(images) < 2:
        raise TrainerInputError(f"merge-stack needs at least 2 images, got {len(images)}")
    loaded = [_read(p) for p in images]
    imgs = [a for a, _ in loaded]
    ndims = {a.ndim for a in imgs}
    if len(ndims) > 1:  # mixed grey and colour: fuse in grey
        from fusion.image.fuse import luminance

        imgs = [luminance(a) for a in imgs]
    try:
        fused = fuse_images(imgs, levels)
    except ImageFusionError as exc:
        raise TrainerInputError(f"{exc} ({', '.join(map(str, images))})") from None
    top = 65535 if all(m == 65535 for _, m in loaded) else 255
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    q = np.round(fused * top).astype(np.uint16 if top == 65535 else np.uint8)
    if not cv2.imwrite(str(out), cv2.cvtColor(q, cv2.COLOR_RGB2BGR) if q.ndim == 3 else q):
        raise TrainerInputError(f"cannot write {out} (unknown extension or unwritable folder)")
    scores = fusion_quality([255 * a for a in imgs], 255 * fused)
    return {"out": str(out), "levels": levels, "inputs": len(imgs), **scores}
