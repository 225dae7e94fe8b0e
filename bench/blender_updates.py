"""The add-on with a million-polygon mesh: time to the viewport's first pixel, and to its first pixel after
a light is moved; F12 (Persistent Data on) before and after the same move.  This checkout against an
earlier commit (before the engine kept each object's geometry), interleaved, each run in its own process.

    python bench/blender_updates.py [--before 16d0c89] [--grid 1000] [--repeat 2]

A bumpy grid of GRID x GRID quads (1,000,000 by default) under a point light, in the bpy module.  The
viewport is driven as Blender drives it, headless: view_update from the depsgraph's update, then view_draw
until the first redraw has traced its first slice (VIEWPORT_SLICE, 0.08 s, of coarse blocks); GPU drawing
is not available in background mode, so the texture upload is left out (it is the same for both).  "First
pixel" is from asking for the first redraw of a depsgraph Blender has already evaluated (switching to
Rendered shading) to that redraw's end; "after a light move" is from the move to the end of the next
redraw (Blender's evaluation of the move included).  F12 is ``bpy.ops.render.render()`` at 320 x 240.
Each time is split into the add-on's scene build (Blender data to tracer scene) and compile_scene.
Prints the medians as JSON and writes them to bench/results/blender_updates.json.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
STEPS = ("viewport_first_pixel", "viewport_after_light_move", "f12_first", "f12_after_light_move")


def child(root: str, grid: int) -> dict:
    """One run in this process, with the add-on and tracer of ``root``."""
    sys.path[:0] = [root, str(Path(root) / "tests")]
    import bpy
    import numpy as np

    from addon import engine
    from blender_scripts.addon_env import fresh, set_resolution

    fresh()
    import tracer.compile as compile_module
    import tracer.native  # noqa: F401  (the C core, built on first use in a fresh checkout: not part of any step)
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=grid, y_subdivisions=grid, size=4)
    mesh = bpy.context.active_object.data
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    co = co.reshape(-1, 3)
    co[:, 2] = 0.3 * np.sin(3.0 * co[:, 0]) * np.cos(2.0 * co[:, 1])
    mesh.vertices.foreach_set("co", co.ravel())
    mesh.update()
    polygons = len(mesh.polygons)
    bpy.ops.object.light_add(type="POINT", location=(-1.0, 0.0, 2.0))
    light = bpy.context.active_object
    light.data.energy = 1000.0
    bpy.ops.object.camera_add(location=(0.0, -5.0, 6.0), rotation=(0.6, 0.0, 0.0))
    camera = bpy.context.scene.camera = bpy.context.active_object
    set_resolution(320, 240)
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    scene.sdl_render.block_size = 8

    split = {"build": 0.0, "compile": 0.0}
    build_scene, compile_scene = engine.build_scene, compile_module.compile_scene

    def timed(name, function):
        def run(*args, **kwargs):
            started = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                split[name] += time.perf_counter() - started
        return run

    engine.build_scene = timed("build", build_scene)
    compile_module.compile_scene = timed("compile", compile_scene)
    if hasattr(engine, "compile_scene"):  # (the add-on imports it by name since its imports became plain ones)
        engine.compile_scene = compile_module.compile_scene

    class Viewport:  # the engine's viewport methods on a stand-in (see tests/test_addon_updates.py)
        _view, _view_dirty, _view_scene, _draw_seconds = None, True, None, 0.0
        view_draw = engine.SDLRenderEngine.__dict__["view_draw"]
        view_update = engine.SDLRenderEngine.__dict__["view_update"]
        info = ""

        def tag_redraw(self):
            pass

        def update_stats(self, stats, info):
            self.info = info

        def _draw(self, scene, rgba, width, height):
            pass

    view = Viewport()
    if hasattr(engine.SDLRenderEngine, "_start"):
        engine.SDLRenderEngine._start(view)
    elif hasattr(engine, "object_cache"):
        view._geometry = engine.object_cache.ObjectCache()
    depsgraph = bpy.context.evaluated_depsgraph_get()
    persp = camera.calc_matrix_camera(depsgraph, x=320, y=240) @ camera.matrix_world.inverted()
    context = type("Context", (), {"region": type("Region", (), {"width": 320, "height": 240}),
                                   "region_data": type("RegionView3D", (), {"perspective_matrix": persp})})
    bpy.app.handlers.depsgraph_update_post.append(lambda scene, graph: view.view_update(context, graph))
    results = {"polygons": polygons}

    def measure(name, action):
        for key in split:
            split[key] = 0.0
        started = time.perf_counter()
        action()
        results[name] = {"seconds": round(time.perf_counter() - started, 3),
                         **{key: round(value, 3) for key, value in split.items()}}

    def first_redraw():
        view.view_draw(context, bpy.context.evaluated_depsgraph_get())

    def move_and_redraw():
        light.location.x += 0.5
        first_redraw()

    measure("viewport_first_pixel", first_redraw)
    measure("viewport_after_light_move", move_and_redraw)
    scene.render.use_persistent_data = True
    measure("f12_first", lambda: bpy.ops.render.render())
    light.location.x += 0.5
    measure("f12_after_light_move", lambda: bpy.ops.render.render())
    scene.render.use_persistent_data = False
    return results


def export_commit(commit: str, folder: Path) -> Path:
    """The files of ``commit`` (git archive), in ``folder``."""
    archive = folder / "before.tar"
    with open(archive, "wb") as out:
        subprocess.run(["git", "archive", commit], cwd=ROOT, stdout=out, check=True)
    target = folder / "before"
    with tarfile.open(archive) as tar:
        tar.extractall(target)
    return target


def run_child(root: Path, grid: int) -> dict:
    proc = subprocess.run([sys.executable, __file__, "--child", str(root), "--grid", str(grid)],
                          capture_output=True, text=True, cwd=root)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise SystemExit(f"error: the run in {root} failed:\n{proc.stdout[-3000:]}{proc.stderr[-3000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--before", default="16d0c89", help="the commit to compare with (default: 16d0c89)")
    parser.add_argument("--grid", type=int, default=1000, help="quads per side (default 1000: 10^6 polygons)")
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--child", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print("RESULT " + json.dumps(child(args.child, args.grid)), flush=True)
        os._exit(0)  # (Blender's exit with a million-polygon scene is slow and measures nothing)
    runs = {"before": [], "after": []}
    with tempfile.TemporaryDirectory() as folder:
        before = export_commit(args.before, Path(folder))
        for _ in range(args.repeat):
            for name, root in (("before", before), ("after", ROOT)):
                runs[name].append(run_child(root, args.grid))
                print(name, json.dumps(runs[name][-1]), file=sys.stderr, flush=True)
    summary = {"grid": args.grid, "polygons": runs["after"][0]["polygons"], "before_commit": args.before,
               "repeat": args.repeat}
    for name, results in runs.items():
        summary[name] = {step: {key: round(statistics.median(r[step][key] for r in results), 3)
                                for key in ("seconds", "build", "compile")} for step in STEPS}
    text = json.dumps(summary, indent=2)
    print(text)
    out = ROOT / "bench" / "results" / "blender_updates.json"
    out.write_text(text + "\n")


if __name__ == "__main__":
    main()
