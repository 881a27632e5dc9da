"""The worker heap stays flat: freed pages go back (malloc_trim) and large blocks never settle in the arenas."""

import sys

import numpy as np
import psutil
import pytest

from crackgen.datagen.heap import MMAP_THRESHOLD_BYTES, configure_heap, heap_info, release_free_heap

glibc_only = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="malloc_trim/mallopt are glibc's")


def _mmapped_bytes() -> int:
    info = heap_info()
    if info is None:
        pytest.skip("needs glibc's mallinfo2")
    return info["hblkhd"]


@glibc_only
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


@glibc_only
def test_large_blocks_are_mapped_even_after_one_was_freed():
    """glibc's default raises its mmap threshold to the size of a freed mapped block, so the next block of
    that size comes from an arena and stays there once freed: the growth of a worker's render threads."""
    assert configure_heap() is True
    size = 8 * 2**20  # a 1024² float64 map; above the fixed threshold
    assert size > MMAP_THRESHOLD_BYTES
    for _ in range(3):  # the second and third blocks are the ones the dynamic threshold would keep
        base = _mmapped_bytes()
        block = np.ones(size // 8)
        assert _mmapped_bytes() - base >= size
        del block
        assert _mmapped_bytes() == base
