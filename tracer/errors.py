"""Errors a user can see.  Every message names where (file:line:column) and what."""
from __future__ import annotations

import contextlib
import sys
import warnings
from typing import Optional, TextIO


class TracerError(Exception):
    """Base class for errors meant for users (the CLI prints them as one line, no traceback)."""


class SDLError(TracerError):
    """A problem in an SDL file: where it is, the token found and what was expected."""

    def __init__(self, message: str, file: Optional[str] = None, line: int = 0, column: int = 0,
                 token: Optional[str] = None, expected: Optional[str] = None):
        self.message = message
        self.file = file
        self.line = line
        self.column = column
        self.token = token
        self.expected = expected
        super().__init__(self.__str__())

    @property
    def where(self) -> str:
        name = self.file or "<sdl>"
        if self.line and self.column:
            return f"{name}:{self.line}:{self.column}"
        if self.line:
            return f"{name}:{self.line}"
        return name

    def __str__(self) -> str:
        text = f"{self.where}: {self.message}"
        if self.token is not None:
            text += f" (found {_cut(self.token)!r}"
            text += f", expected {self.expected})" if self.expected else ")"
        elif self.expected:
            text += f" (expected {self.expected})"
        return text


#: Longest token quoted whole in a message; a longer one shows its start and its length.
MAX_QUOTED_TOKEN = 40


def _cut(token: str) -> str:
    return token if len(token) <= MAX_QUOTED_TOKEN else f"{token[:MAX_QUOTED_TOKEN]}... ({len(token)} characters)"


class RenderCancelled(TracerError):
    """Raised inside a render when the caller's cancel check says stop."""


class TracerWarning(UserWarning):
    """Something a user should know that does not stop the work (the CLI prints it as one ``warning:`` line)."""


class FallbackWarning(TracerWarning):
    """``backend="auto"`` traced with the NumPy path because the C core could not; the message says why."""


@contextlib.contextmanager
def warnings_as_lines(stream: Optional[TextIO] = None):
    """Inside: every :class:`TracerWarning` is printed as one ``warning: ...`` line (each time it happens);
    a library's own warning (one our code did not translate) as one ``warning: Category: ...`` line, not as
    Python's two lines with a source location."""
    with warnings.catch_warnings():
        warnings.simplefilter("always", TracerWarning)

        def show(message, category, filename, lineno, file=None, line=None):
            text = " ".join(str(message).split())
            if not issubclass(category, TracerWarning):
                text = f"{category.__name__}: {text}"
            print(f"warning: {text}", file=stream or sys.stderr)

        warnings.showwarning = show
        yield


class SceneError(TracerError, ValueError):
    """A scene, or a value in one, that the tracer cannot use: a degenerate camera, an unknown shape kind, a
    mesh face using a vertex that does not exist.  (Also a ValueError, which is what these were before.)"""


class WriteError(TracerError, ValueError):
    """Something a file format (SDL, .3vn, USD) cannot express; nothing is written.  (Also a ValueError.)"""
