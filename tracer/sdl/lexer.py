"""Split SDL text into tokens, and say where each one is.

The rules (docs/sdl.md): tokens are separated by white space; ``{`` and ``}`` are always tokens of their own;
``!`` starts a comment that runs to the end of the line.  Unlike the book's lexer, a comment *ends* the token
before it, so ``sphere!x`` followed by ``cube`` on the next line gives ``sphere`` and ``cube``.
A comment ``! name: text`` is kept aside: it names the next shape.

The lexer does not decide what a token means: a file name such as ``../meshes/pawn.3vn`` is one token like
any other, and the parser decides whether a token is a keyword, a number or a name.

A scene of a million shapes is some 1.5·10^7 tokens, so the reader gets them from :class:`Tokens` as plain
strings, a block of lines at a time, numbered in reading order; it asks where a token is (its line and
column) only for what it records or reports (a shape's source, an error), and that question re-reads the
token's line.  :func:`tokenize` gives every token with its place, for tests and small texts.
"""
from __future__ import annotations

import math
import re
from array import array
from bisect import bisect_right
from dataclasses import dataclass
from itertools import accumulate, chain, islice
from typing import NamedTuple, Optional, Union


class Token(NamedTuple):
    text: str
    line: int  # 1-based
    column: int  # 1-based, counted in characters


# A brace on its own, or a run of characters that are neither white space nor braces.  (Python's \s and
# str.split() agree on what white space is, so a line without braces is split with str.split.)
_TOKEN_RE = re.compile(r"[{}]|[^\s{}]+")

# Decimal floats only, in ASCII digits: no 'nan', 'inf', hex, underscores or other scripts' digits, which
# Python's float() (and the pattern \d) would also take.
NUMBER_RE = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")


#: ``! name: text``, the comment that names the next shape (an extension: other readers skip it).
_NAME_COMMENT_RE = re.compile(r"!\s*name:\s*(.*?)\s*$")

#: Tokens into a line beyond which a token's place is looked up in the line's token starts, worked out once.
_FAR = 64

#: About how many characters of text are split into tokens at a time: enough that the per-block work is
#: nothing, few enough that a block's tokens (some 60 bytes each as strings) stay a few megabytes.
BLOCK_CHARS = 1 << 18


@dataclass
class _Block:
    """Lines of the text split at one time."""

    start: int  # where its first line starts in the text
    end: int  # where its last line ends
    first_line: int  # the number of its first line (1-based)
    #: starts[i]: the number of the first token of its line i (a line without tokens: of the next token); a
    #: list while it is the last block (bisected for every shape read), an array after.
    starts: Union[list[int], array]


class Tokens:
    """The tokens of one text, numbered from 0 in reading order, split a block of lines at a time.

    Lines are the text split at '\\n' only (not str.splitlines, which also breaks at form feeds and other rare
    characters), so that line numbers agree with what editors show; a trailing '\\r' is white space.
    """

    def __init__(self, text: str):
        self._text = text
        self._next_start = 0  # where the next block starts in the text
        self._next_line = 1
        self._blocks: list[_Block] = []
        self._block_bases: list[int] = []  # the number of each block's first token, for bisect
        self._lines: dict[int, list[str]] = {}  # the lines of the last blocks asked about, by block number
        self._tokens: list[str] = []  # the last block's
        # (block, line) -> (the line without its comment, where its tokens start), for long lines
        self._far: dict[tuple[int, int], tuple[str, list[int]]] = {}
        #: Tokens split so far.
        self.count = 0
        #: The name comments of the last block: (number of the token after the comment, the name).
        self.name_comments: list[tuple[int, str]] = []

    def next_block(self) -> Optional[list[str]]:
        """The tokens of the next block of lines (maybe none), numbered from :attr:`count` before the call;
        None after the last line."""
        text, start = self._text, self._next_start
        if start > len(text):
            return None
        end = text.find("\n", start + BLOCK_CHARS)
        if end < 0:
            end = len(text)
        chunk = text[start:end]
        lines = chunk.split("\n")
        base = self.count
        self.name_comments = []
        if "!" in chunk or "{" in chunk or "}" in chunk:
            tokens, starts = self._split_lines(lines, base)
        else:
            # The common case for big generated files: no comments, no braces; every loop is in C.
            per_line = list(map(str.split, lines))
            tokens = list(chain.from_iterable(per_line))
            starts = list(accumulate(map(len, per_line), initial=base))
            starts.pop()
        if self._blocks:  # no longer the last: its line starts as an array, a quarter of the memory
            self._blocks[-1].starts = array("q", self._blocks[-1].starts)
        self._block_bases.append(base)
        self._blocks.append(_Block(start, end, self._next_line, starts))
        self._lines = {len(self._blocks) - 1: lines}
        self._tokens = tokens
        self._far = {}
        self._next_start = end + 1
        self._next_line += len(lines)
        self.count += len(tokens)
        return tokens

    def _split_lines(self, lines: list[str], base: int) -> tuple[list[str], list[int]]:
        tokens: list[str] = []
        starts = []
        for line in lines:
            starts.append(base + len(tokens))
            comment = line.find("!")
            if comment >= 0:
                name = _NAME_COMMENT_RE.match(line, comment)
                line = line[:comment]
            if "{" in line or "}" in line:
                tokens += _TOKEN_RE.findall(line)
            else:
                tokens += line.split()
            if comment >= 0 and name is not None and name.group(1):
                self.name_comments.append((base + len(tokens), name.group(1)))
        return tokens, starts

    def locate(self, number: int) -> Token:
        """Token ``number`` (one already split) with its line and column."""
        return Token(*self._find(number))

    def place(self, number: int) -> tuple[int, int]:
        """The line and column of token ``number`` (one already split)."""
        return self._find(number)[1:]

    def _find(self, number: int) -> tuple[str, int, int]:
        last = len(self._blocks) - 1
        index = last if number >= self._block_bases[last] else bisect_right(self._block_bases, number) - 1
        block = self._blocks[index]
        row = bisect_right(block.starts, number) - 1
        n = number - block.starts[row]  # the token is the n-th (from 0) on its line
        lines = self._lines.get(index)
        if lines is None:  # an earlier block (a macro body defined there): split its lines again
            lines = self._lines[index] = self._text[block.start:block.end].split("\n")
        line = lines[row]
        if n >= _FAR:
            # Far along a long line (a whole scene on one line, say): where each of its tokens starts is
            # worked out once, with the line cut at its comment, so that placing all its shapes stays linear in
            # its length.
            far = self._far.get((index, row))
            if far is None:
                line = _without_comment(line)
                far = self._far[(index, row)] = (line, [m.start() for m in _TOKEN_RE.finditer(line)])
            line, starts = far
            return _TOKEN_RE.match(line, starts[n]).group(), block.first_line + row, starts[n] + 1
        if index == last:
            # Most lines are written with single spaces and no indent: then the column is the length of the
            # words before the token, joined by spaces, if the line does start with just that.
            base = self._block_bases[last]
            words = self._tokens[number - n - base:number - base + 1]
            before = " ".join(words[:-1]) + " " if n else ""
            if line.startswith(before) and line.startswith(words[-1], len(before)):
                return words[-1], block.first_line + row, len(before) + 1
        match = next(islice(_TOKEN_RE.finditer(_without_comment(line)), n, None))
        return match.group(), block.first_line + row, match.start() + 1


def _without_comment(line: str) -> str:
    comment = line.find("!")
    return line if comment < 0 else line[:comment]


def tokenize(text: str, names: Optional[list[tuple[int, str]]] = None) -> list[Token]:
    """All tokens of ``text`` in order, each with its place.  Comments and white space are dropped.

    With a ``names`` list, each name comment adds (index in the tokens of the token after it, its text).
    """
    tokens = Tokens(text)
    count = 0
    while (block := tokens.next_block()) is not None:
        count += len(block)
        if names is not None:
            names += tokens.name_comments
    return [tokens.locate(number) for number in range(count)]


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


def to_floats(words: list[str]) -> Optional[tuple[float, ...]]:
    """The values of ``words`` if every one is a decimal number literal (as :func:`to_float` takes), else None.

    Several words at once, for speed: one check of their characters together, float() mapped over them and
    one finiteness check of their sum (finite only if every value is; a sum that overflows just sends the
    words to the one-by-one check)."""
    if not _NUMBER_CHARS.issuperset("".join(words)):
        return None
    try:
        values = tuple(map(float, words))
    except ValueError:
        return None
    if math.isfinite(sum(values)):
        return values
    values = tuple(map(to_float, words))
    return None if None in values else values
