"""What an edit of a compiled scene costs (tracer.edit.EditableScene) against compiling the edited scene again.

    python bench/scene_edit.py                 # 10^4 and 10^5 spheres, 3 repeats, 2 threads
    python bench/scene_edit.py --sizes 10000 --repeat 5 --threads 2 --json out.json

The scene: N small spheres, each of its own material (as an import of one SDL line per sphere makes them),
over a checkered plane, one light.  After a first render (the viewport's state before the edit), per size:

* ``move``: ``set_transform`` of one sphere (its rows, its object box, the refit of the C core's hierarchy);
* ``move + first block``: that, then the first 64 x 48 render of the scene (all it takes to see the edit);
* ``material``: ``set_material`` of one sphere to a new material (one new material row);
* ``animation frame``: ``set_transforms`` of every sphere at once (one pass over the rows, one rebuild);
* ``add`` / ``remove``: one sphere added / removed (rows resized, the FlatScene made anew, the hierarchy rebuilt);
* ``rebuild + first block``: what the add-on did before: compile the edited scene from scratch (a new Scene of
  the same objects) and render its first 64 x 48 image (the C core's scene made anew, hierarchy and all).

Times are CPU seconds of this process (all threads; the machine is shared) and wall seconds, the median of the
repeats, each repeat on a different sphere.  Nothing here is asserted: tests/test_edit.py checks that the
edited scene renders as the rebuilt one.
"""
from __future__ import annotations

import argparse
import dataclasses
import json
import statistics
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

from tracer.backend import load_core  # noqa: E402
from tracer.compile import compile_scene  # noqa: E402
from tracer.edit import EditableScene  # noqa: E402
from tracer.model import Camera, Light, Material, Scene, Settings, Shape  # noqa: E402
from tracer.render import render  # noqa: E402
from tracer.transforms import rotation, scaling, translation  # noqa: E402

WIDTH, HEIGHT = 64, 48


def spheres(n: int, seed: int = 0) -> Scene:
    rng = np.random.default_rng(seed)
    side = max(1.0, n ** (1 / 3))
    centres = rng.uniform(-side, side, (n, 3))
    colours = rng.uniform(0.1, 1.0, (n, 3))
    objects = [Shape("sphere", translation(*c) @ scaling(0.3, 0.3, 0.3), Material(diffuse=tuple(d)))
               for c, d in zip(centres.tolist(), colours.tolist())]
    objects.append(Shape("plane", translation(0, -side - 1, 0) @ rotation(-90, 1, 0, 0),
                         Material(diffuse=(0.8, 0.8, 0.8), texture=-1, parameters=(2,))))
    return Scene(objects=objects, lights=[Light((side * 2, side * 3, side * 4), (1, 1, 1))],
                 camera=Camera(eye=(0, side * 0.5, side * 3.5), look=(0, 0, 0), view_angle=45),
                 settings=Settings(max_recursion_depth=2))


def timed(action) -> tuple[float, float]:
    cpu, wall = time.process_time(), time.perf_counter()
    action()
    return time.process_time() - cpu, time.perf_counter() - wall


def first_block(compiled, threads: int) -> None:
    render(compiled, WIDTH, HEIGHT, backend="c", threads=threads)


def measure(n: int, repeat: int, threads: int) -> dict:
    editable = EditableScene(spheres(n))
    first_block(editable.compiled, threads)  # (the state an edit starts from: the scene traced once)
    rng = np.random.default_rng(n)
    rows: dict[str, list[tuple[float, float]]] = {}

    def record(name: str, action) -> None:
        rows.setdefault(name, []).append(timed(action))

    for r in range(repeat):
        k = int(rng.integers(n))
        moved = translation(*rng.uniform(-1, 1, 3)) @ editable.objects_of(k)[0].matrix
        record("move", lambda: editable.set_transform(k, moved))
        k = int(rng.integers(n))
        moved = translation(*rng.uniform(-1, 1, 3)) @ editable.objects_of(k)[0].matrix

        def move_and_render() -> None:
            editable.set_transform(k, moved)
            first_block(editable.compiled, threads)
        record("move + first block", move_and_render)
        k = int(rng.integers(n))
        material = Material(diffuse=tuple(rng.uniform(0, 1, 3)), reflectivity=0.2)
        record("material", lambda: editable.set_material(k, material))
        frame = [(k, translation(0, 0.01 * (r + 1), 0) @ editable.objects_of(k)[0].matrix) for k in range(n)]
        record("animation frame", lambda: editable.set_transforms(frame))
        record("add", lambda: editable.add_objects(("added", r), [
            Shape("sphere", translation(*rng.uniform(-2, 2, 3)) @ scaling(0.3, 0.3, 0.3), Material())]))
        record("remove", lambda: editable.remove_objects(("added", r)))

        def rebuild_and_render() -> None:
            fresh = dataclasses.replace(editable.scene, objects=list(editable.scene.objects))
            first_block(compile_scene(fresh), threads)
        record("rebuild + first block", rebuild_and_render)
    return {name: {"cpu_s": statistics.median(c for c, _ in values), "wall_s": statistics.median(w for _, w in values)}
            for name, values in rows.items()}


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--sizes", type=int, nargs="+", default=[10_000, 100_000])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--json", type=Path)
    args = parser.parse_args(argv)
    load_core("c")
    results = {}
    for n in args.sizes:
        results[n] = measure(n, args.repeat, args.threads)
        print(f"{n:>8} objects", flush=True)
        for name, value in results[n].items():
            print(f"    {name:<24} {value['cpu_s'] * 1000:9.2f} ms CPU  {value['wall_s'] * 1000:9.2f} ms wall", flush=True)
    if args.json:
        args.json.write_text(json.dumps(results, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
