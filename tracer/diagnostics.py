"""What C libraries print on the process's standard error (usd-core's warnings, libtiff's complaints), held
back while they run and handed to the caller, who reports it in one ``warning:`` or ``error:`` line of its
own: a user reads our messages, naming their file, never a library's raw lines."""
from __future__ import annotations

import contextlib
import os
import re
import sys
import tempfile
from typing import Iterator


@contextlib.contextmanager
def held_stderr() -> Iterator[list[str]]:
    """Catch what is printed on file descriptor 2 meanwhile.  Yields a list that, after the block, holds what
    was printed, one item per message (a line and the indented lines after it, white space made single).
    Where fd 2 cannot be redirected, nothing is held back."""
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
                printed += [" ".join(chunk.split()) for chunk in re.split(r"\n(?=\S)", text.strip()) if chunk.strip()]
    finally:
        os.close(saved)
