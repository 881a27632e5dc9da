"""Keep a long worker's C heap from growing: fixed glibc thresholds, and free pages handed back after each sample.

glibc keeps the pages of freed large temporaries (maps, meshes, ray-cast buffers, render
read-back) in its arenas. Two mechanisms made a worker's RSS grow although nothing leaked:
- freed pages inside the arenas stay resident; ``malloc_trim(0)`` after each sample returns them
  (+224 MB over 20 roads samples before, +98 MB after);
- glibc's *dynamic* mmap threshold: once a large mmapped block (a 16 MB texture) is freed, blocks up
  to that size come from the arenas instead, and the arenas of the render and ray-cast threads are not
  trimmed at their top by ``malloc_trim``, so they filled with free chunks (arenas 584 → 796 MB, 360 MB
  of it free, over 80 samples). ``configure_heap()`` fixes the thresholds at 4 MiB / 8 MiB (arenas
  about 390 MB): over 500 roads samples the growth from the warm-up fell from 95 to 71 MB at the same
  speed. 256 KiB would keep the arenas at 120 MB (growth 52 MB) but costs 0.26 s per sample in page
  faults of re-mapped 512² arrays. A slow drift of about 2 MB per 100 samples remains either way.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

# mallopt parameters (glibc <malloc.h>)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3

MMAP_THRESHOLD_BYTES = 4 * 2**20  # blocks this large (a 1024² float map) are mmapped and unmapped on free
TRIM_THRESHOLD_BYTES = 8 * 2**20  # free memory above this at an arena's top goes back at once


@functools.lru_cache(maxsize=1)
def _libc():
    """glibc, or None on other C libraries (macOS, musl, Windows)."""
    name = ctypes.util.find_library("c")
    if not name:
        return None
    try:
        lib = ctypes.CDLL(name)
        lib.malloc_trim.argtypes = [ctypes.c_size_t]
        lib.malloc_trim.restype = ctypes.c_int
        lib.mallopt.argtypes = [ctypes.c_int, ctypes.c_int]
        lib.mallopt.restype = ctypes.c_int
    except (OSError, AttributeError):
        return None
    return lib


@functools.lru_cache(maxsize=1)
def configure_heap() -> bool:
    """Fix glibc's mmap and trim thresholds, once per process; True when applied (glibc).

    Setting them turns off glibc's dynamic raising of both (what let the arenas fill)."""
    lib = _libc()
    if lib is None:
        return False
    return all(lib.mallopt(p, v) == 1 for p, v in ((M_MMAP_THRESHOLD, MMAP_THRESHOLD_BYTES),
                                                  (M_TRIM_THRESHOLD, TRIM_THRESHOLD_BYTES)))


class _MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                               "fsmblks", "uordblks", "fordblks", "keepcost")]


def heap_info() -> dict[str, int] | None:
    """glibc's ``mallinfo2`` in bytes (``arena``: arena size, ``hblkhd``: mmapped blocks, ``uordblks``: in use,
    ``fordblks``: free), or None without it: where a worker's memory sits, for tests and probes."""
    lib = _libc()
    fn = getattr(lib, "mallinfo2", None) if lib is not None else None
    if fn is None:
        return None
    fn.restype = _MallInfo2
    m = fn()
    return {name: int(getattr(m, name)) for name, _ in _MallInfo2._fields_}


def release_free_heap() -> bool:
    """Return free heap pages to the OS; True when the C library could (glibc)."""
    lib = _libc()
    if lib is None:
        return False
    lib.malloc_trim(0)
    return True
