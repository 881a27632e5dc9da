"""``crackgen verify``: check a whole dataset and say, one line per shard, what is wrong.

Why apart from the reader: reading stops at the first bad shard (a trainer must not
train on half a dataset), whereas verifying goes on and reports every problem —
missing or failed shards, size or sha256 different from the manifest, truncated
tars, members that do not decode, sample counts that disagree.
"""
from __future__ import annotations

import os
from typing import Any, Mapping

from crackgen.shards.errors import ShardError
from crackgen.shards.manifest import Manifest, ManifestError
from crackgen.shards.reader import ShardRef, expand_paths, iter_shard, shard_refs


def verify_dataset(path: Any, decode: bool = True,
                   storage_options: Mapping[str, Any] | None = None) -> list[str]:
    """One problem line per bad shard (missing, truncated, sha mismatch, unreadable member, failed).

    With a manifest every planned shard is checked (size + sha256) and, with
    ``decode``, every member is decoded; without one each ``shard-*.tar`` is read
    through. An empty list means the dataset is sound.
    """
    problems: list[str] = []
    so = dict(storage_options or {})
    root = None if expand_paths(path) is not None else os.fspath(path)
    if root is not None and Manifest.exists(root, so):
        try:
            m = Manifest.load(root, so)
        except ManifestError as exc:
            return [str(exc)]
        indices = sorted(set(range(m.num_shards)) | {r.index for r in m.shards})
        good = []
        for i in indices:
            p = m.problem(i, verify=True)
            if p is None:
                r = m.shard(i)
                good.append(ShardRef(m.url(r.name), r.sha256, r.bytes, r.samples))
            else:
                problems.append(p)
        refs = good
    else:
        try:
            refs = shard_refs(path, so)
        except ShardError as exc:
            return [str(exc)]
        if not refs:
            return [f"{path}: no shards found"]
    for ref in refs:
        try:
            n = 0
            for _ in iter_shard(ref, False, None, None if decode else set(), so):
                n += 1
            if ref.samples is not None and n != ref.samples:
                problems.append(f"{ref.name}: {n} samples, manifest says {ref.samples}")
        except ShardError as exc:
            problems.append(str(exc).replace(ref.url, ref.name, 1))
    return problems
