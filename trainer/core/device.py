"""The torch device a command runs on: the one asked for, else CUDA when present, else the CPU."""
from __future__ import annotations

import torch


def pick_device(name: str | None = None) -> torch.device:
    return torch.device(name or ("cuda" if torch.cuda.is_available() else "cpu"))
