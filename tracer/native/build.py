"""Finding the C core, and building it in a development checkout.

An installed package (a wheel from ``pip wheel .``, a Blender extension zip) carries the library prebuilt by
CMake (CMakeLists.txt), marked ``RT_SOURCE_HASH=prebuilt``: :func:`prebuilt_library` finds it and it is
loaded as it is (tracer.native still checks that it was built from this contract).

Otherwise, or when the prebuilt library does not load, this is the development fallback: the library is
compiled on demand (``cc -O3 -march=x86-64-v2 -fPIC -shared -pthread -lm`` into ``_core.so``, at the first
import of :mod:`tracer.native`) when it is missing or was built from other sources: a hash of the sources
and the compiler flags is compiled into the library as a marker string, and the file is rebuilt whenever
the marker is not found in it.  A file lock keeps parallel
processes (pytest workers, several renders) from building at the same time; the new library is written
beside the old one and renamed over it, so a reader never sees half a file.

The library goes next to the sources when that folder is writable and holds no prebuilt library (a
checkout), else into a per-user cache folder (so that ``pip uninstall`` leaves nothing behind).
``python -m tracer.native.build`` builds it (or says why it cannot) and prints its path.
"""
from __future__ import annotations

import contextlib
import hashlib
import os
import platform
import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
SOURCES = ("core.c", "core.h", "contract.h", "numeric.h", "prims.h", "shapes.h", "mesh.h", "csg.h", "texture.h", "shade.h", "lights.h",
           "scan.h", "bvh_build.h", "mesh_wide.h", "sdl_read.h", "interrupt.h")
#: The library's file name: CMake (see CMakeLists.txt) and this module use the same one.
LIBRARY_NAME = "_core.dll" if sys.platform == "win32" else "_core.so"
MARKER_PREFIX = b"RT_SOURCE_HASH="
PREBUILT_MARKER = MARKER_PREFIX + b"prebuilt;"


class BuildError(RuntimeError):
    """The C core could not be built; the message says why, in a few words."""


def compile_flags() -> list[str]:
    flags = ["-O3", "-fPIC", "-shared", "-pthread", "-std=c11", "-fno-math-errno", "-ffp-contract=off", "-Wall",
             "-Wextra"]
    if platform.machine().lower() in ("x86_64", "amd64"):
        flags.insert(1, "-march=x86-64-v2")
    return flags


def find_compiler() -> str | None:
    """$CC if set, else the first of cc, gcc, clang on PATH."""
    env = os.environ.get("CC")
    if env:
        return env
    import shutil  # (here, as the other tools of an actual build: a render that loads the library needs none)

    for name in ("cc", "gcc", "clang"):
        found = shutil.which(name)
        if found:
            return found
    return None


def source_digest() -> str:
    """Hash of the sources and the flags: a library with this marker is up to date."""
    h = hashlib.sha256()
    for name in SOURCES:
        path = HERE / name
        if not path.is_file():
            raise BuildError(f"C source {name} is missing from {HERE}")
        h.update(name.encode())
        h.update(path.read_bytes())
    h.update(" ".join(compile_flags()).encode())
    return h.hexdigest()[:32]


def _cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "sdl-tracer" / hashlib.sha256(str(HERE).encode()).hexdigest()[:16]


def prebuilt_library() -> Path | None:
    """The library an installed package carries (built by CMake), if there is one beside this module."""
    path = HERE / LIBRARY_NAME
    try:
        return path if PREBUILT_MARKER in path.read_bytes() else None
    except OSError:
        return None


def library_path() -> Path:
    """Where the development build lives: beside the sources in a writable checkout, else a cache folder."""
    if os.access(HERE, os.W_OK) and prebuilt_library() is None:
        return HERE / LIBRARY_NAME
    return _cache_dir() / LIBRARY_NAME


def is_current(path: Path, digest: str) -> bool:
    try:
        data = path.read_bytes()
    except OSError:
        return False
    return MARKER_PREFIX + digest.encode() + b";" in data


@contextlib.contextmanager
def _build_lock(path: Path):
    """An exclusive lock for building ``path`` (a no-op where fcntl does not exist)."""
    import tempfile

    try:
        import fcntl
    except ImportError:  # pragma: no cover - not POSIX
        yield
        return
    name = "sdl-tracer-build-" + hashlib.sha256(str(path).encode()).hexdigest()[:16] + ".lock"
    lock_path = Path(tempfile.gettempdir()) / name
    with open(lock_path, "a+b") as handle:
        fcntl.flock(handle.fileno(), fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(handle.fileno(), fcntl.LOCK_UN)


def build(force: bool = False, verbose: bool = False) -> Path:
    """Build the library if it is missing or out of date; return its path.  Raises :class:`BuildError`."""
    digest = source_digest()
    path = library_path()
    if not force and is_current(path, digest):
        return path
    compiler = find_compiler()
    if compiler is None:
        raise BuildError("no C compiler found (install gcc or set CC)")
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as err:
        raise BuildError(f"cannot create {path.parent}: {err.strerror or err}") from err
    with _build_lock(path):
        if not force and is_current(path, digest):  # another process built it while we waited
            return path
        # The temporary name also ends in .so, so an interrupted build leaves nothing git would list.
        tmp = path.with_name(f"_core.{os.getpid()}.tmp.so")
        command = [compiler, *compile_flags(), f'-DRT_SOURCE_HASH="{digest}"', "-o", str(tmp),
                   str(HERE / "core.c"), "-lm"]
        if verbose:
            print(" ".join(command), file=sys.stderr)
        else:  # the first render would otherwise stall for many seconds without a word
            print(f"note: compiling the C core for this checkout (once): {path}", file=sys.stderr, flush=True)
        import subprocess

        try:
            result = subprocess.run(command, cwd=HERE, capture_output=True, text=True, timeout=300)
        except (OSError, subprocess.SubprocessError) as err:
            tmp.unlink(missing_ok=True)
            raise BuildError(f"could not run the C compiler {compiler!r}: {err}") from err
        if result.returncode != 0:
            tmp.unlink(missing_ok=True)
            lines = [line for line in (result.stderr or result.stdout).splitlines() if "error" in line]
            detail = (lines or (result.stderr or "").splitlines() or ["no message"])[0].strip()
            raise BuildError(f"compiling the C core failed: {detail}")
        os.replace(tmp, path)
    return path


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    try:
        path = build(force="--force" in args, verbose=True)
    except BuildError as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    print(path)
    return 0


if __name__ == "__main__":
    sys.exit(main())
