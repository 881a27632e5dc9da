"""Site adaptation while training: synthetic RGB pulled toward unlabeled target photos.

Why in the loader as well as in the generator: the generator's ``[adapt]`` stage bakes
one target photo into each render; here every epoch draws a fresh photo, method and
band per synthetic sample, so a few hundred renders meet many target appearances, and
``cracktrain sim2real`` can adapt toward the unlabeled images of exactly its own
training split. Only synthetic samples are adapted; masks and depth are never touched.
The transforms themselves are ``crackgen.postrender.adapt`` (pure numpy/OpenCV).
"""
from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path
from typing import Sequence

import cv2
import numpy as np

from crackgen.postrender.adapt import METHODS, adapt_views
from crackgen.postrender.targets import TargetError, TargetPhotos
from trainer.core.errors import TrainerInputError


@dataclass(frozen=True)
class SiteAdaptation:
    """Per-sample random adaptation: a photo from ``targets``, a method from ``methods``."""

    targets: tuple[str, ...]
    methods: tuple[str, ...] = METHODS
    band: tuple[float, float] = (0.005, 0.05)
    probability: float = 1.0

    def __post_init__(self) -> None:
        if not self.targets:
            raise TrainerInputError("site adaptation: no target photos")
        bad = [m for m in self.methods if m not in METHODS]
        if bad or not self.methods:
            raise TrainerInputError(f"--adapt-methods: unknown {bad or 'empty list'}; choose from {', '.join(METHODS)}")
        lo, hi = self.band
        if not 0.0 <= lo <= hi <= 0.5:
            raise TrainerInputError(f"--adapt-band: need 0 <= min <= max <= 0.5, got {lo},{hi}")
        if not 0.0 <= self.probability <= 1.0:
            raise TrainerInputError(f"--adapt-prob must be in [0, 1], got {self.probability}")

    def draw(self, rng: np.random.Generator) -> dict | None:
        """The transform for one sample (all draws made, so the stream of draws never shifts)."""
        apply = rng.random() < self.probability
        method = self.methods[int(rng.integers(len(self.methods)))]
        band = float(rng.uniform(*self.band)) if self.band[1] > self.band[0] else float(self.band[0])
        target = self.targets[int(rng.integers(len(self.targets)))]
        return {"method": method, "band": band, "target": target} if apply else None

    def apply(self, rgb: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        t = self.draw(rng)
        if t is None:
            return rgb
        return adapt_views([rgb], _target(t["target"], rgb.shape[0], rgb.shape[1]), t["method"], t["band"])[0]


@lru_cache(maxsize=512)
def _target(path: str, h: int, w: int) -> np.ndarray:
    """The photo resized to the render size, cached per worker process (decoding dominates)."""
    img = cv2.imread(path, cv2.IMREAD_COLOR)
    if img is None:
        raise TrainerInputError(f"cannot read adaptation target {path}")
    return cv2.cvtColor(cv2.resize(img, (w, h), interpolation=cv2.INTER_AREA), cv2.COLOR_BGR2RGB)


def targets_from_folder(folder: str | Path) -> tuple[str, ...]:
    """Every photo in a folder of unlabeled images (checked: missing/empty/unreadable is one line)."""
    try:
        photos = TargetPhotos(folder)
    except TargetError as exc:
        raise TrainerInputError(str(exc)) from None
    return tuple(str(p) for p in photos.paths)


def targets_from_paths(paths: Sequence[Path]) -> tuple[str, ...]:
    return tuple(str(p) for p in sorted(paths))


def parse_band(text: str) -> tuple[float, float]:
    try:
        parts = [float(x) for x in text.split(",")]
    except ValueError:
        raise TrainerInputError(f"--adapt-band: expected MIN,MAX fractions, got {text!r}") from None
    if len(parts) == 1:
        parts = parts * 2
    if len(parts) != 2:
        raise TrainerInputError(f"--adapt-band: expected MIN,MAX fractions, got {text!r}")
    return parts[0], parts[1]
