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

from .. import diagnostics
from ..errors import TracerError
from ..userfiles import check_regular, open_regular
from . import common as C
from .budget import check_prim_budget

#: The message part of one error in a Tf.ErrorException's text: "Error in 'func' at line N in file F : 'what'".
_ERROR_MESSAGE = re.compile(r"Error in .*? : '(.*)'\s*$", re.DOTALL)


#: An anonymous layer's identifier (``@anon:0x55bad4a37210:scene-session.usda@``, the session layer USD makes
#: for every stage): an address that means nothing to a user, dropped from messages.
_ANONYMOUS_LAYER = re.compile(r",?@anon:0x[0-9a-fA-F]+:[^@]*@")


def usd_error_message(error) -> str:
    """USD's own words from a Tf.ErrorException (or its text): the first error's message (the one that says
    what was wrong; the later ones say what failed because of it), anonymous layers left out."""
    text = error if isinstance(error, str) else exception_text(error)
    for chunk in re.split(r"\n\s*(?=Error in )", text.strip()):
        found = _ERROR_MESSAGE.search(chunk.strip())
        if found:
            return without_anonymous_layers(" ".join(found.group(1).split()))
    return without_anonymous_layers(" ".join(text.split())) or "not a USD file"


def without_anonymous_layers(text: str) -> str:
    return _ANONYMOUS_LAYER.sub("", text)


def exception_text(error: BaseException) -> str:
    """The text of a Tf.ErrorException, each of its errors read on its own: one whose message is not UTF-8
    (USD quotes the bytes of a file it could not parse) would make str() of the whole raise."""
    parts = []
    for item in error.args:
        try:
            parts.append(str(item))
        except UnicodeDecodeError:
            parts.append("Error in 'USD' at line 0 in file ? : 'its text is not UTF-8'")
    return "\n".join(parts)


def check_text_encoding(name: str) -> None:
    """A TracerError at the first byte of a text USD file (``#usda``) that is not UTF-8, which is what the
    format is written in (usd-core fails on it with a message that cannot be printed)."""
    with open_regular(name, "USD file") as handle:
        if handle.read(5) != b"#usda":
            return
        handle.seek(0)
        data = handle.read()
    try:
        data.decode("utf-8")
    except UnicodeDecodeError as err:
        line = data.count(b"\n", 0, err.start) + 1
        column = err.start - (data.rfind(b"\n", 0, err.start) + 1) + 1
        raise TracerError(f"{name}:{line}:{column}: byte 0x{data[err.start]:02x} is not UTF-8 text (a .usda file is "
                          f"UTF-8)") from None


@contextlib.contextmanager
def held_stderr():
    """USD's diagnostics printed meanwhile (tracer.diagnostics.held_stderr), one line each (``Warning: in F at
    line N of FILE -- what`` becomes ``what``), for the caller to report its own way or drop."""
    said: list[str] = []
    printed: list[str] = []
    try:
        with diagnostics.held_stderr() as printed:
            yield said
    finally:
        said += [chunk.split(" -- ", 1)[-1] for chunk in printed]


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
            check_text_encoding(name)
            check_prim_budget(name)  # before USD composes what may be millions of prims
            stage = pxr.Usd.Stage.Open(name, pxr.Usd.Stage.LoadAll)
    except pxr.Tf.ErrorException as exc:
        message = usd_error_message(exc)
        # A text file's parse error already starts with the file name and line; otherwise say which file.
        where = re.match(r"\S.*:\d+:\d+: ", message)
        raise TracerError(message if where else f"{name}: cannot open as USD: {message}") from None
    if stage is None:
        raise TracerError(f"{name}: cannot open as USD")
    errors = stage.GetCompositionErrors() if hasattr(stage, "GetCompositionErrors") else []
    return stage, [without_anonymous_layers(" ".join(str(e).split())) for e in errors]
