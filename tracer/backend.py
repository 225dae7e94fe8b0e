"""Choosing who does the per-ray work: the C core when it is built and can trace the scene, else NumPy.

A backend is an object with ``camera_rays(origins, directions) -> (N, 3) colours``, a ``counts``
attribute (:class:`tracer.trace.RayCounts`) and a ``name`` ("c" or "numpy").
"""
from __future__ import annotations

import warnings
from typing import Optional

from .compile import CompiledScene
from .errors import TracerError
from .savings import RaySavings
from .trace import Tracer

BACKENDS = ("auto", "c", "numpy")
_warned = False


def make_tracer(compiled: CompiledScene, backend: str = "auto", threads: Optional[int] = None,
                savings: Optional[RaySavings] = None):
    """``threads``: the C core's worker threads (None: $SDL_TRACER_THREADS, else every core); ``savings``:
    which useless rays to skip (None: the defaults of tracer.savings)."""
    if threads is not None and threads < 1:
        raise TracerError(f"threads must be 1 or more, not {threads}")
    if backend not in BACKENDS:
        raise TracerError(f"unknown backend {backend!r} (use one of {', '.join(BACKENDS)})")
    if backend in ("auto", "c"):
        try:
            from .native import NativeTracer, load_error
        except ImportError:  # no C core in this source tree at all: NumPy is simply the backend
            NativeTracer, load_error = None, None
        if NativeTracer is None:
            if backend == "c":
                raise TracerError("the C core is not part of this installation")
        elif load_error is None:
            try:  # (the constructor checks that the C core can trace this scene)
                return NativeTracer(compiled, threads, savings)
            except TracerError:
                if backend == "c":
                    raise
        elif backend == "c":
            raise TracerError(f"the C core is not available: {load_error}")
        else:
            _warn_once(load_error)
    tracer = Tracer(compiled, savings)
    tracer.name = "numpy"
    return tracer


def _warn_once(reason) -> None:
    global _warned
    if reason and not _warned:
        _warned = True
        warnings.warn(f"C core unavailable ({reason}); using the slower NumPy path", RuntimeWarning, stacklevel=3)
