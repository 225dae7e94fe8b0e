"""Opening the files a user names (scenes, meshes, images): only regular files are read.

A FIFO would block the reader for ever and ``/dev/zero`` would feed it without end, so the file is opened
without blocking and checked with fstat before a byte is read; a NUL byte in a name (which the OS cannot
take) is refused with a message rather than Python's ValueError.  Other OS errors (not found, permission
denied) are raised as they are, for the caller to report in its own words.
"""
from __future__ import annotations

import os
import stat
from typing import BinaryIO, Union

from .errors import TracerError

PathLike = Union[str, "os.PathLike[str]"]

_KINDS = ((stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a pipe (FIFO)"), (stat.S_ISCHR, "a character device"),
          (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"))


def shown_name(name: str, limit: int = 200) -> str:
    """A file name as messages show it: control characters escaped, very long names cut in the middle, and
    one that starts or ends with white space in quotes (the space would not be seen)."""
    text = name if name.isprintable() else repr(name)[1:-1]
    text = text if len(text) <= limit else f"{text[:limit // 2]}…{text[-limit // 2:]}"
    return f"'{text}'" if text != text.strip() else text


def check_name(path: PathLike, what: str) -> str:
    name = os.fspath(path)
    if "\0" in name:
        raise TracerError(f"{shown_name(name)}: the {what} file name contains a NUL character")
    return name


def _refuse_unless_regular(name: str, mode: int, what: str) -> None:
    if not stat.S_ISREG(mode):
        kind = next((label for test, label in _KINDS if test(mode)), "not a regular file")
        raise TracerError(f"{shown_name(name)}: the {what} is {kind}, not a regular file")


def check_regular(path: PathLike, what: str) -> str:
    """The name, if it is a regular file (or does not exist: opening it then reports that)."""
    name = check_name(path, what)
    try:
        mode = os.stat(name).st_mode
    except OSError:
        return name
    _refuse_unless_regular(name, mode, what)
    return name


def open_regular(path: PathLike, what: str) -> BinaryIO:
    """The file opened for reading in binary, if it is a regular file; TracerError if it is anything else."""
    name = check_name(path, what)
    fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK | getattr(os, "O_CLOEXEC", 0))
    try:
        _refuse_unless_regular(name, os.fstat(fd).st_mode, what)
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_text(path: PathLike, what: str) -> str:
    """A regular file's text as UTF-8 (a byte-order mark dropped, stray bytes replaced)."""
    with open_regular(path, what) as handle:
        return handle.read().decode("utf-8-sig", errors="replace")
