"""Seeded hold-out splits of names and keys: they depend on the names, the fraction and the seed, never on file order.

Shared by segmentation and depth fusion, so neither needs the other's data code.
"""
from __future__ import annotations

import hashlib
from pathlib import Path
from typing import Callable, Sequence

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


def split_fraction_by_group(names: Sequence[str], group_of: Callable[[str], str], fraction: float,
                            seed: int) -> tuple[list[str], list[str]]:
    """``split_fraction`` over the groups of ``names`` (views of one scene, tiles of one photo): a group is
    held out whole. With every name its own group the result is ``split_fraction(names, ...)``."""
    groups = {n: group_of(n) for n in names}
    _, out_groups = split_fraction(sorted(set(groups.values())), fraction, seed)
    out = set(out_groups)
    return sorted(n for n in names if groups[n] not in out), sorted(n for n in names if groups[n] in out)


def shard_groups(path: str | Path) -> Callable[[str], str]:
    """The hold-out group of each sample key of a shard dataset: its scene when the recipe rendered several
    views per scene (the manifest says), else the key itself."""
    from crackgen.shards import ManifestError, scene_group, views_per_scene

    try:
        k = views_per_scene(path) if Path(path).is_dir() else 1
    except ManifestError as exc:
        raise TrainerInputError(str(exc)) from None
    return lambda key: scene_group(key, k)
