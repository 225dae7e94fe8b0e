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
from typing import Optional

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

    evaluations = []  # Blender's own part: the same move evaluated with no engine listening
    for i in range(repeat):
        spheres[len(spheres) // 2].location.x += 0.05
        cpu, wall = _timed(bpy.context.evaluated_depsgraph_get)
        evaluations.append({"cpu": round(cpu, 4), "wall": round(wall, 4)})
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
                      "sync": round(engine.LAST_VIEW["sync"], 4), "scene": engine.LAST_VIEW["scene"],
                      "updates": round(engine.LAST_VIEW["updates"], 4)})
        while "done" not in view.info:
            view.view_draw(context, bpy.context.evaluated_depsgraph_get())
    return {"first_draw": round(first, 3), "after_move": edits, "evaluation_alone": evaluations}


def _screenshot(path: str) -> None:
    """The whole X screen (``$DISPLAY``) as a PNG, with ImageMagick's ``import``."""
    subprocess.run(["import", "-window", "root", "-display", os.environ.get("DISPLAY", ":0"), path],
                   capture_output=True)


class GuiMoves:
    """The ``gui`` measurement on Blender's event loop: for each shading in turn (Solid first: Blender's own
    drawing, the baseline; then Rendered: the engine's), ``repeat`` moves of one sphere, each timed from the
    move (a timer sets the location) to Blender's evaluation of it (depsgraph_update_post) and to the end of
    the viewport's first redraw after it (a POST_PIXEL draw handler: the last thing the region draws); in
    Rendered, only a redraw that drew the engine's first block after the move counts, and the engine's own
    times come with it (LAST_VIEW).  Between moves the viewport settles: no redraw for a second (the engine
    has finished refining), or 30 s."""

    def __init__(self, bpy, engine, space, sphere, repeat: int, shadings, shots):
        self.bpy, self.engine, self.space, self.sphere, self.repeat = bpy, engine, space, sphere, repeat
        self.shadings, self.shots = list(shadings), shots
        self.results = {shading: [] for shading in self.shadings}
        self.draws, self.draws_cpu, self.evaluated = [time.perf_counter()], [time.process_time()], []
        self.moved, self.since = None, time.perf_counter()
        self.space.shading.type = self.shadings[0]

    def drawn(self) -> None:
        self.draws.append(time.perf_counter())
        self.draws_cpu.append(time.process_time())

    def depsgraph_updated(self, *_args) -> None:
        self.evaluated.append(time.perf_counter())

    def quiet(self, now: float) -> bool:
        """The viewport has stopped redrawing (Rendered: the engine has finished refining), or 30 s passed."""
        return now - self.draws[-1] > 1.0 or now - self.since > 30.0

    def tick(self):
        now, shading = time.perf_counter(), self.space.shading.type
        if self.moved == "shoot":  # after a shading's last move: its screenshot, once settled
            if not self.quiet(now):
                return 0.05
            _screenshot(os.path.join(self.shots, f"gui_{shading.lower()}.png"))
            return self.next_shading()
        if self.moved is None:  # settling before a move
            if self.quiet(now):
                self.moved, self.moved_cpu = time.perf_counter(), time.process_time()
                self.sphere.location.x += 0.05
            return 0.05
        drawn = [t for t in self.draws if t > self.moved]
        if shading == "RENDERED":
            engine_drawn = self.engine.LAST_VIEW.get("drawn_at", 0.0)
            drawn = [t for t in drawn if engine_drawn > self.moved and t >= engine_drawn]
        if not drawn:
            return self.finish("no draw after a move") if now - self.moved > 120.0 else 0.005
        self.record(shading, drawn[0])
        self.moved, self.since = None, time.perf_counter()
        if len(self.results[shading]) >= self.repeat:
            if self.shots:
                self.moved = "shoot"
                return 0.05
            return self.next_shading()
        return 0.05

    def next_shading(self):
        self.shadings.pop(0)
        if not self.shadings:
            return self.finish()
        self.space.shading.type = self.shadings[0]
        self.moved, self.since = None, time.perf_counter()
        return 0.05

    def record(self, shading: str, drawn: float) -> None:
        evaluated = [t for t in self.evaluated if t > self.moved]
        cpu = self.draws_cpu[self.draws.index(drawn)]
        entry = {"from_move": round(drawn - self.moved, 4), "cpu_from_move": round(cpu - self.moved_cpu, 4),
                 "evaluated": round(evaluated[0] - self.moved, 4) if evaluated else None}
        if shading == "RENDERED":
            view = self.engine.LAST_VIEW
            entry.update({"engine_drawn": round(view["drawn_at"] - self.moved, 4),
                          "from_view_update": round(view["first_block"], 4),
                          "until_view_draw": round(view["until_view_draw"], 4),
                          "sync": round(view["sync"], 4), "scene": view["scene"],
                          "updates": round(view.get("updates", 0.0), 4)})
        self.results[shading].append(entry)

    def finish(self, error: Optional[str] = None):
        result = {"after_move": self.results.get("RENDERED", []),
                  "solid_after_move": self.results.get("SOLID", [])}
        if error:
            result["error"] = error
        print("RESULT " + json.dumps(result), flush=True)
        os._exit(0)


def child_gui(blend: str, sdl: str, repeat: int) -> None:
    """In Blender's window: the 3D viewport alone (as Ctrl Alt Space shows it), overlays off, through the
    camera; Solid shading then Rendered, ``repeat`` moves each (GuiMoves).  Prints RESULT and quits; with
    ``--shots DIR``, a screenshot of each shading after its last move, settled."""
    bpy, engine, scene, spheres = _setup(blend, sdl)
    window = bpy.context.window_manager.windows[0]
    area = next(a for a in window.screen.areas if a.type == "VIEW_3D")
    space = area.spaces.active
    space.region_3d.view_perspective = "CAMERA"
    if "--whole-window" not in sys.argv:  # the viewport alone: no other editor to draw
        with bpy.context.temp_override(window=window, area=area):
            bpy.ops.screen.screen_full_area(use_hide_panels=True)
    if "--overlays" not in sys.argv:  # (Blender's overlays draw every object's origin: software OpenGL's time)
        space.overlay.show_overlays = False
    shots = sys.argv[sys.argv.index("--shots") + 1] if "--shots" in sys.argv else None
    moves = GuiMoves(bpy, engine, space, spheres[len(spheres) // 2], repeat, ("SOLID", "RENDERED"), shots)
    bpy.types.SpaceView3D.draw_handler_add(moves.drawn, (), "WINDOW", "POST_PIXEL")
    bpy.app.handlers.depsgraph_update_post.append(moves.depsgraph_updated)
    bpy.app.timers.register(moves.tick, first_interval=2.0)


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
    parser.add_argument("--measure", nargs="+", choices=sorted(CHILDREN), default=sorted(CHILDREN),
                        help="what to measure in the bpy module and blender -b (all by default)")
    parser.add_argument("--gui-counts", type=int, nargs="+", help="with --gui: only these counts in the window")
    parser.add_argument("--out", default=str(ROOT / "bench" / "results" / "blender_edit.json"),
                        help="where the JSON goes (bench/results/blender_edit.json)")
    parser.add_argument("--blends", help="keep the imported .blend files in this folder (and reuse them)")
    parser.add_argument("--merge", action="store_true",
                        help="keep the other counts' runs already in bench/results/blender_edit.json")
    parser.add_argument("--shots", help="with --gui: a folder for screenshots of each shading, settled")
    parser.add_argument("--child", nargs=4, metavar=("WHAT", "BLEND", "SDL", "REPEAT"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        what, blend, sdl, repeat = args.child
        if what == "gui":
            try:
                child_gui(blend, sdl, int(repeat))
            except Exception as exc:  # (else Blender's window stays open, waiting)
                print("RESULT " + json.dumps({"error": repr(exc), "after_move": []}), flush=True)
                os._exit(1)
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
            blender_env = dict(os.environ, PYTHONPATH=blender_numpy_path(blender, folder))
            if args.blender:
                hosts["blender_b"] = ([blender, "-b", "--factory-startup", "--python", __file__, "--"],
                                      blender_env)
        for count in args.counts:
            sdl = folder / f"spheres_{count}.sdl"
            sdl.write_text(sphere_scene(count))
            for host, (command, env) in hosts.items():
                blend = Path(args.blends or folder) / f"spheres_{count}_{host}.blend"
                for what in args.measure:
                    result = run_child(command + ["--child", what, str(blend), str(sdl), str(args.repeat)], env)
                    results.setdefault(f"{host} {count}", {})[what] = result
                    print(host, count, what, json.dumps(result), file=sys.stderr, flush=True)
            if args.gui and blender and count in (args.gui_counts or args.counts):
                blend = folder / f"spheres_{count}_gui.blend"
                command = [blender, "--factory-startup", "--python", __file__, "--", "--child", "gui", str(blend),
                           str(sdl), str(args.repeat)]
                if args.shots:
                    os.makedirs(args.shots, exist_ok=True)
                    command += ["--shots", os.path.abspath(f"{args.shots}/{count}")]
                    os.makedirs(command[-1], exist_ok=True)
                result = run_child(command, blender_env, timeout=1200.0)
                results.setdefault(f"gui {count}", {})["view"] = result
                print("gui", count, json.dumps(result), file=sys.stderr, flush=True)
    out = Path(args.out)
    if args.merge and out.exists():  # (another run's counts, kept beside these)
        results = {**json.loads(out.read_text())["runs"], **results}
    summary = {"runs": results, "median": {}}
    for key, kinds in results.items():
        medians = {}
        if "f12" in kinds:
            medians["f12_after_move_cpu"] = statistics.median(m["cpu"] for m in kinds["f12"]["after_move"])
            medians["f12_after_move_wall"] = statistics.median(m["wall"] for m in kinds["f12"]["after_move"])
        if "animation" in kinds:
            medians["animation_made_after_frame_1"] = kinds["animation"]["made_after_frame_1"]
        if "view" in kinds and kinds["view"].get("evaluation_alone"):  # Blender's evaluation of a move, alone
            medians["evaluation_alone_cpu"] = statistics.median(m["cpu"] for m in kinds["view"]["evaluation_alone"])
            medians["evaluation_alone_wall"] = statistics.median(m["wall"] for m in kinds["view"]["evaluation_alone"])
        if "view" in kinds and kinds["view"]["after_move"]:
            for name in ("from_move", "cpu_from_move", "from_view_update", "until_view_draw", "engine_drawn",
                         "evaluated", "updates", "sync"):
                values = [m[name] for m in kinds["view"]["after_move"] if m.get(name) is not None]
                if values:
                    medians[f"first_block_{name}"] = statistics.median(values)
        if "view" in kinds and kinds["view"].get("solid_after_move"):  # Blender's own redraw, in Solid shading
            for name in ("from_move", "cpu_from_move", "evaluated"):
                values = [m[name] for m in kinds["view"]["solid_after_move"] if m.get(name) is not None]
                if values:
                    medians[f"solid_redraw_{name}"] = statistics.median(values)
        summary["median"][key] = medians
    if blender:
        summary["blender"] = subprocess.run([blender, "--version"], capture_output=True,
                                            text=True).stdout.splitlines()[0]
    print(json.dumps(summary["median"], indent=1))
    import bpy  # (the bpy module this ran with)

    summary["bpy"] = bpy.app.version_string
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(json.dumps(summary, indent=1) + "\n")


if __name__ == "__main__":
    if "--" in sys.argv:  # under blender: the script's own arguments follow "--"
        sys.argv = [sys.argv[0]] + sys.argv[sys.argv.index("--") + 1:]
    main()
