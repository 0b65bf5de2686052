"""Keeping the host's memory flat: glibc's malloc told not to keep what a burst asked for.

glibc serves requests of ``M_MMAP_THRESHOLD`` bytes or more (128 KiB at start) with their own
``mmap``, returned to the system on ``free``. But by default the threshold is *dynamic*: each
time such a chunk is freed, the threshold rises to its size (up to 32 MiB), so every later
request up to that size comes from the heaps and arenas instead, where freed memory mostly
stays resident. One stranger's burst of large messages therefore raised the host's resident
memory for good: in ``benchmarks/soak.py --attack oversize`` (600 KB payloads, 5 a second for
72 s, received by Zenoh and dropped by the host unread) the host's RSS stepped up 6 MB and
stayed there; with the threshold pinned at 128 KiB it moved 0.3 MB.

``pin_mmap_threshold`` sets the threshold once, which also turns the dynamic adjustment off
(``mallopt(3)``). Large buffers then always go back to the system when freed; the cost is an
``mmap``/``munmap`` pair per large allocation, which the host makes a few of per step.
"""

from __future__ import annotations

import ctypes
import ctypes.util
import logging
import platform
from typing import Final

__all__ = ["pin_mmap_threshold", "MMAP_THRESHOLD_BYTES"]

log = logging.getLogger("superbody.host")

MMAP_THRESHOLD_BYTES: Final[int] = 128 * 1024  # glibc's own starting value
_M_MMAP_THRESHOLD: Final[int] = -3  # from glibc's malloc.h


def pin_mmap_threshold(nbytes: int = MMAP_THRESHOLD_BYTES) -> bool:
    """Fix glibc's mmap threshold at ``nbytes`` for this process (module docstring).

    Returns:
        True if set; False where the C library is not glibc (musl, macOS: nothing to do there)
        or refused the value.
    """
    if not 0 < nbytes <= 32 * 1024 * 1024:
        raise ValueError(f"mmap threshold must be in (0, 32 MiB] bytes, got {nbytes!r}")
    if platform.system() != "Linux" or platform.libc_ver()[0] != "glibc":
        return False
    try:
        return bool(ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").mallopt(_M_MMAP_THRESHOLD, int(nbytes)))
    except (OSError, AttributeError) as e:
        log.debug("mallopt unavailable: %s", e)
        return False
