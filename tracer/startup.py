"""What the command-line program sets before anything else is imported (the package imports this first).

OpenSSL left out.  NumPy imports numpy.random, whose seeding imports the standard library's secrets module,
whose hmac import loads ``_hashlib`` and with it OpenSSL's libcrypto: about 3.4 MB resident, a tenth of what
importing the tracer costs, for nothing the program uses.  Without ``_hashlib``, hashlib and hmac fall
back to Python's own implementations (among them sha256 and blake2b, the tracer's), so when this process
is the program (``python -m tracer`` or the ``sdl-trace`` script) ``_hashlib`` is marked as absent before
NumPy is imported.  A program that imports the tracer as a library keeps its process as it is.
"""
from __future__ import annotations

import os
import sys

#: The installed command (pyproject.toml's [project.scripts]).
SCRIPT = "sdl-trace"


def started_as_the_program() -> bool:
    """Whether this process is the tracer's command line being started: ``python -m tracer`` (while runpy
    imports the package to find tracer/__main__.py, sys.argv[0] is "-m") or the installed script."""
    if sys.argv[:1] == ["-m"]:
        argv = getattr(sys, "orig_argv", [])
        return "-m" in argv and argv[argv.index("-m") + 1:][:1] == ["tracer"]
    return bool(sys.argv) and os.path.basename(sys.argv[0]) == SCRIPT


def leave_out_openssl() -> None:
    """Mark ``_hashlib`` as absent, unless something has loaded it already (see the module's note)."""
    sys.modules.setdefault("_hashlib", None)
