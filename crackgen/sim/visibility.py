"""Does the labelled crack show in the render? A luminance contrast check and what to do if not.

Why a ring contrast: a person calls a crack visible when its pixels are darker than the
surface right next to it. So we compare the median luminance inside the label with the
median of a thin ring around it (dilate(label, ring_px) minus label), on the clean
render (before camera effects or adaptation, so the check is the same whatever they do):

    contrast = (median ring luminance - median inside luminance) / median ring luminance

1 = black crack on a lit surface, 0 = no difference, < 0 = crack brighter than its rim.
Luminance is Rec. 709 luma of the 8-bit sRGB values (what is displayed), in [0, 1].
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from crackgen.errors import CrackgenError

__all__ = ["VisibilityError", "luminance", "ring", "label_contrast", "LabelDecision", "decide_label"]

RING_PX = 2  # ring width (camera px) around the label
LUMA = np.array([0.2126, 0.7152, 0.0722], np.float64)


class VisibilityError(CrackgenError, ValueError):
    """Bad arguments to the visibility check (names the argument)."""


def luminance(rgb: np.ndarray) -> np.ndarray:
    """(H, W) float64 luma in [0, 1] of an 8-bit (H, W, 3) RGB image."""
    a = np.asarray(rgb)
    if a.ndim != 3 or a.shape[2] != 3:
        raise VisibilityError(f"rgb must be (H, W, 3), got {a.shape}")
    return (a.astype(np.float64) / 255.0) @ LUMA


def ring(label: np.ndarray, ring_px: int = RING_PX) -> np.ndarray:
    """Bool (H, W): pixels within ``ring_px`` (chessboard) of the label, not in it."""
    on = np.asarray(label) > 0
    k = np.ones((2 * int(ring_px) + 1,) * 2, np.uint8)
    return (cv2.dilate(on.astype(np.uint8), k) > 0) & ~on


def label_contrast(rgb: np.ndarray, label: np.ndarray, ring_px: int = RING_PX) -> float | None:
    """Ring-vs-inside luminance contrast (see module doc); None when the label or its ring is empty."""
    lum = luminance(rgb)
    on = np.asarray(label) > 0
    if on.shape != lum.shape:
        raise VisibilityError(f"label {on.shape} must match the rgb's {lum.shape}")
    rg = ring(on, ring_px)
    if not on.any() or not rg.any():
        return None
    outside = float(np.median(lum[rg]))
    inside = float(np.median(lum[on]))
    if outside <= 0:
        return 0.0
    return (outside - inside) / outside


@dataclass
class LabelDecision:
    """What happens to a sample's label: ``action`` is ok | empty | keep | redraw."""

    action: str
    shows: bool  # the crack shows (or there is no crack in view)

    @property
    def label_emptied(self) -> bool:
        return self.action == "empty"


def decide_label(has_crack: bool, label_px: int, contrast: float | None, *, min_contrast: float,
                 invisible: str, attempt: int, max_redraws: int) -> LabelDecision:
    """Decide a sample's fate from its check.

    A crack that is in view (``has_crack``: the thesis mask has pixels) does not show when its
    label is empty or its contrast is below ``min_contrast``. Then ``invisible`` says what to do:
    ``empty`` (clear the label: a hard negative), ``keep``, or ``redraw`` (a new crack, up to
    ``max_redraws`` times, then empty). A view without any crack is a plain negative: ok.
    """
    if invisible not in ("empty", "redraw", "keep"):
        raise VisibilityError(f"label.invisible must be empty, redraw or keep, got {invisible!r}")
    shows = (not has_crack) or (label_px > 0 and contrast is not None and contrast >= min_contrast)
    if shows:
        return LabelDecision("ok", True)
    if invisible == "keep":
        return LabelDecision("keep", False)
    if invisible == "redraw" and attempt < max_redraws:
        return LabelDecision("redraw", False)
    return LabelDecision("empty", False)
