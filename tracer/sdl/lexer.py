"""Split SDL text into tokens, each with the line and column where it starts.

The rules (docs/sdl.md): tokens are separated by white space; ``{`` and ``}`` are always tokens of their own;
``!`` starts a comment that runs to the end of the line.  Unlike the book's lexer, a comment *ends* the token
before it, so ``sphere!x`` followed by ``cube`` on the next line gives ``sphere`` and ``cube``.
A comment ``! name: text`` is kept aside (see :func:`tokenize`): it names the next shape.

The lexer does not decide what a token means: a file name such as ``../meshes/pawn.3vn`` is one token like
any other, and the parser decides whether a token is a keyword, a number or a name.
"""
from __future__ import annotations

import math
import re
from typing import NamedTuple, Optional


class Token(NamedTuple):
    text: str
    line: int  # 1-based
    column: int  # 1-based, counted in characters


# A brace on its own, or a run of characters that are neither white space nor braces.
_TOKEN_RE = re.compile(r"[{}]|[^\s{}]+")

# Decimal floats only, in ASCII digits: no 'nan', 'inf', hex, underscores or other scripts' digits, which
# Python's float() (and the pattern \d) would also take.
NUMBER_RE = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


#: ``! name: text``, the comment that names the next shape (an extension: other readers skip it).
_NAME_COMMENT_RE = re.compile(r"!\s*name:\s*(.*?)\s*$")


def tokenize(text: str, names: Optional[list[tuple[int, str]]] = None) -> list[Token]:
    """All tokens of ``text`` in order.  Comments and white space are dropped.

    With a ``names`` list, each name comment adds (index in the tokens of the token after it, its text).
    """
    tokens: list[Token] = []
    # Split on '\n' only (not str.splitlines, which also breaks at form feeds and other rare characters),
    # so that line numbers agree with what editors show; a trailing '\r' is white space.
    for line_number, line in enumerate(text.split("\n"), start=1):
        comment = line.find("!")
        name = None
        if comment >= 0:
            if names is not None:
                name = _NAME_COMMENT_RE.match(line, comment)
            line = line[:comment]
        for match in _TOKEN_RE.finditer(line):
            tokens.append(Token(match.group(), line_number, match.start() + 1))
        if name is not None and name.group(1):
            names.append((len(tokens), name.group(1)))
    return tokens


def is_number(text: str) -> bool:
    """True if ``text`` is a decimal number literal that gives a finite float."""
    return to_float(text) is not None


#: The characters of NUMBER_RE.  A word made of these alone that float() takes is a NUMBER_RE match (float's
#: grammar restricted to them is NUMBER_RE's), so to_float needs no regular expression.
_NUMBER_CHARS = frozenset("0123456789.eE+-")


def to_float(text: str) -> Optional[float]:
    """The value of a decimal number literal, or None if ``text`` is not one (or overflows to infinity)."""
    if not _NUMBER_CHARS.issuperset(text):
        return None
    try:
        value = float(text)
    except ValueError:
        return None
    return value if math.isfinite(value) else None
