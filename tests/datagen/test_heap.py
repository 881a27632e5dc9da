"""release_free_heap gives freed heap pages back: the flat-memory guarantee of a long worker."""

import sys

import psutil
import pytest

from crackgen.datagen.heap import release_free_heap


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="malloc_trim is glibc's")
def test_freed_fragmented_heap_is_returned_to_the_os():
    proc = psutil.Process()
    # 64 KiB blocks sit below glibc's mmap threshold, so they live in the heap; the last one stays
    # alive at the top, which stops glibc's own top-of-heap trimming: the pattern of a sample's temporaries
    blocks = [bytearray(64 * 1024) for _ in range(3000)]  # ~190 MiB, every page touched (zeroed)
    keep = blocks[-1]
    del blocks
    before = proc.memory_info().rss
    assert release_free_heap() is True
    after = proc.memory_info().rss
    assert before - after > 100 * 2**20, f"RSS {before / 2**20:.0f} -> {after / 2**20:.0f} MiB"
    assert len(keep) == 64 * 1024


PROBE = """
import numpy as np, psutil
from crackgen.datagen.heap import fix_mmap_threshold
if {fix}:
    assert fix_mmap_threshold() is True
p = psutil.Process()
a = np.ones(16 * 2**20, np.uint8); del a          # glibc raises its dynamic threshold to this size here
b = np.ones(16 * 2**20 - 4096, np.uint8)          # ... so this one comes from the heap (default) or mmap (fixed)
pin = bytearray(64 * 1024)                        # a live block after it stops top-of-heap trimming
before = p.memory_info().rss
del b
print((before - p.memory_info().rss) / 2**20)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="mallopt is glibc's")
def test_fixed_mmap_threshold_returns_big_temporaries_at_free():
    import subprocess

    def freed_mb(fix: bool) -> float:
        out = subprocess.run([sys.executable, "-c", PROBE.format(fix=fix)], capture_output=True, text=True, check=True)
        return float(out.stdout.strip())

    assert freed_mb(True) > 14.0  # the 16 MiB block went back to the OS when it was freed
    assert freed_mb(False) < 2.0  # glibc's default kept it in the heap: what the fixed threshold is for
