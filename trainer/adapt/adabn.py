"""``cracktrain adapt-bn``: a trained model's BatchNorm statistics moved to a site's unlabeled photos.

For a model that already exists (a shipped synthetic model, a finished ``sim2real`` row):
the weights are copied unchanged, the BN running statistics are re-estimated on the
photos (``trainer.seg.target_bn``), and the result is written as a new checkpoint that
``evaluate``/``predict`` read like any other. The source checkpoint is never modified.
"""
from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any, Sequence

import torch

from trainer.core.checkpoint import load_checkpoint, save_checkpoint
from trainer.core.errors import TrainerInputError
from trainer.seg.scoring import load_model
from trainer.seg.target_bn import DEFAULT_BATCHES, adapt_bn_to_photos

# What a BN-adapted checkpoint keeps of its source: enough to evaluate, predict and fine-tune (--init) from it.
KEPT_KEYS = ("args", "sample_config", "step", "epoch", "best", "world_size")


def add_adapt_bn_args(p: argparse.ArgumentParser) -> None:
    p.add_argument("--checkpoint", "-c", default=None, help="trained cracktrain checkpoint (RGB model)")
    p.add_argument("model", nargs="?", default=None, help=argparse.SUPPRESS)  # old positional, deprecated
    p.add_argument("--target", required=True, metavar="FOLDER", help="folder of unlabeled photos of the site")
    p.add_argument("--out", required=True, metavar="CKPT", help="new checkpoint to write (must differ from the source)")
    p.add_argument("--batches", type=int, default=DEFAULT_BATCHES, help="batches of photo crops averaged")
    p.add_argument("--batch-size", "-b", type=int, default=8)
    p.add_argument("--crop", type=int, default=None, help="crop size (px; default: the model's training crop)")
    p.add_argument("--workers", "-j", type=int, default=2)
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--device", default=None)


def adapt_checkpoint(src: str | Path, dst: str | Path, photos: Sequence[str], device: torch.device, *,
                     target: str, batches: int = DEFAULT_BATCHES, batch_size: int = 8, crop: int | None = None,
                     workers: int = 0, seed: int = 0) -> dict[str, Any]:
    """Write ``dst``: ``src``'s weights with BN statistics from ``photos``. Returns the record stored under
    ``target_bn`` in the new checkpoint."""
    src, dst = Path(src), Path(dst)
    if dst.resolve() == src.resolve():
        raise TrainerInputError(f"--out {dst} is the source checkpoint; write the adapted model elsewhere")
    ckpt = load_checkpoint(src)
    model, cfg, train_args = load_model(src, device)
    crop = crop if crop is not None else (ckpt["sample_config"].get("crop") or train_args.get("crop"))
    used = adapt_bn_to_photos(model, photos, cfg, device, crop=crop, batches=batches, batch_size=batch_size,
                              workers=workers, seed=seed)
    record = {"source": str(src), "target": target, "photos": len(photos), "batches": used,
              "batch_size": batch_size, "crop": crop, "seed": seed}
    payload = {k: ckpt[k] for k in KEPT_KEYS if k in ckpt}
    payload |= {"model": {k: v.cpu() for k, v in model.state_dict().items()}, "finished": True, "target_bn": record}
    dst.parent.mkdir(parents=True, exist_ok=True)
    save_checkpoint(dst, payload)
    return record
