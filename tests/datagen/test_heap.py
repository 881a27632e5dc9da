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
