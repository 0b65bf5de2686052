"""One BLAS thread for a while: the bundle adjustment's many small vector operations
(``least_squares``' LSMR steps) run 5-17 times slower when OpenBLAS spreads each over threads
on cores other processes also use (measured on 2 shared cores: 0.85 s against 14 s for one
camera over 8,000 joints). numpy's bundled OpenBLAS is told through its own C entry point;
where there is none (another BLAS), nothing changes."""

from __future__ import annotations

import ctypes
import glob
import os
from collections.abc import Iterator
from contextlib import contextmanager

import numpy as np

__all__ = ["single_threaded_blas"]

_SETTERS = ("scipy_openblas_set_num_threads64_", "openblas_set_num_threads64_", "openblas_set_num_threads")
_GETTERS = ("scipy_openblas_get_num_threads64_", "openblas_get_num_threads64_", "openblas_get_num_threads")


def _openblas() -> tuple | None:
    """numpy's OpenBLAS (set, get) functions, or None."""
    libs = glob.glob(os.path.join(os.path.dirname(os.path.dirname(np.__file__)), "numpy.libs", "*openblas*"))
    for path in libs:
        try:
            lib = ctypes.CDLL(path)
        except OSError:
            continue
        for s, g in zip(_SETTERS, _GETTERS):
            if hasattr(lib, s) and hasattr(lib, g):
                setter, getter = getattr(lib, s), getattr(lib, g)
                setter.argtypes, setter.restype, getter.restype = [ctypes.c_int], None, ctypes.c_int
                return setter, getter
    return None


_LIB = _openblas()


@contextmanager
def single_threaded_blas() -> Iterator[None]:
    """Run the block with numpy's OpenBLAS on one thread, then restore its thread count."""
    if _LIB is None:
        yield
        return
    setter, getter = _LIB
    before = int(getter())
    setter(1)
    try:
        yield
    finally:
        setter(before)
