"""Watching a running `crackgen generate` from a test: wait for a condition, count the finished shards.

Why shared: the kill-and-resume tests must kill at the same point (after the manifest records a shard;
the shard file lands a moment before the manifest does), and a wait that differs between them races.
"""
from __future__ import annotations

import time
from pathlib import Path
from typing import Any, Callable

from crackgen.shards.manifest import Manifest


def wait_for(cond: Callable[[], Any], timeout_s: float, what: str) -> Any:
    """Poll ``cond`` every 0.1 s; return its first truthy value, or fail naming ``what``."""
    t0 = time.time()
    while time.time() - t0 < timeout_s:
        v = cond()
        if v:
            return v
        time.sleep(0.1)
    raise AssertionError(f"timed out waiting for {what}")


def done_shards(out: Path) -> int:
    """Shards the manifest records as done; 0 while it is not written yet."""
    try:
        return len(Manifest.load(out).done())
    except (OSError, ValueError):  # ManifestError is a ValueError
        return 0
