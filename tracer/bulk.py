"""Process settings for bulk work (reading, compiling, tracing big scenes): one BLAS thread, and Python's
cyclic garbage collector paused.

One BLAS thread.  NumPy's OpenBLAS starts its worker threads for every small LAPACK call (compile_scene inverts one 4x4
matrix per shape) and keeps them spinning for a while afterwards.  The tracer has no large matrix
products for those threads to share, so on a busy machine they only cost: measured on 2 cores shared with
other work, inverting 100,000 matrices took 4.8 s with OpenBLAS's default threads and 0.34 s with one, and
the spinning threads take cores from the C core's own threads.  :func:`one_blas_thread` sets OpenBLAS to
one thread for the duration of a block and restores what it was, so a program that uses the tracer as a
library keeps its own setting.  Without OpenBLAS (another BLAS, or none found) it does nothing.

The collector paused.  Reading and compiling allocate several objects per statement and per shape, few of
them ever garbage, so the collector's generation counters keep running over and it rescans the growing
scene again and again: for a file of 10,000 shapes that was about a third of the reading time, and half
of compiling 100,000 spheres.  :func:`collector_paused` turns it off for a block; reference counting still
frees what is dropped, and the few reference cycles made go at the next collection after it.
"""
from __future__ import annotations

import contextlib
import ctypes
import functools
import gc
from pathlib import Path
from typing import Iterator, Optional

#: The (set, get) symbol pairs of OpenBLAS builds: NumPy's 64-bit-integer build, then the plain one.
_SYMBOLS = (("openblas_set_num_threads64_", "openblas_get_num_threads64_"),
            ("openblas_set_num_threads", "openblas_get_num_threads"))


@functools.lru_cache(maxsize=1)
def _openblas() -> Optional[tuple]:
    """(set_num_threads, get_num_threads) of the OpenBLAS that NumPy loaded, or None."""
    import numpy as np

    candidates = sorted((Path(np.__file__).parent.parent / "numpy.libs").glob("libopenblas*.so*"))
    for path in candidates:
        try:
            lib = ctypes.CDLL(str(path))  # already loaded by NumPy: this returns the same library
        except OSError:
            continue
        for set_name, get_name in _SYMBOLS:
            if hasattr(lib, set_name) and hasattr(lib, get_name):
                return (ctypes.CFUNCTYPE(None, ctypes.c_int)((set_name, lib)),
                        ctypes.CFUNCTYPE(ctypes.c_int)((get_name, lib)))
    return None


@contextlib.contextmanager
def one_blas_thread() -> Iterator[None]:
    """Run the block with OpenBLAS on one thread (see the module's note)."""
    functions = _openblas()
    if functions is None:
        yield
        return
    setter, getter = functions
    before = getter()
    if before == 1:
        yield
        return
    setter(1)
    try:
        yield
    finally:
        setter(before)


@contextlib.contextmanager
def collector_paused() -> Iterator[None]:
    """Python's cyclic garbage collector off for the block (and back as it was after)."""
    was_enabled = gc.isenabled()
    gc.disable()
    try:
        yield
    finally:
        if was_enabled:
            gc.enable()
