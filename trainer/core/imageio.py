"""Reading RGB photos, masks and depth/disparity maps with clear errors.

Every reader raises :class:`TrainerInputError` naming the file when it cannot
decode it, so loaders can either fail with a one-line reason or skip the file
(``--skip-bad``).
"""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np

from trainer.core.errors import TrainerInputError

IMAGE_EXTS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")
DEPTH_EXTS = (".png", ".tif", ".tiff", ".exr", ".pfm", ".npy")


def read_rgb(path: str | Path) -> np.ndarray:
    """uint8 HxWx3 RGB (grey images are expanded to 3 channels)."""
    img = cv2.imread(str(path), cv2.IMREAD_COLOR)
    if img is None:
        raise TrainerInputError(f"cannot read image {path}")
    return cv2.cvtColor(img, cv2.COLOR_BGR2RGB)


def read_mask(path: str | Path) -> np.ndarray:
    """uint8 HxW 0/255 mask; a pixel is crack where the grey value is > 127."""
    m = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
    if m is None:
        raise TrainerInputError(f"cannot read mask {path}")
    return np.where(m > 127, 255, 0).astype(np.uint8)


def _read_exr(path: Path) -> np.ndarray:
    import OpenEXR  # local: only needed for EXR depth maps

    try:
        # Copy the pixels out inside the block: closing the file empties its channel dict.
        with OpenEXR.File(str(path), separate_channels=True) as f:
            chans = {name: np.array(c.pixels, dtype=np.float32) for name, c in f.channels().items()}
    except Exception as exc:  # OpenEXR raises plain RuntimeError/ValueError
        raise TrainerInputError(f"cannot read EXR {path}: {exc}") from None
    for name in ("Z", "Y", "R", "depth", "V"):
        if name in chans:
            return chans[name]
    if len(chans) == 1:
        return next(iter(chans.values()))
    raise TrainerInputError(f"EXR {path} has no depth channel (channels: {sorted(chans)})")


def read_float_map(path: str | Path) -> np.ndarray:
    """Raw single-channel map as float32 (16-bit PNG counts stay counts).

    Supports 8/16-bit PNG/TIFF, float TIFF, PFM, EXR and .npy. Units are the
    caller's business (see ``trainer.seg.depth``).
    """
    p = Path(path)
    ext = p.suffix.lower()
    if ext == ".npy":
        try:
            arr = np.load(p, allow_pickle=False)
        except Exception as exc:
            raise TrainerInputError(f"cannot read {p}: {exc}") from None
    elif ext == ".exr":
        arr = _read_exr(p)
    else:
        arr = cv2.imread(str(p), cv2.IMREAD_UNCHANGED | cv2.IMREAD_ANYDEPTH)
        if arr is None:
            raise TrainerInputError(f"cannot read depth/disparity map {p}")
    arr = np.asarray(arr)
    if arr.ndim == 3:
        arr = arr[..., 0]
    if arr.ndim != 2:
        raise TrainerInputError(f"{p}: expected a single-channel 2-D map, got shape {arr.shape}")
    return arr.astype(np.float32)
