"""The worker heap stays flat: freed pages go back (malloc_trim), and with CRACKGEN_MMAP_THRESHOLD large blocks
never settle in the arenas."""

import sys
from pathlib import Path

import numpy as np
import psutil
import pytest

from crackgen.datagen.heap import (
    ENV_MMAP_THRESHOLD,
    HeapSettingError,
    configure_heap,
    heap_info,
    mmap_threshold_from_env,
    release_free_heap,
)

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
    that size comes from an arena and stays there once freed: the growth of a worker's render threads.
    A fixed CRACKGEN_MMAP_THRESHOLD keeps every such block its own mapping."""
    assert configure_heap({ENV_MMAP_THRESHOLD: "4M"}) == 4 * 2**20
    size = 8 * 2**20  # a 1024² float64 map; above the fixed threshold
    for _ in range(3):  # the second and third blocks are the ones the dynamic threshold would keep
        base = _mmapped_bytes()
        block = np.ones(size // 8)
        assert _mmapped_bytes() - base >= size
        del block
        assert _mmapped_bytes() == base


@pytest.mark.parametrize("raw, expected", [("", None), ("0", None), ("4194304", 4194304), ("256K", 262144),
                                           ("4M", 4 * 2**20), ("4MiB", 4 * 2**20), (" 32m ", 32 * 2**20)])
def test_mmap_threshold_sizes_parse(raw, expected):
    assert mmap_threshold_from_env({ENV_MMAP_THRESHOLD: raw}) == expected
    assert mmap_threshold_from_env({}) is None  # unset: glibc's default, nothing configured


@pytest.mark.parametrize("raw", ["lots", "4G", "-1", "1.5M", "64M", "100"])
def test_bad_mmap_threshold_is_one_line_naming_the_variable(raw):
    with pytest.raises(HeapSettingError) as exc:
        mmap_threshold_from_env({ENV_MMAP_THRESHOLD: raw})
    assert ENV_MMAP_THRESHOLD in str(exc.value) and "\n" not in str(exc.value)


def test_generate_refuses_a_bad_mmap_threshold_before_rendering(monkeypatch):
    from crackgen.config.recipe import load_recipe
    from crackgen.datagen.generate import GenerateError, check_inputs

    monkeypatch.setenv(ENV_MMAP_THRESHOLD, "lots")
    with pytest.raises(GenerateError, match=ENV_MMAP_THRESHOLD):
        check_inputs(load_recipe(Path(__file__).resolve().parents[2] / "recipes" / "demo.toml"))
