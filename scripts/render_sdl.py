"""Render an SDL file headless with the add-on's SDL_RAYTRACER engine, in Blender or in the bpy module.

    blender -b --factory-startup --python scripts/render_sdl.py -- SCENE.sdl OUT.png [WIDTH HEIGHT] [--lenient]
    .venv/bin/python scripts/render_sdl.py SCENE.sdl OUT.png [WIDTH HEIGHT] [--lenient]

Uses the add-on when it is installed and enabled, else registers the checkout's ``addon`` package.  The
scene is imported strictly (any problem in the file stops it, as in ``python -m tracer render``; with
``--lenient`` what can be read is imported and the problems are printed as warnings) into an empty file, rendered at WIDTH x HEIGHT (default 640 x 480) with the colour
management the importer sets (View Transform Raw: the tracer's PNG, see docs/blender.md) and written to
OUT, whose folder must exist.  Problems are one line and exit 2.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

import bpy

CHECKOUT = Path(__file__).resolve().parent.parent


def _arguments() -> list[str]:
    # Under blender, the script's own arguments follow "--"; in the bpy module they are sys.argv[1:].
    return sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]


def _ensure_addon():
    """The registered add-on's module, registering the checkout's when none is enabled."""
    if "sdl" not in dir(bpy.ops.import_scene):
        sys.path.insert(0, str(CHECKOUT))
        import addon

        addon.register()
        return addon
    return None


def _size(args: list[str]) -> tuple[int, int]:
    """WIDTH and HEIGHT as whole numbers of pixels, at least 1 each (Blender would raise 0 to 4 silently)."""
    if len(args) == 2:
        return 640, 480
    try:
        width, height = int(args[2]), int(args[3])
    except ValueError:
        raise ValueError(f"size {args[2]} {args[3]}: WIDTH and HEIGHT must be whole numbers") from None
    if width < 1 or height < 1:
        raise ValueError(f"size {width} {height}: WIDTH and HEIGHT must be at least 1")
    return width, height


def _operator_problem(err: RuntimeError, scene_path: Path) -> str:
    """An operator's reported error as the CLI words it: the parser's "FILE:LINE:COL: what" when there is one."""
    problem = str(err).strip().splitlines()[-1].removeprefix("Error: ")
    problem = problem.removeprefix(f"Cannot import {scene_path.name}: ")
    return problem if problem.startswith(str(scene_path)) else f"{scene_path}: {problem}"


def main() -> int:
    args = _arguments()
    lenient = "--lenient" in args
    args = [arg for arg in args if arg != "--lenient"]
    if len(args) not in (2, 4):
        print("error: usage: " + __doc__.strip().splitlines()[2].strip(), file=sys.stderr)
        return 2
    scene_path, out = Path(args[0]).resolve(), Path(args[1]).resolve()
    try:
        width, height = _size(args)
    except ValueError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2
    if not scene_path.is_file():
        print(f"error: {scene_path}: no such file", file=sys.stderr)
        return 2
    if not out.parent.is_dir():  # as the CLI: a typo in the folder is not silently made into a new folder
        print(f"error: {out}: folder '{out.parent}' does not exist", file=sys.stderr)
        return 2
    bpy.ops.wm.read_homefile(use_empty=True)  # an empty scene; preferences (and enabled add-ons) kept
    try:
        registered = _ensure_addon()
    except ImportError as err:  # e.g. Debian's blender without python3-numpy
        hint = " (on Debian/Ubuntu: apt-get install python3-numpy)" if "numpy" in str(err) else ""
        print(f"error: the add-on cannot load in this Python: {err}{hint}", file=sys.stderr)
        return 2
    try:
        if bpy.ops.import_scene.sdl(filepath=str(scene_path), strict=not lenient) != {"FINISHED"}:
            print(f"error: {scene_path}: could not be imported", file=sys.stderr)
            return 2
        scene = bpy.context.scene
        scene.render.engine = "SDL_RAYTRACER"
        scene.render.resolution_x, scene.render.resolution_y = width, height
        scene.render.resolution_percentage = 100
        scene.render.filepath = str(out)
        started = time.perf_counter()
        bpy.ops.render.render()
        seconds = time.perf_counter() - started  # F12 itself: the scene built, traced and shown
        bpy.data.images["Render Result"].save_render(str(out), scene=scene)
    except RuntimeError as err:  # an operator's reported error: Blender has printed it already
        print(f"error: {_operator_problem(err, scene_path)}", file=sys.stderr)
        return 2
    finally:
        if registered is not None:
            registered.unregister()  # (the bpy module can hang at exit with the add-on still registered)
    print(f"wrote {out} (F12: {seconds:.3f} s)")
    return 0


if __name__ == "__main__":
    status = main()
    if status:
        sys.exit(status)
