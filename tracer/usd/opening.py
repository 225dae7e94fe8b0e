"""Opening a USD file for reading: every way it can fail becomes one line naming the file.

USD reports problems in two ways, neither of which suits a command line: errors are raised as
``Tf.ErrorException`` whose text is several lines of C++ function names, and composition problems (a
reference to a missing file, say) are printed to the process's stderr as multi-line warnings while the
stage opens anyway.  Here errors become a :class:`TracerError` carrying USD's own message (for text files
``FILE:LINE:COLUMN: what``), USD's printing is held back while the stage opens, and the composition errors
are handed back so that the reader can treat them like any other problem.
"""
from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile

from ..errors import TracerError
from ..userfiles import check_regular
from . import common as C
from .budget import check_prim_budget

#: The message part of one error in a Tf.ErrorException's text: "Error in 'func' at line N in file F : 'what'".
_ERROR_MESSAGE = re.compile(r"Error in .*? : '(.*)'\s*$", re.DOTALL)


def usd_error_message(text: str) -> str:
    """USD's own words from a Tf.ErrorException's text: the first error's message (the one that says what
    was wrong; the later ones say what failed because of it)."""
    for chunk in re.split(r"\n\s*(?=Error in )", text.strip()):
        found = _ERROR_MESSAGE.search(chunk.strip())
        if found:
            return " ".join(found.group(1).split())
    return " ".join(text.split()) or "not a USD file"


@contextlib.contextmanager
def held_stderr():
    """Catch what C++ code prints on file descriptor 2 meanwhile.  Yields a list that, after the block, holds
    USD's diagnostics, one line each (``Warning: in F at line N of FILE -- what`` becomes ``what``), for the
    caller to report its own way or drop.  Where fd 2 cannot be redirected, nothing is held back."""
    printed: list[str] = []
    try:
        sys.stderr.flush()
        saved = os.dup(2)
    except (OSError, ValueError):
        yield printed
        return
    try:
        with tempfile.TemporaryFile() as sink:
            os.dup2(sink.fileno(), 2)
            try:
                yield printed
            finally:
                os.dup2(saved, 2)
                sink.seek(0)
                text = sink.read().decode("utf-8", "replace")
                for chunk in re.split(r"\n(?=\S)", text.strip()):
                    if chunk.strip():
                        printed.append(" ".join(chunk.split(" -- ", 1)[-1].split()))
    finally:
        os.close(saved)


def open_stage(path) -> tuple[object, list[str]]:
    """(stage, composition errors as messages) for a USD file; FileNotFoundError if it does not exist, a
    TracerError naming it if USD cannot read it."""
    pxr = C.pxr()
    name = check_regular(path, "USD file")
    if not os.path.isfile(name):
        if os.path.exists(name):
            raise TracerError(f"{name}: not a file")
        raise FileNotFoundError(2, "No such file or directory", name)
    # Another stage opened from this file earlier in the process would be served from USD's layer
    # registry as it was then; read the file as it is now.
    layer = pxr.Sdf.Layer.Find(name)
    try:
        with held_stderr():
            if layer is not None:
                layer.Reload()
            check_prim_budget(name)  # before USD composes what may be millions of prims
            stage = pxr.Usd.Stage.Open(name, pxr.Usd.Stage.LoadAll)
    except pxr.Tf.ErrorException as exc:
        message = usd_error_message(str(exc))
        # A text file's parse error already starts with the file name and line; otherwise say which file.
        where = re.match(r"\S.*:\d+:\d+: ", message)
        raise TracerError(message if where else f"{name}: cannot open as USD: {message}") from None
    if stage is None:
        raise TracerError(f"{name}: cannot open as USD")
    errors = stage.GetCompositionErrors() if hasattr(stage, "GetCompositionErrors") else []
    return stage, [" ".join(str(e).split()) for e in errors]
