"""Errors a user can see.  Every message names where (file:line:column) and what."""
from __future__ import annotations

from typing import Optional


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
