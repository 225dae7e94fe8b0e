"""Files that appear complete or not at all: written beside the target, then renamed over it."""
from __future__ import annotations

import contextlib
import os
from pathlib import Path
from typing import Iterator, Union

from .errors import TracerError

PathLike = Union[str, os.PathLike]


@contextlib.contextmanager
def replacing(target: PathLike, suffix: str = ".tmp") -> Iterator[Path]:
    """A new, empty temporary file in ``target``'s folder, renamed over ``target`` when the block ends
    without an error and removed when it does not (a cancelled or failed write leaves ``target`` as it was).

    Renaming within one folder is atomic, so readers never see half a file.  The temporary file is created
    with the permissions any new file gets (the umask applied), not tempfile.mkstemp's private 0600, since it
    becomes the user's file.  ``suffix`` matters to writers that choose the format by extension (USD).
    """
    target = Path(target)
    if not target.parent.is_dir():  # (else the error would name the temporary file)
        raise TracerError(f"{target}: folder {str(target.parent)!r} does not exist")
    while True:
        temp = target.with_name(f".{target.name}.{os.urandom(4).hex()}{suffix}")
        try:
            os.close(os.open(temp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666))
            break
        except FileExistsError:  # another writer's temporary: draw another name
            continue
        except OSError as err:
            raise _naming_target(err, target) from None
    try:
        yield temp
        os.replace(temp, target)
    except BaseException as err:
        with contextlib.suppress(OSError):
            os.unlink(temp)
        if isinstance(err, OSError) and err.filename in (None, str(temp), temp):
            raise _naming_target(err, target) from None
        raise


def _naming_target(err: OSError, target: Path) -> OSError:
    """The same error about the user's file: the temporary file's name means nothing to them."""
    return type(err)(err.errno, err.strerror or str(err), str(target))
