"""The operating threshold of a model, chosen on validation labels and stored with it.

A site team has no test labels, so the threshold a model is used and scored at
must come from data set aside for choosing: the best-F1 threshold of the
validation histogram (lowest on ties). It is stored in the checkpoint under
``val_threshold`` with what it was chosen on; ``predict`` and ``evaluate`` use it
by default and ``benchmark`` scores every set at it. Any change of the weights
or of BatchNorm statistics (``adapt-bn``) drops it: the new model is chosen anew.
"""
from __future__ import annotations

from pathlib import Path
from typing import Any

from trainer.core.checkpoint import load_checkpoint, save_checkpoint
from trainer.seg.metrics import ConfusionHistogram

THRESHOLD_KEY = "val_threshold"
DEFAULT_THRESHOLD = 0.5


def threshold_record(best: dict[str, Any], chosen_on: str, photos: int) -> dict[str, Any]:
    """The stored record of a best-F1 point on validation (``ConfusionHistogram.best()``): its scores there
    and what it was chosen on."""
    return {"threshold": best["threshold"], "val_f1": best["f1"], "val_precision": best["precision"],
            "val_recall": best["recall"], "chosen_on": chosen_on, "photos": int(photos)}


def choose_threshold(val: ConfusionHistogram, chosen_on: str, photos: int) -> dict[str, Any]:
    """The best-F1 threshold of a validation histogram (lowest on ties), as a record."""
    return threshold_record(val.best(), chosen_on, photos)


def stored_threshold(ckpt: dict[str, Any]) -> dict[str, Any] | None:
    """The ``val_threshold`` record of a loaded checkpoint, or None when it was never chosen."""
    rec = ckpt.get(THRESHOLD_KEY)
    return rec if isinstance(rec, dict) and "threshold" in rec else None


def store_threshold(path: str | Path, record: dict[str, Any]) -> None:
    """Write the record into the checkpoint file (atomically, like every checkpoint write)."""
    ckpt = load_checkpoint(path)
    ckpt[THRESHOLD_KEY] = record
    save_checkpoint(path, ckpt)


def operating_threshold(ckpt: dict[str, Any], given: float | None) -> tuple[float, str]:
    """(threshold, where it came from): ``given`` on the command line, else the stored validation choice,
    else 0.5."""
    if given is not None:
        return float(given), "--threshold"
    rec = stored_threshold(ckpt)
    if rec is not None:
        return float(rec["threshold"]), f"validation ({rec['chosen_on']})"
    return DEFAULT_THRESHOLD, "default 0.5 (no validation threshold stored)"
