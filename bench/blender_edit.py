"""Blender while editing: F12 and the viewport after a change, on bench/run.py's scenes of N spheres.

    python bench/blender_edit.py [--counts 1000 10000 100000] [--repeat 3] [--blender] [--gui]

For each count N the scene of N spheres of their own colours (one SDL line each) is imported once per host
and saved as a .blend; each measurement then runs in its own process on that file:

* ``f12``: F12 at 64 x 48 with Persistent Data on: the first render, then a render after each of ``--repeat``
  moves of one sphere (``bpy.ops.render.render()``, the whole operator, CPU and wall seconds) and how the
  engine made its scene (``edit``: the kept scene edited, not built);
* ``animation``: every sphere's location keyframed at frames 1 and 3, frames 1, 2, 3 rendered (64 x 48,
  Persistent Data on): seconds per frame, and the meshes read out of Blender after frame 1 (the engine's
  object cache counts them: 0 expected);
* ``view``: the viewport (Rendered), driven as Blender drives it: a sphere moved, Blender's evaluation of
  the move (which calls view_update), then redraws; seconds from the move to the first block drawn, and
  from view_update to it (what the engine shows in its status text), 320 x 240.  Without a window there is
  no GPU drawing: the texture upload is left out;
* ``gui`` (with ``--gui``, Debian's Blender 3.4 on ``$DISPLAY``, e.g. under Xvfb): the same in a real 3D
  viewport in Rendered shading, the upload and Blender's own drawing included: from the move (a timer sets
  the location) to the end of the engine's first draw after it.

Hosts: the bpy module, and with ``--blender`` Debian's ``blender -b`` too.  Prints the medians as JSON and
writes everything to bench/results/blender_edit.json.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SIZE = (64, 48)
VIEW_SIZE = (320, 240)


# -- in the child process (the bpy module, or Blender's Python) ----------------------------------------------

def _setup(blend: str, sdl: str):
    """The scene: opened from ``blend``, or imported from ``sdl`` and saved there first."""
    import bpy

    sys.path.insert(0, str(ROOT))
    import addon

    addon.register()
    if os.path.exists(blend):
        bpy.ops.wm.open_mainfile(filepath=blend)
    else:
        bpy.ops.wm.read_factory_settings(use_empty=True)
        addon.register()
        bpy.ops.import_scene.sdl(filepath=sdl)
        bpy.ops.wm.save_as_mainfile(filepath=blend)
    addon.register()
    from addon import engine

    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    scene.render.resolution_x, scene.render.resolution_y = SIZE
    scene.render.resolution_percentage = 100
    spheres = [o for o in bpy.data.objects if o.get("sdl_kind") == "sphere"]
    return bpy, engine, scene, spheres


def _timed(action) -> tuple[float, float]:
    cpu, wall = time.process_time(), time.perf_counter()
    action()
    return time.process_time() - cpu, time.perf_counter() - wall


def child_f12(blend: str, sdl: str, repeat: int) -> dict:
    bpy, engine, scene, spheres = _setup(blend, sdl)
    scene.render.use_persistent_data = True
    first = _timed(lambda: bpy.ops.render.render())
    moves = []
    for i in range(repeat):
        spheres[len(spheres) // 2].location.x += 0.05
        cpu, wall = _timed(lambda: bpy.ops.render.render())
        moves.append({"cpu": round(cpu, 4), "wall": round(wall, 4), "scene": engine.LAST_RENDER.get("scene")})
    return {"first": {"cpu": round(first[0], 3), "wall": round(first[1], 3)}, "after_move": moves}


def child_animation(blend: str, sdl: str, repeat: int) -> dict:
    bpy, engine, scene, spheres = _setup(blend, sdl)
    for frame, dz in ((1, 0.0), (3, 0.3)):
        scene.frame_set(frame)
        for sphere in spheres:
            sphere.location.z += dz
            sphere.keyframe_insert("location", frame=frame)
    scene.frame_start, scene.frame_end = 1, 3
    scene.render.use_persistent_data = True
    made, frames = [], []

    def counted(_scene, *_args):  # what the render engine's object caches made, after each frame
        from addon import object_cache
        made.append(sum(sum(cache.made.values()) for cache in object_cache._LIVE))

    bpy.app.handlers.render_post.append(counted)
    for frame in (1, 2, 3):
        scene.frame_set(frame)
        cpu, wall = _timed(lambda: bpy.ops.render.render())
        frames.append({"frame": frame, "cpu": round(cpu, 3), "wall": round(wall, 3),
                       "scene": engine.LAST_RENDER.get("scene")})
    return {"frames": frames, "made_after_frame_1": made[-1] - made[0] if made else None, "made": made}


def child_view(blend: str, sdl: str, repeat: int) -> dict:
    bpy, engine, scene, spheres = _setup(blend, sdl)
    width, height = VIEW_SIZE

    class Viewport:  # the engine's viewport methods on a stand-in (see tests/test_addon_updates.py)
        view_draw = engine.SDLRenderEngine.__dict__["view_draw"]
        view_update = engine.SDLRenderEngine.__dict__["view_update"]
        _draw_seconds = 0.0
        info = ""

        def tag_redraw(self):
            pass

        def update_stats(self, stats, info):
            self.info = info

        def _draw(self, scene, rgba, w, h):
            pass

    view = Viewport()
    engine.SDLRenderEngine._start(view)
    camera = scene.camera
    depsgraph = bpy.context.evaluated_depsgraph_get()
    persp = camera.calc_matrix_camera(depsgraph, x=width, y=height) @ camera.matrix_world.inverted()
    context = type("Context", (), {"region": type("Region", (), {"width": width, "height": height}),
                                   "region_data": type("RegionView3D", (), {"perspective_matrix": persp})})
    bpy.app.handlers.depsgraph_update_post.append(lambda scene, graph: view.view_update(context, graph))
    started = time.perf_counter()
    view.view_draw(context, bpy.context.evaluated_depsgraph_get())
    first = time.perf_counter() - started
    while "done" not in view.info:
        view.view_draw(context, bpy.context.evaluated_depsgraph_get())
    edits = []
    for i in range(repeat):
        moved, moved_cpu = time.perf_counter(), time.process_time()
        spheres[len(spheres) // 2].location.x += 0.05
        view.view_draw(context, bpy.context.evaluated_depsgraph_get())  # (evaluating calls view_update)
        edits.append({"from_move": round(engine.LAST_VIEW["drawn_at"] - moved, 4),
                      "cpu_from_move": round(time.process_time() - moved_cpu, 4),
                      "from_view_update": round(engine.LAST_VIEW["first_block"], 4),
                      "sync": round(engine.LAST_VIEW["sync"], 4), "scene": engine.LAST_VIEW["scene"]})
        while "done" not in view.info:
            view.view_draw(context, bpy.context.evaluated_depsgraph_get())
    return {"first_draw": round(first, 3), "after_move": edits}


def child_gui(blend: str, sdl: str, repeat: int) -> None:
    """In Blender's window: Rendered shading in the 3D viewport, then ``repeat`` moves, each timed from the
    move to the end of the engine's first draw after it.  Prints RESULT and quits."""
    bpy, engine, scene, spheres = _setup(blend, sdl)
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    space = area.spaces.active
    results, state = [], {"phase": "settle", "since": time.perf_counter(), "moves": 0}
    space.region_3d.view_perspective = "CAMERA"
    space.shading.type = "RENDERED"
    if "--whole-window" not in sys.argv:  # the viewport alone, as Ctrl Alt Space shows it: no other editor to draw
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.screen.screen_full_area(use_hide_panels=True)
    if "--overlays" not in sys.argv:  # (Blender's overlays draw every object's origin: software OpenGL's time)
        space.overlay.show_overlays = False

    def tick():
        now = time.perf_counter()
        last = engine.LAST_VIEW.get("drawn_at", 0.0)
        if state["phase"] == "settle":
            if now - state["since"] > 20.0 or (last and now - last > 3.0):
                state["phase"], state["moved"] = "moved", time.perf_counter()
                spheres[len(spheres) // 2].location.x += 0.05
            return 0.05
        if last > state["moved"]:
            results.append({"from_move": round(last - state["moved"], 4),
                            "from_view_update": round(engine.LAST_VIEW["first_block"], 4),
                            "until_view_draw": round(engine.LAST_VIEW["until_view_draw"], 4),
                            "sync": round(engine.LAST_VIEW["sync"], 4), "scene": engine.LAST_VIEW["scene"]})
            state["moves"] += 1
            if state["moves"] >= repeat:
                print("RESULT " + json.dumps({"after_move": results}), flush=True)
                os._exit(0)
            state["phase"], state["since"] = "settle", time.perf_counter()
        elif now - state["moved"] > 120.0:
            print("RESULT " + json.dumps({"after_move": results, "error": "no draw after a move"}), flush=True)
            os._exit(0)
        return 0.01

    bpy.app.timers.register(tick, first_interval=2.0)


CHILDREN = {"f12": child_f12, "animation": child_animation, "view": child_view}


# -- the runs --------------------------------------------------------------------------------------------------

def run_child(command: list[str], env: dict, timeout: float = 3600.0) -> dict:
    proc = subprocess.run(command, capture_output=True, text=True, env=env, cwd=ROOT, timeout=timeout)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if not lines:
        raise SystemExit(f"error: {' '.join(command)} failed:\n{proc.stdout[-3000:]}{proc.stderr[-3000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--blender", action="store_true", help="also under Debian's blender -b")
    parser.add_argument("--gui", action="store_true", help="also in Debian's Blender's window on $DISPLAY")
    parser.add_argument("--child", nargs=4, metavar=("WHAT", "BLEND", "SDL", "REPEAT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        what, blend, sdl, repeat = args.child
        if what == "gui":
            child_gui(blend, sdl, int(repeat))
            return  # (Blender's window goes on; the timer prints the result and quits)
        print("RESULT " + json.dumps(CHILDREN[what](blend, sdl, int(repeat))), flush=True)
        os._exit(0)  # (freeing 10^5 objects at exit measures nothing)
    sys.path[:0] = [str(ROOT), str(ROOT / "bench"), str(ROOT / "tests")]
    from run import sphere_scene

    hosts = {"bpy": ([sys.executable, __file__], dict(os.environ, PYTHONPATH=str(ROOT)))}
    blender = shutil.which("blender")
    results: dict = {}
    with tempfile.TemporaryDirectory(prefix="blender_edit_") as tmp:
        folder = Path(tmp)
        if blender and (args.blender or args.gui):
            from blender_binary import blender_numpy_path
            env = dict(os.environ, PYTHONPATH=blender_numpy_path(blender, folder))
            if args.blender:
                hosts["blender_b"] = ([blender, "-b", "--factory-startup", "--python", __file__, "--"], env)
        for count in args.counts:
            sdl = folder / f"spheres_{count}.sdl"
            sdl.write_text(sphere_scene(count))
            for host, (command, env) in hosts.items():
                blend = folder / f"spheres_{count}_{host}.blend"
                for what in ("f12", "animation", "view"):
                    result = run_child(command + ["--child", what, str(blend), str(sdl), str(args.repeat)], env)
                    results.setdefault(f"{host} {count}", {})[what] = result
                    print(host, count, what, json.dumps(result), file=sys.stderr, flush=True)
            if args.gui and blender:
                blend = folder / f"spheres_{count}_gui.blend"
                command = [blender, "--factory-startup", "--python", __file__, "--", "--child", "gui", str(blend),
                           str(sdl), str(args.repeat)]
                result = run_child(command, env)
                results.setdefault(f"gui {count}", {})["view"] = result
                print("gui", count, json.dumps(result), file=sys.stderr, flush=True)
    summary = {"runs": results, "median": {}}
    for key, kinds in results.items():
        medians = {}
        if "f12" in kinds:
            medians["f12_after_move_cpu"] = statistics.median(m["cpu"] for m in kinds["f12"]["after_move"])
            medians["f12_after_move_wall"] = statistics.median(m["wall"] for m in kinds["f12"]["after_move"])
        if "animation" in kinds:
            medians["animation_made_after_frame_1"] = kinds["animation"]["made_after_frame_1"]
        if "view" in kinds and kinds["view"]["after_move"]:
            for name in ("from_move", "cpu_from_move", "from_view_update", "until_view_draw"):
                values = [m[name] for m in kinds["view"]["after_move"] if name in m]
                if values:
                    medians[f"first_block_{name}"] = statistics.median(values)
        summary["median"][key] = medians
    if blender:
        summary["blender"] = subprocess.run([blender, "--version"], capture_output=True,
                                            text=True).stdout.splitlines()[0]
    print(json.dumps(summary["median"], indent=1))
    out = ROOT / "bench" / "results"
    out.mkdir(parents=True, exist_ok=True)
    (out / "blender_edit.json").write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    if "--" in sys.argv:  # under blender: the script's own arguments follow "--"
        sys.argv = [sys.argv[0]] + sys.argv[sys.argv.index("--") + 1:]
    main()
