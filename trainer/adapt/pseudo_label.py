"""Pseudo-labels for a site's unlabeled photos: class-balanced self-training (Zou et al. 2018, CBST).

Why: a model trained on renders already finds most cracks on real photos, but it has
never seen the site's texture. Its *most confident* predictions on the site's own photos
are mostly right; training on them beside the renders (which keep the crack shapes
anchored) shows the model that texture without a single label. Uncertain pixels are
written as ignored, never as background, so the student is not taught the teacher's
doubts.

How: the teacher (by default with target BatchNorm first, ``trainer.seg.target_bn``, so that
0.5 is a sensible operating point on the photos) predicts every photo at native size. A
pixel is predicted crack when p >= 0.5. Per class, the threshold is the (1 - portion)
quantile of that class's confidence (p for crack, 1 - p for background) over all photos,
so each class keeps its most confident ``portion`` whatever its size (the class balance
of CBST: a global threshold would keep almost no crack pixels). Everything else is ignored.

The folder written is a real folder (``images/``, ``masks/``, ``ignore/``) that ``seg --real``
reads like any other, plus ``pseudo_labels.json`` with the settings and the shares.
"""
from __future__ import annotations

import argparse
import json
import shutil
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any, Sequence

import cv2
import numpy as np
import torch
from tqdm import tqdm

from trainer.core.errors import TrainerInputError
from trainer.core.imageio import read_rgb
from trainer.seg.scoring import load_model, predict_probability
from trainer.seg.target_bn import DEFAULT_BATCHES, adapt_bn_to_photos

RECORD = "pseudo_labels.json"
QUANTILE_SAMPLE = 2_000_000  # pixels (about) used for the class quantiles: a strided subsample of every photo
PROB_DIR = "_prob"  # the teacher's probabilities between the two passes (removed before the folder is finished)


@dataclass(frozen=True)
class PseudoSettings:
    """What decides the labels; a folder made with other settings is never reused."""

    teacher: str
    portion: float = 0.5  # share of the predicted crack pixels kept as crack labels
    background_portion: float | None = None  # share of the predicted background kept (None: ``portion``)
    target_bn: bool = True  # re-estimate the teacher's BN statistics on the photos first
    bn_batches: int = DEFAULT_BATCHES
    batch_size: int = 8
    crop: int | None = None  # target-BN crop (default: the teacher's training crop)
    seed: int = 0

    def __post_init__(self) -> None:
        if not 0.0 < self.portion <= 1.0:
            raise TrainerInputError(f"--portion must be in (0, 1], got {self.portion}")
        if self.background_portion is not None and not 0.0 < self.background_portion <= 1.0:
            raise TrainerInputError(f"--background-portion must be in (0, 1], got {self.background_portion}")


def _quantile(values: list[np.ndarray], q: float) -> float:
    """q-quantile of the concatenated values (strided subsample beyond QUANTILE_SAMPLE); inf when empty."""
    allv = np.concatenate([v.ravel() for v in values]) if values else np.empty(0, np.float32)
    if allv.size == 0:
        return float("inf")
    step = max(1, allv.size // QUANTILE_SAMPLE)
    return float(np.quantile(allv[::step].astype(np.float64), q))


def class_thresholds(probs: Sequence[np.ndarray], portion: float,
                     background_portion: float | None = None) -> tuple[float, float]:
    """(t_crack, t_background): crack where p >= t_crack, background where 1 - p >= t_background.

    Each class keeps its most confident share (``portion``; ``background_portion`` for the
    background, default the same) of the pixels predicted as that class."""
    crack = [p[p >= 0.5] for p in probs]
    back = [1.0 - p[p < 0.5] for p in probs]
    bp = portion if background_portion is None else background_portion
    return _quantile(crack, 1.0 - portion), _quantile(back, 1.0 - bp)


def label_maps(prob: np.ndarray, t_crack: float, t_background: float) -> tuple[np.ndarray, np.ndarray]:
    """(mask, ignore) as uint8 0/255: confident crack, and everything neither confident crack nor background."""
    crack = (prob >= 0.5) & (prob >= t_crack)
    background = (prob < 0.5) & (1.0 - prob >= t_background)
    return (crack * np.uint8(255)), (~(crack | background) * np.uint8(255))


def _write_png(path: Path, img: np.ndarray) -> None:
    if not cv2.imwrite(str(path), img):
        raise TrainerInputError(f"pseudo-label: cannot write {path}")


def _unique_stems(photos: Sequence[str | Path]) -> list[Path]:
    paths = [Path(p) for p in photos]
    seen: dict[str, Path] = {}
    for p in paths:
        if p.stem in seen:
            raise TrainerInputError(f"pseudo-label: {seen[p.stem]} and {p} share the name '{p.stem}'; "
                                    "rename one (labels are stored by name)")
        seen[p.stem] = p
    return paths


def finished_record(out: Path, settings: PseudoSettings, n_photos: int) -> dict[str, Any] | None:
    """The record of a finished folder made with these settings and as many photos, else None."""
    rec_path = out / RECORD
    if not rec_path.is_file():
        return None
    rec = json.loads(rec_path.read_text())
    if rec.get("settings") == asdict(settings) and rec.get("photos") == n_photos:
        return rec
    return None


def write_pseudo_folder(photos: Sequence[str | Path], out: str | Path, settings: PseudoSettings,
                        device: torch.device, *, workers: int = 0, progress: bool = True) -> dict[str, Any]:
    """Pseudo-label ``photos`` with the teacher and write a real folder at ``out``; returns the record.

    A finished folder with the same settings is kept as it is. Any other existing ``out`` is refused,
    and the folder appears only when complete (written beside it, then renamed), so an interrupted
    run leaves nothing that looks finished."""
    out = Path(out)
    paths = _unique_stems(photos)
    if not paths:
        raise TrainerInputError("pseudo-label: no target photos")
    done = finished_record(out, settings, len(paths))
    if done is not None:
        return done
    if out.exists():
        raise TrainerInputError(f"pseudo-label: {out} already exists and was made otherwise; use a new --out")
    model, cfg, train_args = load_model(settings.teacher, device)
    if cfg.channels != "rgb":
        raise TrainerInputError(f"pseudo-label: {settings.teacher} takes {cfg.channels}; photos have no depth (RGB model needed)")
    crop = settings.crop or train_args.get("crop")
    if settings.target_bn:
        adapt_bn_to_photos(model, paths, cfg, device, crop=crop, batches=settings.bn_batches,
                           batch_size=settings.batch_size, workers=workers, seed=settings.seed)
    model.eval()
    tmp = out.with_name(out.name + ".partial")
    if tmp.exists():
        shutil.rmtree(tmp)
    for sub in ("images", "masks", "ignore", PROB_DIR):
        (tmp / sub).mkdir(parents=True)
    # pass 1: probabilities to disk (16-bit PNG) and a bounded subsample for the class quantiles,
    # so memory does not grow with the number of photos (a site may have thousands)
    sample: list[np.ndarray] = []
    for path in tqdm(paths, desc="pseudo-label: predict", disable=not progress):
        q = np.round(predict_probability(model, cfg, {"key": path.stem, "rgb": read_rgb(path), "mask": None}, device) * 65535.0).astype(np.uint16)
        _write_png(tmp / PROB_DIR / f"{path.stem}.png", q)
        sample.append(q.ravel()[:: max(1, q.size * len(paths) // QUANTILE_SAMPLE)].astype(np.float32) / 65535.0)
    t_crack, t_back = class_thresholds(sample, settings.portion, settings.background_portion)
    del sample
    # pass 2: labels from the stored probabilities
    n_px = n_crack = n_ignore = n_pred = 0
    for path in tqdm(paths, desc="pseudo-label: write", disable=not progress):
        prob = cv2.imread(str(tmp / PROB_DIR / f"{path.stem}.png"), cv2.IMREAD_UNCHANGED).astype(np.float32) / 65535.0
        mask, ignore = label_maps(prob, t_crack, t_back)
        shutil.copy2(path, tmp / "images" / path.name)
        _write_png(tmp / "masks" / f"{path.stem}.png", mask)
        _write_png(tmp / "ignore" / f"{path.stem}.png", ignore)
        n_px += prob.size
        n_crack += int((mask > 0).sum())
        n_ignore += int((ignore > 0).sum())
        n_pred += int((prob >= 0.5).sum())
    shutil.rmtree(tmp / PROB_DIR)
    record = {"settings": asdict(settings), "photos": len(paths), "crop": crop,
              "threshold_crack": t_crack, "threshold_background": t_back,
              "predicted_crack_fraction": n_pred / n_px, "crack_fraction": n_crack / n_px,
              "background_fraction": 1.0 - (n_crack + n_ignore) / n_px, "ignored_fraction": n_ignore / n_px}
    (tmp / RECORD).write_text(json.dumps(record, indent=2))
    tmp.rename(out)
    return record


def add_pseudo_label_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", "-c", default=None,
                   help="trained cracktrain checkpoint (RGB model), e.g. a synthetic-only model")
    p.add_argument("model", nargs="?", default=None, help=argparse.SUPPRESS)  # old positional, deprecated
    p.add_argument("--target", required=True, metavar="FOLDER", help="folder of unlabeled photos of the site")
    p.add_argument("--out", required=True, metavar="FOLDER", help="new real folder: images/, masks/, ignore/")
    p.add_argument("--portion", type=float, default=0.5, help="share of the predicted crack pixels kept as labels")
    p.add_argument("--background-portion", type=float, default=None,
                   help="share of the predicted background kept as labels (default: --portion)")
    p.add_argument("--no-target-bn", dest="target_bn", action="store_false",
                   help="predict with the teacher's own BN statistics (default: re-estimated on the photos)")
    p.add_argument("--batches", type=int, default=DEFAULT_BATCHES, help="target BN: batches of photo crops averaged")
    p.add_argument("--batch-size", "-b", type=int, default=8)
    p.add_argument("--crop", type=int, default=None, help="target BN crop (px; default: the model's training crop)")
    p.add_argument("--workers", "-j", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default=None)
    p.add_argument("--no-progress", action="store_true")


__all__ = ["PseudoSettings", "class_thresholds", "label_maps", "write_pseudo_folder",
           "finished_record", "add_pseudo_label_args", "RECORD"]
