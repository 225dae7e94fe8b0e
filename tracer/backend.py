"""Choosing who does the per-ray work: the C core when it is built and can trace the scene, else NumPy.

A backend is an object with ``camera_rays(origins, directions) -> (N, 3) colours``, a ``counts``
attribute (:class:`tracer.trace.RayCounts`) and a ``name`` ("c" or "numpy").

``"auto"`` takes the C core when it can and otherwise says why in a :class:`tracer.errors.FallbackWarning`
(the CLI prints it as a ``warning:`` line): the NumPy path gives the same image, 16-66 times slower, so
falling back is never silent.
"""
from __future__ import annotations

import warnings
from typing import Optional

from .compile import MAX_CSG_DEPTH, CompiledScene, boolean_depth
from .errors import FallbackWarning, TracerError
from .savings import RaySavings
from .trace import Tracer

BACKENDS = ("auto", "c", "numpy")

def check_boolean_depth(compiled: CompiledScene) -> None:
    """Raise a TracerError naming the first top-level boolean nested more than MAX_CSG_DEPTH deep.  (Read from
    the compiled booleans: a scene of 10^5 plain shapes is not walked again before every render.)"""
    for k in sorted(compiled.objects.booleans):
        depth = boolean_depth(compiled.objects.booleans[k])
        if depth > MAX_CSG_DEPTH:
            obj = compiled.scene.objects[k]
            where = f"{obj.source}: " if getattr(obj, "source", None) is not None else ""
            raise TracerError(f"{where}{obj.op}: booleans nested {depth} deep; the tracer follows at most "
                              f"{MAX_CSG_DEPTH}")


def load_core(backend: str = "auto") -> None:
    """Load (in a development checkout: build) the C core now, when ``backend`` may use it, so that a caller
    timing a render does not count a one-off compile as render time.  Problems surface later, in make_tracer."""
    if backend in ("auto", "c"):
        try:
            # deferred: importing loads (in a checkout: builds) the library, which only a C render wants
            from . import native  # noqa: F401
        except ImportError:
            pass


def make_tracer(compiled: CompiledScene, backend: str = "auto", threads: Optional[int] = None,
                savings: Optional[RaySavings] = None):
    """``threads``: the C core's worker threads (None: $SDL_TRACER_THREADS, else every core); ``savings``:
    which useless rays to skip (None: the defaults of tracer.savings)."""
    if threads is not None and threads < 1:
        raise TracerError(f"threads must be 1 or more, not {threads}")
    if backend not in BACKENDS:
        raise TracerError(f"unknown backend {backend!r} (use one of {', '.join(BACKENDS)})")
    check_boolean_depth(compiled)
    if backend in ("auto", "c"):
        try:
            from .native.tracer import NativeTracer  # deferred: (loads the C core, as in load_core)
        except ImportError:  # no C core in this source tree at all: NumPy is simply the backend
            if backend == "c":
                raise TracerError("the C core is not part of this installation") from None
        else:
            try:  # (the constructor checks that the C core is loaded and can trace this scene)
                return NativeTracer(compiled, threads, savings)
            except TracerError as err:
                if backend == "c":
                    raise
                warnings.warn(f"{err}; using the slower NumPy path", FallbackWarning, stacklevel=3)
    tracer = Tracer(compiled, savings)
    tracer.name = "numpy"
    return tracer
