"""Files that appear complete or not at all, and leave nothing behind when they do not.

A new file is written where no one sees it and then renamed over its target in one step (a rename within a
folder is atomic), so a reader finds the old file or the whole new one, never half of it:

* :func:`writing` gives an open file.  On Linux it is an anonymous file in the target's folder (O_TMPFILE):
  it has no name until it is complete, so a process killed mid-write (even by SIGKILL) leaves nothing; it is
  then linked under a temporary name and renamed over the target.  Elsewhere, or on a file system without
  O_TMPFILE, it is a named temporary file as below.
* :func:`replacing` gives the name of a new, empty temporary file beside the target, for writers that open
  files by name.
* :func:`through_private_folder` gives a name in a new folder of the system's temporary folder, for a writer
  that must name its file and makes temporary files of its own beside it (usd-core's .usdc); the result is
  then copied through :func:`writing`.  A kill -9 meanwhile leaves that private folder, never a file in the
  target's folder; the next call removes private folders whose process is gone.

A named temporary file is ``.NAME.<8 hex>-PID@HOST<suffix>``: NAME is the target's name, cut short if the
whole would pass the file system's limit on a name (so a target of any valid length can be written), and
the process id and host mark whose it is.  A run killed before it removed its temporary file leaves it
behind; the next write of the same target removes those whose process is gone.  While a temporary file
exists, the C core's signal watchdog knows it (tracer.signals.holding), and the final rename is made only if
no signal has been heard (tracer.signals.commit).  Files get the permissions any new file gets (the umask
applied), not tempfile.mkstemp's private 0600, since they become the user's.  Errors name the target: the
temporary file's name means nothing to the user.
"""
from __future__ import annotations

import contextlib
import errno
import hashlib
import os
import re
import shutil
import tempfile
from pathlib import Path
from typing import IO, Iterator, Optional, Union

from . import signals
from .errors import TracerError

PathLike = Union[str, os.PathLike]

#: A temporary file's name: "." + the target's name (maybe cut short) + "." + 8 random hex digits + "-" +
#: the process id + "@" + a tag of the host + the suffix.
TEMPORARY_NAME = re.compile(r"\.(?P<name>.+)\.[0-9a-f]{8}-(?P<pid>[0-9]+)@(?P<host>[0-9a-f]{6})"
                            r"(?P<suffix>\.[A-Za-z0-9]+)")
#: A private folder of :func:`through_private_folder`: "sdl-tracer-" + process id + "@" + host tag + "-" + random.
PRIVATE_FOLDER = re.compile(r"sdl-tracer-(?P<pid>[0-9]+)@(?P<host>[0-9a-f]{6})-.+")
#: Temporary files being written now by this process: their path -> the target's (for messages).
_TARGETS: dict[str, str] = {}
#: Errors of open(O_TMPFILE) that mean "not here" (an old kernel, a file system without it): use a name.
_NO_TMPFILE = (errno.EOPNOTSUPP, errno.EISDIR, errno.EINVAL, getattr(errno, "ENOTSUP", errno.EOPNOTSUPP))


def is_temporary(path: str) -> bool:
    """Whether ``path`` has the form of a temporary file's name."""
    return TEMPORARY_NAME.fullmatch(os.path.basename(path)) is not None


def user_file(path: str) -> str:
    """The file a user named, for a path that may be a temporary file's: the target it is being written for
    by this process, else (a name cut short cannot be restored) the name its own form gives."""
    path = os.fspath(path)
    if path in _TARGETS:
        return _TARGETS[path]
    found = TEMPORARY_NAME.fullmatch(os.path.basename(path))
    return os.path.join(os.path.dirname(path), found["name"]) if found else path


def _host_tag() -> str:
    return hashlib.blake2b(os.uname().nodename.encode() if hasattr(os, "uname") else b"", digest_size=3).hexdigest()


def _name_limit(folder: Path) -> int:
    try:
        return os.pathconf(folder, "PC_NAME_MAX")
    except (AttributeError, OSError, ValueError):
        return 255


def _temporary_name(target: Path, suffix: str) -> Path:
    """A fresh temporary name beside ``target`` that fits the folder's limit on a name's length (in bytes)."""
    tail = f".{os.urandom(4).hex()}-{os.getpid()}@{_host_tag()}{suffix}"
    room = _name_limit(target.parent) - len(os.fsencode("." + tail))
    name = target.name
    while len(os.fsencode(name)) > room and name:
        name = name[:-1]  # (by characters, so a multi-byte one is never split)
    return target.with_name(f".{name}{tail}")


def _remove_stale(target: Path, suffix: str) -> None:
    """Remove temporary files of ``target`` whose process, on this host, is gone (killed mid-write)."""
    host = _host_tag()
    try:
        entries = list(os.scandir(target.parent))
    except OSError:
        return
    for entry in entries:
        found = TEMPORARY_NAME.fullmatch(entry.name)
        if found is None or found["host"] != host or found["suffix"] != suffix or \
                not target.name.startswith(found["name"]) or int(found["pid"]) == os.getpid():
            continue
        if _process_gone(int(found["pid"])):
            with contextlib.suppress(OSError):
                os.unlink(entry.path)


def _process_gone(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return True
    except (OSError, OverflowError, ValueError):
        return False
    return False


def _check_folder(target: Path) -> None:
    if not target.parent.is_dir():  # (else the error would name the temporary file)
        raise TracerError(f"{target}: folder {str(target.parent)!r} does not exist")


def _new_named(target: Path, suffix: str) -> Path:
    """Create an empty temporary file beside ``target`` (the umask's permissions) and return its name."""
    while True:
        temp = _temporary_name(target, suffix)
        try:
            os.close(os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL | getattr(os, "O_CLOEXEC", 0), 0o666))
            return temp
        except FileExistsError:  # another writer's: draw another name
            continue
        except OSError as err:
            raise naming_target(err, target) from None


def _commit(temp: Path, target: Path) -> None:
    signals.commit(str(target), lambda: os.replace(temp, target))


@contextlib.contextmanager
def replacing(target: PathLike, suffix: str = ".tmp") -> Iterator[Path]:
    """A new, empty temporary file in ``target``'s folder, renamed over ``target`` when the block ends
    without an error and removed when it does not (a cancelled or failed write leaves ``target`` as it was).
    ``suffix`` matters to writers that choose the format by extension (USD)."""
    target = Path(target)
    _check_folder(target)
    _remove_stale(target, suffix)
    temp = _new_named(target, suffix)
    _TARGETS[str(temp)] = str(target)
    try:
        with signals.holding(str(temp)):
            try:
                yield temp
                _commit(temp, target)
            except BaseException as err:
                with contextlib.suppress(OSError):
                    os.unlink(temp)
                if isinstance(err, OSError) and err.filename in (None, str(temp), temp):
                    raise naming_target(err, target) from None
                raise
    finally:
        _TARGETS.pop(str(temp), None)


@contextlib.contextmanager
def writing(target: PathLike, mode: str = "wb", **open_args) -> Iterator[IO]:
    """An open file (``mode`` "wb" or "w", ``open_args`` as for open()) whose content becomes ``target`` when
    the block ends without an error; otherwise ``target`` is left as it was and nothing else remains."""
    target = Path(target)
    _check_folder(target)
    fd = _anonymous_file(target)
    if fd is None:
        with replacing(target) as temp, open(temp, mode, **open_args) as handle:
            yield handle
        return
    try:
        with os.fdopen(fd, mode, **open_args) as handle:
            yield handle
            handle.flush()
            _link_and_commit(handle.fileno(), target)
    except OSError as err:
        if err.filename is None or is_temporary(str(err.filename)):
            raise naming_target(err, target) from None
        raise


def _anonymous_file(target: Path) -> Optional[int]:
    """A file descriptor of a new file without a name in ``target``'s folder (O_TMPFILE), or None where the
    system or the file system has no such files (then a named temporary file is used)."""
    if not hasattr(os, "O_TMPFILE") or not os.path.isdir("/proc/self/fd"):
        return None
    try:
        return os.open(target.parent, os.O_TMPFILE | os.O_WRONLY | getattr(os, "O_CLOEXEC", 0), 0o666)
    except OSError as err:
        if err.errno in _NO_TMPFILE:
            return None
        raise naming_target(err, target) from None


def _link_and_commit(fd: int, target: Path) -> None:
    """Give the anonymous file a temporary name (linkat through /proc), then rename it over ``target``."""
    _remove_stale(target, ".tmp")
    folder = os.open(target.parent, os.O_RDONLY | getattr(os, "O_DIRECTORY", 0) | getattr(os, "O_CLOEXEC", 0))
    try:
        _link_into(fd, folder, target)
    finally:
        os.close(folder)


def _link_into(fd: int, folder: int, target: Path) -> None:
    while True:
        temp = _temporary_name(target, ".tmp")
        _TARGETS[str(temp)] = str(target)
        try:
            with signals.holding(str(temp)):
                try:  # (a folder descriptor makes Python call linkat with AT_SYMLINK_FOLLOW, not link)
                    os.link(f"/proc/self/fd/{fd}", temp.name, dst_dir_fd=folder, follow_symlinks=True)
                except FileExistsError:
                    continue
                except OSError as err:
                    raise naming_target(err, target) from None
                try:
                    _commit(temp, target)
                except BaseException:
                    with contextlib.suppress(OSError):
                        os.unlink(temp)
                    raise
                return
        finally:
            _TARGETS.pop(str(temp), None)


def naming_target(err: OSError, target: Path) -> OSError:
    """The same error about the user's file: the temporary file's name means nothing to them."""
    return type(err)(err.errno, err.strerror or str(err), str(target))


@contextlib.contextmanager
def through_private_folder(target: PathLike, suffix: str) -> Iterator[Path]:
    """A file name ending in ``suffix`` in a new private folder of the system's temporary folder; when the
    block ends without an error, that file's bytes become ``target`` (through :func:`writing`: no name in the
    target's folder until complete).  The private folder is removed however the block ends, and is known to
    the C watchdog meanwhile (its file is removed if the watchdog ends the process)."""
    target = Path(target)
    _check_folder(target)
    _remove_stale_private_folders()
    folder = Path(tempfile.mkdtemp(prefix=f"sdl-tracer-{os.getpid()}@{_host_tag()}-"))
    try:
        temp = folder / f"out{suffix}"
        with signals.holding(str(temp)):
            yield temp
            with open(temp, "rb") as source, writing(target) as handle:
                shutil.copyfileobj(source, handle, 1 << 20)
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def _remove_stale_private_folders() -> None:
    """Remove private folders (:func:`through_private_folder`) of this host whose process is gone (killed)."""
    host = _host_tag()
    try:
        entries = list(os.scandir(tempfile.gettempdir()))
    except OSError:
        return
    for entry in entries:
        found = PRIVATE_FOLDER.fullmatch(entry.name)
        if found is not None and found["host"] == host and int(found["pid"]) != os.getpid() and \
                _process_gone(int(found["pid"])):
            shutil.rmtree(entry.path, ignore_errors=True)
