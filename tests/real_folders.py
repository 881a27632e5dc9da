"""A tiny real-style images/ + masks/ folder (dark horizontal crack on a grey photo), for trainer tests."""
from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def write_real_folder(root: Path, n: int = 8) -> Path:
    """``n`` 64x48 photos with one 3-px dark crack each and their 0/255 masks; returns ``root``."""
    (root / "images").mkdir(parents=True)
    (root / "masks").mkdir()
    rng = np.random.default_rng(0)
    for i in range(n):
        img = (rng.random((48, 64, 3)) * 60 + 100).astype(np.uint8)
        m = np.zeros((48, 64), np.uint8)
        r = int(rng.integers(5, 40))
        m[r:r + 3, 4:60] = 255
        img[m > 0] = 20
        cv2.imwrite(str(root / f"images/{i:03d}.png"), img)
        cv2.imwrite(str(root / f"masks/{i:03d}.png"), m)
    return root


def train_tiny_model(base: Path) -> dict[str, Path]:
    """A 2-step U-Net trained on a fresh 8-photo folder under ``base``: {"real", "ckpt", "base"}."""
    from trainer.cli import main  # local: keeps this module importable without torch

    real = write_real_folder(base / "real", n=8)
    run = base / "run"
    assert main(["seg", "--real", str(real), "--arch", "unet", "-b", "2", "--crop", "32", "-j", "0",
                 "--no-progress", "--max-steps", "2", "--out", str(run)]) == 0
    return {"real": real, "ckpt": run / "checkpoint.pt", "base": base}
