"""What a model gets wrong on a labelled set: overlays of its worst images and a summary of its false positives.

Why: an F1 says how much is wrong, not what. Per image the prediction at the model's operating
threshold is compared with the label; the images with the most false-positive pixels are written
as overlays (true positives green, false positives red, missed crack blue), and the false-positive
components are described by what a reader would look for: line-like (elongated, like a joint, an
edge or a crack) or blob-like (pores, stains), and darker or brighter than the surface around them.
"""
from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

import cv2
import numpy as np

from trainer.seg.sources import RealFolder

ELONGATED = 4.0  # a component this many times longer than wide is line-like


@dataclass
class ImageErrors:
    key: str
    tp: int
    fp: int
    fn: int


def error_overlay(rgb: np.ndarray, pred: np.ndarray, label: np.ndarray, alpha: float = 0.6) -> np.ndarray:
    """RGB with true positives green, false positives red and missed crack pixels blue."""
    out = rgb.astype(np.float32).copy()
    for sel, colour in (((pred & label), (0, 255, 0)), ((pred & ~label), (255, 0, 0)), ((~pred & label), (0, 80, 255))):
        out[sel] = (1 - alpha) * out[sel] + alpha * np.asarray(colour, np.float32)
    return out.astype(np.uint8)


def component_shapes(mask: np.ndarray, grey: np.ndarray) -> list[dict[str, float]]:
    """Each 8-connected component of ``mask``: pixels, elongation (length / width of its principal axes) and
    contrast (its median luma against the median of a 3-px ring around it; > 0 = darker than its surround)."""
    n, lab = cv2.connectedComponents(mask.astype(np.uint8), connectivity=8)
    out = []
    kernel = np.ones((7, 7), np.uint8)
    for k in range(1, n):
        comp = lab == k
        ys, xs = np.nonzero(comp)
        if ys.size >= 3:
            ev = np.linalg.eigvalsh(np.cov(np.stack([xs, ys]).astype(np.float64)) + 1e-3 * np.eye(2))
            elong = float(np.sqrt(ev[1] / ev[0]))
        else:
            elong = 1.0
        ring = (cv2.dilate(comp.astype(np.uint8), kernel) > 0) & ~comp
        inside, around = float(np.median(grey[comp])), float(np.median(grey[ring])) if ring.any() else float("nan")
        out.append({"pixels": int(ys.size), "elongation": elong,
                    "contrast": (around - inside) / around if around > 0 else 0.0})
    return out


def describe_errors(
    folder: RealFolder, probability: Callable[[dict[str, Any]], np.ndarray], threshold: float,
    out_dir: Path | None = None, worst: int = 6,
) -> dict[str, Any]:
    """Errors of one model on ``folder`` at ``threshold``; writes the ``worst`` images by false-positive pixels
    to ``out_dir`` (overlays side by side with the photo) when given."""
    per: list[ImageErrors] = []
    fp_components: list[dict[str, float]] = []
    kept: list[tuple[int, str, np.ndarray]] = []
    for key in folder.keys:
        s = folder.load(key)
        pred = probability(s) >= threshold
        label = s["mask"] > 127
        grey = cv2.cvtColor(s["rgb"], cv2.COLOR_RGB2GRAY).astype(np.float64)
        fp = pred & ~label
        per.append(ImageErrors(key, int((pred & label).sum()), int(fp.sum()), int((~pred & label).sum())))
        fp_components += component_shapes(fp, grey)
        if out_dir is not None and fp.any():
            kept.append((int(fp.sum()), key, np.hstack([s["rgb"], error_overlay(s["rgb"], pred, label)])))
            kept = sorted(kept, key=lambda t: -t[0])[:worst]  # only the worst few stay in memory
    written = []
    if out_dir is not None:
        out_dir.mkdir(parents=True, exist_ok=True)
        for rank, (_, key, img) in enumerate(kept):
            path = out_dir / f"{rank:02d}_{key}.png"
            cv2.imwrite(str(path), cv2.cvtColor(img, cv2.COLOR_RGB2BGR))
            written.append(str(path))
    fp_px = sum(c["pixels"] for c in fp_components)

    def share(sel: Callable[[dict[str, float]], bool]) -> float:
        return sum(c["pixels"] for c in fp_components if sel(c)) / fp_px if fp_px else 0.0

    return {
        "images": len(per), "tp": sum(e.tp for e in per), "fp": sum(e.fp for e in per), "fn": sum(e.fn for e in per),
        "images_with_fp": sum(e.fp > 0 for e in per),
        "fp_components": len(fp_components),
        "fp_line_like": share(lambda c: c["elongation"] >= ELONGATED),
        "fp_darker_than_surround": share(lambda c: c["contrast"] > 0.05),
        "fp_brighter_than_surround": share(lambda c: c["contrast"] < -0.05),
        "worst": [e.key for e in sorted(per, key=lambda e: -e.fp)[:worst]],
        "overlays": written,
    }
