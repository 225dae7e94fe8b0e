"""Build the installable add-on zips: ``python scripts/build_extension.py [--platform P | --legacy | --all]``.

A zip is a Blender extension (blender_manifest.toml at its root, for Blender 4.2+) whose add-on package is
``addon/`` with the ``tracer`` package vendored inside it as ``tracer/`` (its Python files and the C core's
sources; no caches).  The add-on imports it as ``.tracer`` (see addon/__init__.py; in the checkout
``addon/tracer`` is a link to ``../tracer``, left out here).

* ``--platform linux-x64`` / ``windows-x64``: the C core prebuilt by CMake (CMakeLists.txt) goes in as
  ``tracer/native/_core.so`` / ``_core.dll`` and the manifest's ``platforms`` names that platform only.
  linux-x64 is built natively, windows-x64 cross-compiled with Debian's mingw-w64
  (cmake/mingw-w64-x86_64.cmake).  Each library is smoke-tested before it is packed: scripts/smoke_core.c
  loads it, checks its contract and traces a few rays (under Wine for the DLL, when Wine is installed).
* no option: the zip for every platform without a prebuilt core (macOS): the core is compiled on first use,
  which needs a C compiler; without one the add-on traces with NumPy and says so.
* ``--legacy``: the same files under one top-level folder ``sdl_raytracer/``, the layout Blender 2.8-4.1
  installs as a legacy add-on (Preferences > Add-ons > Install...), with every prebuilt core given.
* ``--all`` (``make extension``): all of the above that this machine can build, in dist/.

Every file in a zip has mode 0644, and so has the zip.
"""
from __future__ import annotations

import argparse
import os
import platform as host
import re
import shutil
import subprocess
import sys
import tempfile
import zipfile
from pathlib import Path
from typing import Iterable, Optional

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "sdl_raytracer"
#: What goes in from tracer/: the add-on needs no USD support (it would need the pxr module).
TRACER_EXCLUDE_DIRS = {"__pycache__", "usd"}
TRACER_SUFFIXES = {".py", ".c", ".h"}
#: Platforms with a prebuilt core: the library's name and the CMake toolchain file (None: this machine's).
PREBUILT = {"linux-x64": ("_core.so", None),
            "windows-x64": ("_core.dll", ROOT / "cmake" / "mingw-w64-x86_64.cmake")}
#: A fixed time for every zip member, so that a zip depends on its contents only.
ZIP_TIME = (2026, 1, 1, 0, 0, 0)


class BuildFailed(RuntimeError):
    """A core could not be built or failed its smoke test; the message says which and why."""


def manifest_text() -> str:
    return (ROOT / "blender_manifest.toml").read_text(encoding="utf-8")


def manifest_version() -> str:
    match = re.search(r'^version\s*=\s*"([^"]+)"', manifest_text(), re.M)
    if not match:
        raise SystemExit("blender_manifest.toml has no version")
    return match.group(1)


def manifest_for(platform: Optional[str]) -> str:
    """The manifest as shipped: for a prebuilt platform, ``platforms`` names that one only."""
    text = manifest_text()
    if platform is None:
        return text
    text, count = re.subn(r"^platforms\s*=.*$", f'platforms = ["{platform}"]', text, flags=re.M)
    if count != 1:
        raise SystemExit("blender_manifest.toml has no platforms line")
    return text


def members() -> list[tuple[Path, str]]:
    """(source file, name inside the add-on package) for everything the zip holds, but the manifest."""
    out = []
    for path in sorted((ROOT / "addon").rglob("*.py")):
        rel = path.relative_to(ROOT / "addon")
        if "__pycache__" not in rel.parts and rel.parts[0] != "tracer":  # (the checkout's link to ../tracer)
            out.append((path, rel.as_posix()))
    for path in sorted((ROOT / "tracer").rglob("*")):
        rel = path.relative_to(ROOT / "tracer")
        if path.is_file() and path.suffix in TRACER_SUFFIXES and not TRACER_EXCLUDE_DIRS & set(rel.parts):
            out.append((path, "tracer/" + rel.as_posix()))
    return out


def _add(zf: zipfile.ZipFile, name: str, data: bytes) -> None:
    info = zipfile.ZipInfo(name, date_time=ZIP_TIME)
    info.external_attr = 0o100644 << 16  # a regular file, rw-r--r--
    info.compress_type = zipfile.ZIP_DEFLATED
    zf.writestr(info, data)


def build(output: Path, legacy: bool = False, platform: Optional[str] = None,
          libraries: Iterable[Path] = ()) -> Path:
    """Write one zip; ``libraries`` (prebuilt cores) go into tracer/native/ under their own names."""
    prefix = f"{PACKAGE}/" if legacy else ""
    output.parent.mkdir(parents=True, exist_ok=True)
    # Written beside the target and renamed over it, so an interrupted build leaves no broken zip.
    fd, tmp = tempfile.mkstemp(prefix=output.name, suffix=".part", dir=output.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(tmp, "w") as zf:
            _add(zf, prefix + "blender_manifest.toml", manifest_for(platform).encode("utf-8"))
            for source, name in members():
                _add(zf, prefix + name, source.read_bytes())
            for library in libraries:
                _add(zf, f"{prefix}tracer/native/{library.name}", library.read_bytes())
        os.chmod(tmp, 0o644)  # (mkstemp made it 0600)
        os.replace(tmp, output)
    except BaseException:
        os.unlink(tmp)
        raise
    return output


def _run(command: list, what: str, **kwargs) -> subprocess.CompletedProcess:
    try:
        result = subprocess.run([str(c) for c in command], capture_output=True, text=True, timeout=600, **kwargs)
    except (OSError, subprocess.SubprocessError) as err:
        raise BuildFailed(f"{what}: {err}") from None
    if result.returncode != 0:
        lines = (result.stdout + result.stderr).strip().splitlines()
        raise BuildFailed(f"{what} failed: " + " / ".join(lines[-5:]))
    return result


def can_build(platform: str) -> Optional[str]:
    """None if this machine can build the platform's core, else why not."""
    if shutil.which("cmake") is None:
        return "cmake is not installed"
    if platform == "linux-x64":
        if sys.platform != "linux" or host.machine().lower() not in ("x86_64", "amd64"):
            return "this machine is not linux-x64"
        return None
    if platform == "windows-x64":
        if not (shutil.which("x86_64-w64-mingw32-gcc-posix") or shutil.which("x86_64-w64-mingw32-gcc")):
            return "mingw-w64 is not installed (apt-get install mingw-w64)"
        return None
    return f"no prebuilt core for {platform}"


def build_core(platform: str, build_root: Path = ROOT / "build") -> Path:
    """Build the platform's core with CMake (warnings are errors) and return the library."""
    name, toolchain = PREBUILT[platform]
    folder = build_root / f"extension-{platform}"
    configure = ["cmake", "-S", ROOT, "-B", folder, "-DCMAKE_BUILD_TYPE=Release", "-DRT_WERROR=ON"]
    if toolchain is not None:
        configure.append(f"-DCMAKE_TOOLCHAIN_FILE={toolchain}")
    _run(configure, f"configuring the {platform} core")
    _run(["cmake", "--build", folder], f"building the {platform} core")
    return folder / name


def smoke_test(platform: str, library: Path, build_root: Path = ROOT / "build") -> str:
    """Load the library with scripts/smoke_core.c and trace a few rays; returns what was done.  The DLL runs
    under Wine; without Wine it is not run, and the answer says so."""
    folder = build_root / f"extension-{platform}"
    source = ROOT / "scripts" / "smoke_core.c"
    flags = ["-std=c11", "-O1", "-Wall", "-Wextra", "-Werror", "-I", ROOT / "tracer" / "native", source]
    if platform == "windows-x64":
        compiler = shutil.which("x86_64-w64-mingw32-gcc-posix") or shutil.which("x86_64-w64-mingw32-gcc")
        harness = folder / "smoke_core.exe"
        _run([compiler, *flags, "-o", harness], "compiling the smoke test for Windows")
        wine = shutil.which("wine") or shutil.which("wine64")
        if wine is None:
            return "not run: Wine is not installed (apt-get install wine)"
        env = dict(os.environ, WINEPREFIX=str(build_root / "wine-prefix"), WINEDEBUG="-all")
        result = _run([wine, harness, library], "the Windows core under Wine", env=env, cwd=folder)
    else:
        harness = folder / "smoke_core"
        _run([shutil.which("cc") or "cc", *flags, "-o", harness, "-ldl"], "compiling the smoke test")
        result = _run([harness, library], f"the {platform} core's smoke test")
    if "ok" not in result.stdout.split():
        raise BuildFailed(f"the {platform} core's smoke test said: {result.stdout.strip()}")
    return "passed" + (" under Wine" if platform == "windows-x64" else "")


def build_all(dist: Path) -> list[Path]:
    """make extension: the per-platform zips this machine can build, the any-platform zip and the legacy
    zip (with every core built here).  Says on stderr what it could not build."""
    version = manifest_version()
    built, libraries = [], []
    for platform in PREBUILT:
        reason = can_build(platform)
        if reason:
            print(f"warning: no {platform} zip: {reason}", file=sys.stderr)
            continue
        library = build_core(platform)
        print(f"{platform} core: smoke test {smoke_test(platform, library)}", file=sys.stderr)
        libraries.append(library)
        built.append(build(dist / f"{PACKAGE}-{version}-{platform.replace('-', '_')}.zip", platform=platform,
                           libraries=[library]))
    built.append(build(dist / f"{PACKAGE}-{version}.zip"))
    built.append(build(dist / f"{PACKAGE}-{version}-legacy.zip", legacy=True, libraries=libraries))
    return built


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, help="zip to write (default dist/sdl_raytracer-VERSION...zip)")
    parser.add_argument("--legacy", action="store_true", help="one top-level folder, for Blender < 4.2")
    parser.add_argument("--platform", choices=sorted(PREBUILT), help="with the C core prebuilt for this platform")
    parser.add_argument("--all", action="store_true", help="every zip this machine can build, in dist/")
    args = parser.parse_args(argv)
    try:
        if args.all:
            for path in build_all(ROOT / "dist"):
                print(path)
            return 0
        libraries = []
        if args.platform:
            reason = can_build(args.platform)
            if reason:
                raise BuildFailed(f"cannot build the {args.platform} core: {reason}")
            libraries.append(build_core(args.platform))
            print(f"{args.platform} core: smoke test {smoke_test(args.platform, libraries[0])}", file=sys.stderr)
        suffix = ("-legacy" if args.legacy else "") + (f"-{args.platform.replace('-', '_')}" if args.platform else "")
        output = args.output or ROOT / "dist" / f"{PACKAGE}-{manifest_version()}{suffix}.zip"
        print(build(output, args.legacy, None if args.legacy else args.platform, libraries))
    except BuildFailed as err:
        print(f"error: {err}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
