"""Hand freed heap pages back to the OS after each sample.

glibc keeps the pages of freed large temporaries (maps, meshes, ray-cast buffers, render
read-back) in its arenas, so a worker's RSS grew about 0.5 MB per sample (+224 MB over 20
roads samples) although nothing leaked. ``malloc_trim(0)`` after each sample returns them
(128 px probe: flat over 60 samples; 512² roads: +98 MB over 20, so something else remains)."""

from __future__ import annotations

import ctypes
import ctypes.util
import functools

M_MMAP_THRESHOLD = -3  # mallopt parameter number (malloc.h)
MMAP_THRESHOLD_BYTES = 1 << 20  # blocks of 1 MiB and more are mmapped and unmapped on free


@functools.lru_cache(maxsize=1)
def _libc():
    name = ctypes.util.find_library("c")
    if not name:
        return None
    try:
        return ctypes.CDLL(name)
    except OSError:
        return None


@functools.lru_cache(maxsize=1)
def fix_mmap_threshold(nbytes: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Serve every block of ``nbytes`` or more by its own mmap, for the life of the process.

    glibc starts at 128 KiB but raises the threshold to the size of each mmapped block that
    is freed (up to 32 MiB), so after the first sample the multi-MB maps of later samples
    come from the heap, where freed space fragments and the worker's RSS climbs to a plateau
    over its first ~200 samples. A fixed threshold turns that dynamic rule off: big temporaries
    go back to the OS when freed. True when the C library took it (glibc)."""
    lib = _libc()
    fn = getattr(lib, "mallopt", None) if lib is not None else None
    if fn is None:
        return False
    fn.argtypes = [ctypes.c_int, ctypes.c_int]
    fn.restype = ctypes.c_int
    return fn(M_MMAP_THRESHOLD, int(nbytes)) == 1


@functools.lru_cache(maxsize=1)
def _malloc_trim():
    """glibc's ``malloc_trim``, or None on other C libraries (macOS, musl, Windows)."""
    fn = getattr(_libc(), "malloc_trim", None)
    if fn is None:
        return None
    fn.argtypes = [ctypes.c_size_t]
    fn.restype = ctypes.c_int
    return fn


def release_free_heap() -> bool:
    """Return free heap pages to the OS; True when the C library could (glibc)."""
    fn = _malloc_trim()
    if fn is None:
        return False
    fn(0)
    return True
