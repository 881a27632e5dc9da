"""``cracktrain predict``: real photos (optionally + depth) -> masks, overlays, crack length.

Per image it writes ``STEM_prob.png`` (probability x 255), ``STEM_mask.png``
(0/255), ``STEM_overlay.png`` (crack pixels tinted red) and ``STEM.json`` with
the crack pixel count and the crack length from ``fusion.crack_length``
(geodesic skeleton diameter). Length is in pixels unless ``--pixel-size-m``
gives a metric scale (metres per pixel on a fronto-parallel surface).

``OUT/report.json`` holds ``{"predicted": [per-image reports], "skipped":
[{"image": path, "reason": one line}]}``; inputs are skipped (instead of
stopping the run) only with ``--skip-bad``.
"""
from __future__ import annotations

import argparse
import json
import logging
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import cv2
import numpy as np
import torch
from tqdm import tqdm

from trainer.augment import sample_to_tensors
from trainer.builders import add_data_args, real_folder
from trainer.errors import TrainerInputError
from trainer.evaluate import _inherit_depth, load_model

log = logging.getLogger(__name__)
REPORT_NAME = "report.json"


def add_predict_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("input", help="folder with images/ (+ depth subfolder) or a folder of images")
    p.add_argument("--checkpoint", "-c", required=True)
    p.add_argument("--out", required=True)
    p.add_argument("--threshold", type=float, default=0.5)
    p.add_argument("--pixel-size-m", type=float, default=None, help="metres per pixel, for lengths in metres")
    p.add_argument("--min-length", type=float, default=0.0, help="ignore cracks shorter than this (report units)")
    p.add_argument("--device", default=None)
    p.add_argument("--no-progress", action="store_true")
    add_data_args(p)


def overlay(rgb: np.ndarray, mask: np.ndarray, alpha: float = 0.6) -> np.ndarray:
    out = rgb.astype(np.float32).copy()
    red = np.array([255, 0, 0], np.float32)
    m = mask > 0
    out[m] = (1 - alpha) * out[m] + alpha * red
    return out.astype(np.uint8)


@dataclass
class PredictResult:
    """What ``run_predict`` did: per-image reports, skipped inputs with reasons, and the report file."""

    report: Path
    predicted: list[dict[str, Any]] = field(default_factory=list)
    skipped: list[dict[str, str]] = field(default_factory=list)

    def summary(self) -> str:
        """One line for the CLI, counting predicted and skipped inputs separately."""
        return f"{len(self.predicted)} predicted, {len(self.skipped)} skipped (see {self.report})"


def run_predict(args: argparse.Namespace) -> PredictResult:
    from fusion.crack_length import crack_length  # pure numpy/scipy

    device = torch.device(args.device or ("cuda" if torch.cuda.is_available() else "cpu"))
    model, cfg, train_args = load_model(args.checkpoint, device)
    _inherit_depth(args, train_args, cfg)
    root = Path(args.input)
    if not root.is_dir():
        raise TrainerInputError(f"input folder {root} does not exist")
    if not (root / args.image_dir).is_dir():  # a flat folder of photos
        args.image_dir = "."
    folder = real_folder(args, root, require_masks=False)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    result = PredictResult(report=out / REPORT_NAME)
    for key in tqdm(folder.keys, desc="predict", disable=args.no_progress):
        try:
            sample = folder.load(key)
        except TrainerInputError as exc:
            if not args.skip_bad:
                raise
            log.warning("skipped: %s", exc)
            result.skipped.append({"image": str(folder.image_path(key)), "reason": str(exc)})
            continue
        t = sample_to_tensors(sample, cfg)
        with torch.no_grad():
            logits = model(t["image"][None].to(device))
        H, W = sample["rgb"].shape[:2]
        if logits.shape[-2:] != (H, W):
            logits = torch.nn.functional.interpolate(logits, size=(H, W), mode="bilinear", align_corners=False)
        prob = torch.sigmoid(logits)[0, 0].cpu().numpy()
        mask = (prob >= args.threshold).astype(np.uint8) * 255
        cv2.imwrite(str(out / f"{key}_prob.png"), np.round(prob * 255).astype(np.uint8))
        cv2.imwrite(str(out / f"{key}_mask.png"), mask)
        cv2.imwrite(str(out / f"{key}_overlay.png"), cv2.cvtColor(overlay(sample["rgb"], mask), cv2.COLOR_RGB2BGR))
        unit = "m" if args.pixel_size_m else "px"
        length = crack_length(mask > 0, args.pixel_size_m, min_length=args.min_length) if mask.any() else 0.0
        rep = {"image": sample["path"], "threshold": args.threshold, "crack_pixels": int((mask > 0).sum()),
               "crack_fraction": float((mask > 0).mean()), "crack_length": float(length), "length_unit": unit,
               "max_probability": float(prob.max())}
        (out / f"{key}.json").write_text(json.dumps(rep, indent=2))
        result.predicted.append(rep)
    result.report.write_text(json.dumps({"predicted": result.predicted, "skipped": result.skipped}, indent=2))
    if not result.predicted:
        raise TrainerInputError(f"{root}: none of {len(result.skipped)} image(s) could be read (see {result.report})")
    return result
