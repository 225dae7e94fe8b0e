"""Build the installable add-on zip: ``python scripts/build_extension.py [-o dist/sdl_raytracer-VERSION.zip]``.

The zip is a Blender extension (blender_manifest.toml at its root, for Blender 4.2+) whose add-on package
is ``addon/`` with the ``tracer`` package vendored inside it as ``tracer/`` (its Python files and the C
core's sources, which tracer/native/build.py compiles on first import; no compiled library, no caches).
The add-on finds the vendored copy through addon/deps.py.

With ``--legacy`` it writes the same files under one top-level folder ``sdl_raytracer/`` instead, the
layout Blender 2.8-4.1 installs as a legacy add-on (Preferences > Add-ons > Install...).
"""
from __future__ import annotations

import argparse
import os
import re
import sys
import tempfile
import zipfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PACKAGE = "sdl_raytracer"
#: What goes in from tracer/: the add-on needs no USD support (it would need the pxr module).
TRACER_EXCLUDE_DIRS = {"__pycache__", "usd"}
TRACER_SUFFIXES = {".py", ".c", ".h"}


def manifest_version() -> str:
    text = (ROOT / "blender_manifest.toml").read_text(encoding="utf-8")
    match = re.search(r'^version\s*=\s*"([^"]+)"', text, re.M)
    if not match:
        raise SystemExit("blender_manifest.toml has no version")
    return match.group(1)


def members() -> list[tuple[Path, str]]:
    """(source file, name inside the add-on package) for everything the zip holds."""
    out = [(ROOT / "blender_manifest.toml", "blender_manifest.toml")]
    for path in sorted((ROOT / "addon").rglob("*.py")):
        if "__pycache__" not in path.parts:
            out.append((path, path.relative_to(ROOT / "addon").as_posix()))
    for path in sorted((ROOT / "tracer").rglob("*")):
        rel = path.relative_to(ROOT / "tracer")
        if path.is_file() and path.suffix in TRACER_SUFFIXES and not TRACER_EXCLUDE_DIRS & set(rel.parts):
            out.append((path, "tracer/" + rel.as_posix()))
    return out


def build(output: Path, legacy: bool = False) -> Path:
    prefix = f"{PACKAGE}/" if legacy else ""
    output.parent.mkdir(parents=True, exist_ok=True)
    # Written beside the target and renamed over it, so an interrupted build leaves no broken zip.
    fd, tmp = tempfile.mkstemp(prefix=output.name, suffix=".part", dir=output.parent)
    os.close(fd)
    try:
        with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
            for source, name in members():
                zf.write(source, prefix + name)
        os.replace(tmp, output)
    except BaseException:
        os.unlink(tmp)
        raise
    return output


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("-o", "--output", type=Path, help="zip to write (default dist/sdl_raytracer-VERSION.zip)")
    parser.add_argument("--legacy", action="store_true", help="one top-level folder, for Blender < 4.2")
    args = parser.parse_args(argv)
    suffix = "-legacy" if args.legacy else ""
    output = args.output or ROOT / "dist" / f"{PACKAGE}-{manifest_version()}{suffix}.zip"
    print(build(output, args.legacy))
    return 0


if __name__ == "__main__":
    sys.exit(main())
