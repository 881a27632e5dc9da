"""Keep a long worker's C heap from growing: free pages handed back after each sample, optional fixed glibc thresholds.

glibc keeps the pages of freed large temporaries (maps, meshes, ray-cast buffers, render
read-back) in its arenas. Two mechanisms made a worker's RSS grow although nothing leaked:
- freed pages inside the arenas stay resident; ``malloc_trim(0)`` after each sample returns them
  (+224 MB over 20 roads samples before, +98 MB after);
- glibc's *dynamic* mmap threshold: once a large mmapped block (a 16 MB texture) is freed, blocks up
  to that size come from the arenas instead, and the arenas of the render and ray-cast threads are not
  trimmed at their top by ``malloc_trim``, so they filled with free chunks (arenas 584 → 796 MB, 360 MB
  of it free, over 80 samples). ``CRACKGEN_MMAP_THRESHOLD`` (read by ``configure_heap()``) fixes the
  thresholds instead. It trades speed for memory, so it is off by default: over 500 roads samples at
  4 MiB the growth from the warm-up fell from 95 to 71 MB (256 KiB: 52 MB), but re-mapping and
  faulting in blocks costs time (32 spp, same hour: 1.25 s per sample outside Cycles at 4 MiB against
  1.10 s unset; 0.26 s more than unset at 256 KiB, 4 spp). A slow drift of about 2 MB per 100 samples
  remains either way, and 128 KiB grows as much as 256 KiB (51 MB); jemalloc instead of glibc grew 138 MB.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import functools
import os
import re
from typing import Mapping

from crackgen.errors import CrackgenError

# mallopt parameters (glibc <malloc.h>)
M_TRIM_THRESHOLD = -1
M_MMAP_THRESHOLD = -3

ENV_MMAP_THRESHOLD = "CRACKGEN_MMAP_THRESHOLD"  # bytes, or with a K/M suffix; unset or 0 = glibc's dynamic default
MAX_MMAP_THRESHOLD = 32 * 2**20  # glibc's ceiling on 64-bit (DEFAULT_MMAP_THRESHOLD_MAX)
_SIZE = re.compile(r"(\d+)\s*([kKmM]?)(?:i?[bB])?")


class HeapSettingError(CrackgenError, ValueError):
    """A bad CRACKGEN_MMAP_THRESHOLD; one line naming it."""


def mmap_threshold_from_env(environ: Mapping[str, str] | None = None) -> int | None:
    """The fixed mmap threshold asked for in ``CRACKGEN_MMAP_THRESHOLD``, in bytes; None when unset or 0."""
    raw = (os.environ if environ is None else environ).get(ENV_MMAP_THRESHOLD, "").strip()
    if not raw:
        return None
    m = _SIZE.fullmatch(raw)
    if m is None:
        raise HeapSettingError(f"{ENV_MMAP_THRESHOLD}={raw!r}: expected a size in bytes such as 4194304, 256K or "
                               f"4M (0 or unset = glibc's default)")
    value = int(m[1]) * {"": 1, "k": 1024, "m": 2**20}[m[2].lower()]
    if value and not 4096 <= value <= MAX_MMAP_THRESHOLD:
        raise HeapSettingError(f"{ENV_MMAP_THRESHOLD}={raw!r}: must be 0 or between 4K and 32M (glibc's range)")
    return value or None


class _MallInfo2(ctypes.Structure):
    _fields_ = [(n, ctypes.c_size_t) for n in ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks",
                                               "fsmblks", "uordblks", "fordblks", "keepcost")]


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
        if hasattr(lib, "mallinfo2"):  # glibc >= 2.33
            lib.mallinfo2.restype = _MallInfo2
    except (OSError, AttributeError):
        return None
    return lib


def configure_heap(environ: Mapping[str, str] | None = None) -> int | None:
    """Apply ``CRACKGEN_MMAP_THRESHOLD`` (mmap threshold T, trim threshold 2T) to this process; returns T, or
    None when it is unset or the C library is not glibc. Fixing them also turns off glibc's dynamic raising."""
    threshold = mmap_threshold_from_env(environ)
    lib = _libc()
    if threshold is None or lib is None:
        return None
    if lib.mallopt(M_MMAP_THRESHOLD, threshold) != 1 or lib.mallopt(M_TRIM_THRESHOLD, 2 * threshold) != 1:
        raise HeapSettingError(f"{ENV_MMAP_THRESHOLD}={threshold}: glibc refused it")
    return threshold


def heap_info() -> dict[str, int] | None:
    """glibc's ``mallinfo2`` in bytes (``arena``: arena size, ``hblkhd``: mmapped blocks, ``uordblks``: in use,
    ``fordblks``: free), or None without it: where a worker's memory sits, for tests and probes."""
    lib = _libc()
    if lib is None or not hasattr(lib, "mallinfo2"):
        return None
    m = lib.mallinfo2()
    return {name: int(getattr(m, name)) for name, _ in _MallInfo2._fields_}


def release_free_heap() -> bool:
    """Return free heap pages to the OS; True when the C library could (glibc)."""
    lib = _libc()
    if lib is None:
        return False
    lib.malloc_trim(0)
    return True
