"""What a user reads when something about their input goes wrong: one translation for every front end.

The command line prints ``error: `` + :func:`error_message` and exits 2; the Blender add-on puts the same
text in its report.  Errors meant for users (TracerError, SDLError) already name the file and place; OS
errors are given the file they concern (never the hidden temporary file an atomic write uses); running out
of memory names the input; usd-core's errors give USD's own words.  Anything else is a bug and is not
translated (None), so that it is seen.
Warnings become ``warning:`` lines through tracer.errors.warnings_as_lines.
"""
from __future__ import annotations

import errno
from typing import Optional

from .atomic import user_file
from .errors import TracerError
from .userfiles import shown_name

#: A message longer than this is cut in the middle (a 1 MB token must not become a 1 MB line).
MAX_MESSAGE = 600


def user_path(name: str) -> str:
    """The file a user named, for a path that may be the temporary file of an atomic write."""
    return user_file(name)


def shortened(text: str, limit: int = MAX_MESSAGE) -> str:
    text = " ".join(text.split("\n"))
    if len(text) <= limit:
        return text
    keep = limit // 2
    return f"{text[:keep]} … ({len(text) - 2 * keep} characters left out) … {text[-keep:]}"


def _os_error(err: OSError, subject: Optional[str]) -> str:
    name = err.filename if err.filename is not None else subject
    where = f"{shown_name(user_path(str(name)))}: " if name is not None else ""
    if isinstance(err, FileNotFoundError):
        return f"{where}no such file"
    if err.errno == errno.EFBIG:
        return f"{where}file too large (the process' file size limit, ulimit -f, was reached)"
    if err.errno == errno.ENOSPC:
        return f"{where}no space left on the device"
    return f"{where}{err.strerror or err}"


def error_message(err: BaseException, subject: Optional[str] = None) -> Optional[str]:
    """The one-line text (without ``error: ``) for an error caused by the input or the system, or None for
    an error that is a bug.  ``subject`` is the file being worked on, named where the error names none."""
    if isinstance(err, TracerError):
        return shortened(str(err))
    if isinstance(err, OSError):
        return shortened(_os_error(err, subject))
    if isinstance(err, MemoryError):
        where = f"{shown_name(subject)}: " if subject else ""
        return f"{where}not enough memory ({err or 'the request is too large for this machine'})"
    if type(err).__name__ == "ErrorException" and type(err).__module__.startswith("pxr"):
        # usd-core refusing a value while reading or writing (an asset path with a control character, say):
        # its own words, which name what was wrong, after the file being worked on.
        from .usd.opening import usd_error_message  # deferred: only a USD error needs the USD modules

        where = f"{shown_name(subject)}: " if subject else ""
        return shortened(f"{where}USD: {usd_error_message(err)}")
    return None
