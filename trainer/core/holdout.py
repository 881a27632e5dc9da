"""Seeded hold-out splits of names and keys: they depend on the names, the fraction and the seed, never on file order.

Shared by segmentation and depth fusion, so neither needs the other's data code.
"""
from __future__ import annotations

import hashlib
from typing import Sequence

import numpy as np

from trainer.core.errors import TrainerInputError


def split_fraction(names: Sequence[str], fraction: float, seed: int) -> tuple[list[str], list[str]]:
    """Deterministic (rest, held_out) split of a name list: seeded permutation of the sorted names.

    The result depends only on the set of names, the fraction and the seed,
    never on file-system order.
    """
    if not 0.0 <= fraction < 1.0:
        raise TrainerInputError(f"split fraction must be in [0, 1), got {fraction}")
    ordered = sorted(names)
    perm = np.random.default_rng(np.random.SeedSequence([seed, 0x5EED])).permutation(len(ordered))
    n_out = int(round(fraction * len(ordered)))
    out = sorted(ordered[i] for i in perm[:n_out])
    rest = sorted(ordered[i] for i in perm[n_out:])
    return rest, out


def key_in_val(key: str, fraction: float, seed: int) -> bool:
    """Streaming-friendly split: a key is validation when its seeded hash < fraction."""
    h = hashlib.blake2b(f"{seed}:{key}".encode(), digest_size=8).digest()
    return int.from_bytes(h, "little") / 2.0**64 < fraction
