"""What the command-line program sets up before anything else is imported (the package imports this first).

Importing NumPy and the tracer is most of a small render's peak memory (docs/performance.md), and part of
it is for things the program never uses.  When this process is the program (``python -m tracer`` or the
``sdl-trace`` script), :func:`prepare_the_program` therefore, before NumPy is imported:

* Defers NumPy's subpackages that ``numpy/__init__.py`` imports but the program does not use
  (:data:`DEFERRED_NUMPY_PARTS`: random, ma, polynomial, fft, ctypeslib; about 5.7 MB resident with NumPy
  1.26, numpy.random's compiled modules the largest part).  They are loaded by the standard library's
  ``importlib.util.LazyLoader``: each is a module object whose code runs the first time one of its names is
  used, so code that does use one (a command that draws random numbers, a package that checks for masked
  arrays) gets the same module, only later.
* Leaves OpenSSL out: ``import hashlib`` (the tracer hashes scenes and sources with blake2b and sha256) and
  the secrets module (numpy.random's seeding) load ``_hashlib`` and with it OpenSSL's libcrypto, about
  3.4 MB resident.  Marked absent, ``_hashlib`` gives way to Python's own implementations of those hashes,
  which hashlib and hmac fall back to.
* Hands freed memory back to the system (:func:`return_freed_memory`): glibc's malloc raises the size from
  which an allocation gets pages of its own (mmap) to the size of every such block freed, up to 32 MB, so
  after the first big NumPy temporary is freed, arrays of up to that size come from the heap, and the heap
  keeps what they freed (it is trimmed only from its top, and only past twice that size).  Reading and
  building a 10^6-triangle mesh frees tens of megabytes of temporaries that way, which the render then
  holds as part of its peak (116 MB against 102 MB with the size fixed, docs/performance.md, section (e)).

A program that imports the tracer as a library keeps its process as it is.
"""
from __future__ import annotations

import os
import sys

#: The installed command (pyproject.toml's [project.scripts]).
SCRIPT = "sdl-trace"

#: NumPy's subpackages that ``import numpy`` loads and the program does not use (loaded when first used).
DEFERRED_NUMPY_PARTS = ("numpy.random", "numpy.ma", "numpy.polynomial", "numpy.fft", "numpy.ctypeslib")

#: Blocks of this many bytes and more get pages of their own, which go back to the system when freed.  (Smaller
#: keeps less: 100 MB at 1 MiB on the 10^6-triangle row, 102 MB at 8 MiB; but every block mapped anew costs
#: page faults when it is first written: 546,000 faults for 10^6 spheres at 1 MiB, 490,000 at 8 MiB, 289,000
#: with glibc's own rule.)
OWN_PAGES_FROM = 8 << 20

#: glibc's mallopt parameter for that size (malloc.h's M_MMAP_THRESHOLD).
M_MMAP_THRESHOLD = -3


def started_as_the_program() -> bool:
    """Whether this process is the tracer's command line being started: ``python -m tracer`` (while runpy
    imports the package to find tracer/__main__.py, sys.argv[0] is "-m") or the installed script."""
    if sys.argv[:1] == ["-m"]:
        argv = getattr(sys, "orig_argv", [])
        return "-m" in argv and argv[argv.index("-m") + 1:][:1] == ["tracer"]
    return bool(sys.argv) and os.path.basename(sys.argv[0]) == SCRIPT


def hear_signals_at_once() -> None:
    """SIGINT and SIGTERM end the program at once, with 128 + the signal and an ``interrupted`` line, from the
    first line of the package on: tracer.signals does the same in its starting phase, but importing it (the
    signal module's enums, typing) takes a few milliseconds, ten times that on a loaded machine, in which a
    Ctrl-C would have been Python's KeyboardInterrupt and its traceback.  Nothing but the C module _signal."""
    import _signal

    def end(signum, frame):
        try:
            os.write(2, b"\ninterrupted\n")
        except OSError:
            pass
        os._exit(128 + signum)

    for signum in (_signal.SIGINT, _signal.SIGTERM):
        if _signal.getsignal(signum) is not _signal.SIG_IGN:  # (a shell's `cmd &` ignores SIGINT: keep that)
            _signal.signal(signum, end)


def prepare_the_program() -> None:
    """The measures of the module's note (the first two only when nothing has loaded its modules yet)."""
    leave_out_openssl()
    defer_imports(DEFERRED_NUMPY_PARTS)
    return_freed_memory()


def return_freed_memory() -> bool:
    """Fix the size from which glibc's malloc gives a block pages of its own at :data:`OWN_PAGES_FROM` (which
    also stops it from raising that size as blocks are freed: see the module's note).  Returns whether it
    did: False where the C library is not glibc (musl, macOS, Windows: each has its own allocator)."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes  # (the C core is loaded with ctypes too)

    try:
        libc = ctypes.CDLL(None)
    except OSError:
        return False
    if not (hasattr(libc, "mallopt") and hasattr(libc, "gnu_get_libc_version")):  # (musl's mallopt does nothing)
        return False
    return libc.mallopt(ctypes.c_int(M_MMAP_THRESHOLD), ctypes.c_int(OWN_PAGES_FROM)) == 1  # (int mallopt(int, int))


def leave_out_openssl() -> None:
    """Mark ``_hashlib`` as absent, unless something has loaded it already (see the module's note)."""
    sys.modules.setdefault("_hashlib", None)


class DeferredImports:
    """A finder for sys.meta_path (not derived from importlib.abc's, whose import costs more than this
    module): finds the named modules as the standard path finder does, with a loader that runs a module's
    code only when one of its names is first used."""

    def __init__(self, names):
        self.names = frozenset(names)

    def find_spec(self, name, path=None, target=None):
        if name not in self.names:
            return None
        import importlib.machinery  # (here: the first milliseconds are for hear_signals_at_once)
        import importlib.util

        spec = importlib.machinery.PathFinder.find_spec(name, path)
        if spec is None or not hasattr(spec.loader, "exec_module"):
            return None  # (found some other way: imported as usual)
        spec.loader = importlib.util.LazyLoader(spec.loader)
        return spec


def defer_imports(names) -> None:
    """Defer the named modules that are not imported yet (see :class:`DeferredImports`)."""
    waiting = [name for name in names if name not in sys.modules]
    if waiting:
        sys.meta_path.insert(0, DeferredImports(waiting))
