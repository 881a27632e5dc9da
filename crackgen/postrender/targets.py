"""The folder of unlabeled target photos that [adapt] pulls renders toward.

Why a class: the folder is checked once, before any rendering (missing, empty or
unreadable is a one-line error up front, not a failure at sample 9,000), the file
list is sorted so that a drawn fraction names the same photo on every worker, and
decoded photos are cached per process.
"""
from __future__ import annotations

from functools import lru_cache
from pathlib import Path

import cv2
import numpy as np
from PIL import Image, UnidentifiedImageError

from crackgen.errors import CrackgenError

PHOTO_EXTS = (".jpg", ".jpeg", ".png", ".bmp", ".tif", ".tiff", ".webp")


class TargetError(CrackgenError, ValueError):
    """The target photo folder is missing, empty or holds an unreadable file."""


class TargetPhotos:
    """Sorted, checked list of photos in one folder (not recursive)."""

    def __init__(self, folder: str | Path, check: bool = True, what: str = "adapt target"):
        self.folder = Path(folder).expanduser()
        self.what = what  # how error messages name the folder (the recipe field)
        if not self.folder.is_dir():
            raise TargetError(f"{what} {self.folder}: no such folder")
        self.paths = sorted(p for p in self.folder.iterdir() if p.suffix.lower() in PHOTO_EXTS and p.is_file())
        if not self.paths:
            raise TargetError(f"{what} {self.folder}: no photos ({', '.join(PHOTO_EXTS)})")
        if check:
            for p in self.paths:
                try:
                    with Image.open(p) as im:
                        im.verify()
                except (UnidentifiedImageError, OSError, SyntaxError) as exc:
                    raise TargetError(f"{what} {p}: unreadable image ({exc})") from None

    def __len__(self) -> int:
        return len(self.paths)

    def name_for(self, fraction: float) -> str:
        """The photo a drawn fraction in [0, 1) selects."""
        i = min(int(float(fraction) * len(self.paths)), len(self.paths) - 1)
        return self.paths[i].name

    def load(self, name: str) -> np.ndarray:
        """uint8 RGB of one photo by file name."""
        return _read_rgb(str(self.folder / name), self.what)


@lru_cache(maxsize=64)
def _read_rgb(path: str, what: str = "adapt target") -> np.ndarray:
    img = cv2.imread(path, cv2.IMREAD_COLOR)
    if img is None:
        raise TargetError(f"{what} {path}: unreadable image")
    out = cv2.cvtColor(img, cv2.COLOR_BGR2RGB)
    out.setflags(write=False)
    return out
