"""Small shard datasets written without Blender, for trainer and tool tests.

Why a shared helper: several tests need real shards (the writer's tar format and
manifest-free listing) with known pixels, and rendering them would need bpy.
Samples come from ``crackgen.tools.bench_shards.synthetic_sample`` (every member,
render-like statistics, sparse maps mostly -1).
"""
from __future__ import annotations

from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from crackgen.shards import ShardWriter, sample_key
from crackgen.tools.bench_shards import synthetic_sample

DEFAULT_MEMBERS = ("rgb.png", "mask.png", "depth.exr", "tof.exr", "json")


def write_shards(root: Path, n_shards: int = 2, per_shard: int = 4, size_px: int = 48, tof_px: int = 16,
                 members: Sequence[str] = DEFAULT_MEMBERS, seed: int = 1,
                 extra: Mapping[str, Callable[[dict[str, Any]], Any]] | None = None) -> Path:
    """Write ``n_shards`` x ``per_shard`` synthetic samples under ``root`` (shard-NNNNNN.tar); returns ``root``.

    ``extra`` adds members made from each sample, e.g. ``{"mask_thesis.png": lambda s: ...}``.
    """
    rng = np.random.default_rng(seed)
    for s in range(n_shards):
        with ShardWriter(root, s) as w:
            for i in range(per_shard):
                smp = synthetic_sample(rng, size_px, tof_px)
                members_out = {k: smp[k] for k in members}
                for name, make in (extra or {}).items():
                    members_out[name] = make(smp)
                w.add(sample_key(s, i), members_out)
    return root
