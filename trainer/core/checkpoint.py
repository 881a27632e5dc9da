"""Checkpoints in the torchvision-references layout, plus what exact resume needs.

Keys: model, optimizer, lr_scheduler, scaler, epoch, batch_in_epoch, step,
args, sample_config, rng (torch CPU, CUDA, Python), best (validation record).
The data order and augmentation need no stored generator state: they are pure
functions of (seed, epoch, sample id) (see ``trainer.seg.stream``); ``epoch`` and
``batch_in_epoch`` say where to continue. Files are written to a temporary
name and renamed, so a kill never leaves a half-written checkpoint.
"""
from __future__ import annotations

import os
import random
from pathlib import Path
from typing import Any

import torch

from trainer.core.errors import TrainerInputError

REQUIRED = ("model", "args", "sample_config")


def rng_state() -> dict[str, Any]:
    return {
        "torch": torch.get_rng_state(),
        "cuda": torch.cuda.get_rng_state_all() if torch.cuda.is_available() else [],
        "python": random.getstate(),
    }


def set_rng_state(state: dict[str, Any]) -> None:
    torch.set_rng_state(state["torch"])
    if state.get("cuda") and torch.cuda.is_available():
        torch.cuda.set_rng_state_all(state["cuda"])
    if state.get("python") is not None:
        random.setstate(state["python"])


def save_checkpoint(path: str | Path, payload: dict[str, Any]) -> None:
    path = Path(path)
    tmp = path.with_name(path.name + ".tmp")
    torch.save(payload, tmp)
    os.replace(tmp, path)


def load_checkpoint(path: str | Path) -> dict[str, Any]:
    """Load on CPU and check the keys; a bad file is a one-line TrainerInputError."""
    path = Path(path)
    if not path.is_file():
        raise TrainerInputError(f"checkpoint {path} does not exist")
    try:
        ckpt = torch.load(path, map_location="cpu", weights_only=False)
    except Exception as exc:
        raise TrainerInputError(f"checkpoint {path} is unreadable: {type(exc).__name__}: {str(exc)[:200]}") from None
    if not isinstance(ckpt, dict) or any(k not in ckpt for k in REQUIRED):
        raise TrainerInputError(f"checkpoint {path} is not a cracktrain checkpoint (needs keys {REQUIRED})")
    return ckpt


def steps_seen(ckpt: dict[str, Any]) -> int:
    """Every step a checkpoint's weights have seen: its own, plus those of its ``--init`` chain."""
    return int(ckpt.get("step", 0)) + int(ckpt.get("args", {}).get("init_steps", 0) or 0)
