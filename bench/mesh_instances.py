"""Instances of one mesh, without Blender: N mesh shapes sharing one MeshData (a UV sphere of about T
triangles), each under its own rotation, scale and translation on a grid, compiled by ``compile_scene``;
what geometry nodes' Instance on Points hands the tracer through the add-on (bench/blender_instances.py
measures that inside bpy).

    python bench/mesh_instances.py [--instances 100000] [--triangles 10000] [--repeat 2] [--against DIR]
                                   [--render 160x120] [--rows]

Each measurement runs in a fresh process, this checkout and ``--against DIR`` (another checkout, e.g.
/work/main) in turn, so that both see the same load: CPU seconds of ``compile_scene`` (the mesh's BVH is
built first by a compile of one instance, not timed, as a file's mesh is found again by content), and of a
C render at ``--render`` (to see that cheaper bounds do not cost tracing time), and the resident size's peak
growth from the compile to the render's end, per instance (the scene's making before it not counted).  A second process per side
counts, with tracemalloc, the bytes per instance the scene model (Shapes and their matrices) and the
compiled scene keep.  Prints JSON and writes bench/results/mesh_instances.json (with ``--rows``, the
instances as a table's float32 rows, as the add-on hands them over: mesh_instance_rows.json).
"""
from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

from run import machine  # noqa: E402

#: Run in the child first: the checkout (last argument) on the path, and the scene.
_SCENE = """
import sys
sys.meta_path[:] = [finder for finder in sys.meta_path if not type(finder).__module__.startswith("_editable")]
sys.path.insert(0, sys.argv.pop())
import numpy as np
from tracer.meshdata import MeshData
from tracer.model import Camera, Light, Material, Scene, Shape


def uv_sphere(triangles):
    rings = max(3, round((triangles / 4) ** 0.5))
    segments = 2 * rings
    theta = np.linspace(0.0, np.pi, rings + 1)[1:-1]
    phi = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    ring = np.stack([np.sin(theta)[:, None] * np.cos(phi), np.sin(theta)[:, None] * np.sin(phi),
                     np.cos(theta)[:, None] + 0 * phi], axis=-1).reshape(-1, 3)
    vertices = np.concatenate([[(0.0, 0.0, 1.0)], ring, [(0.0, 0.0, -1.0)]])
    faces = []
    bottom = len(vertices) - 1
    for s in range(segments):
        t = (s + 1) % segments
        faces.append((0, 1 + s, 1 + t))
        for r in range(rings - 3):
            a, b = 1 + r * segments, 1 + (r + 1) * segments
            faces.append((a + s, b + s, b + t, a + t))
        last = 1 + (rings - 2) * segments
        faces.append((last + s, bottom, last + t))
    faces = [(f, f) for f in faces]
    return MeshData(vertices, vertices.copy(), faces, origin="bench:uv_sphere")


def make_scene(instances, triangles, rows=False):
    rng = np.random.default_rng(1)
    mesh = uv_sphere(triangles)
    side = max(1, round(instances ** 0.5))
    material = Material(diffuse=(0.8, 0.3, 0.2))
    objects = []
    for i in range(instances):
        axis = rng.normal(size=3)
        axis /= np.linalg.norm(axis)
        angle = rng.uniform(0, np.pi)
        k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
        rotation = np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k
        matrix = np.eye(4)
        matrix[:3, :3] = rotation * rng.uniform(0.6, 1.4, size=3)
        matrix[:3, 3] = (3.0 * (i % side - side / 2), 3.0 * (i // side - side / 2), 0.0)
        objects.append(matrix if rows else Shape("mesh", matrix, material, mesh=mesh))
    if rows:  # (as the add-on hands over geometry nodes' instances: float32 matrices, rows of a table)
        from tracer.model import TableRows
        table = TableRows()
        table.add_block(np.array(objects, dtype=np.float32), np.full(instances, table.part("mesh", mesh, material)))
        objects = table.table()
    camera = Camera(eye=(0.0, -side * 2.0, side * 1.5), look=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0))
    return Scene(objects=objects, lights=[Light(position=(side, -side, side * 2.0), color=(1.0, 1.0, 1.0))],
                 camera=camera)
"""

#: Run in the child: compile (after a one-instance compile that builds the mesh's BVH), then render.
_TIMED = _SCENE + """
import dataclasses, json, time
import tracer.native
from tracer.bulk import one_blas_thread
from tracer.compile import compile_scene
from tracer.render import render
instances, triangles, width, height, rows = (int(a) for a in sys.argv[1:6])
scene = make_scene(instances, triangles, rows)
warm = compile_scene(make_scene(1, triangles))


def resident(field):
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith(field))


import ctypes
ctypes.CDLL("libc.so.6").malloc_trim(0)  # (what the scene's making freed given back: else the compile reuses it)
with open("/proc/self/clear_refs", "w") as refs:  # (the peak from here on: the scene's making is not counted)
    refs.write("5")
before = resident("VmRSS:")
with one_blas_thread():
    cpu = time.process_time()
    compiled = compile_scene(scene)
    compile_cpu = time.process_time() - cpu
cpu = time.process_time()
result = render(scene, width, height, backend="c", threads=1) if width else None
render_cpu = time.process_time() - cpu
print(json.dumps({"compile_cpu": compile_cpu, "render_cpu": render_cpu,
                  "peak_growth_per_instance": (resident("VmHWM:") - before) / instances,
                  "image_sum": float(result.image.sum()) if result else None}))
"""

#: Run in the child: the bytes per instance the model and the compiled scene keep.
_MEMORY = _SCENE + """
import dataclasses, gc, json, tracemalloc
import tracer.native
from tracer.compile import compile_scene
instances, triangles, rows = (int(a) for a in sys.argv[1:4])
probe = make_scene(1, triangles)
tracemalloc.start()
scene = make_scene(instances, triangles, rows)
gc.collect()
model = tracemalloc.get_traced_memory()[0]
tracemalloc.stop()
warm = compile_scene(probe)
tracemalloc.start()
compiled = compile_scene(scene)
gc.collect()
kept, peak = tracemalloc.get_traced_memory()
print(json.dumps({"model_per_instance": model / instances, "compiled_per_instance": kept / instances,
                  "compile_peak_per_instance": peak / instances}))
"""


def run_child(code: str, checkout: Path, *args) -> dict:
    done = subprocess.run([sys.executable, "-c", code, *map(str, args), str(checkout)], capture_output=True,
                          text=True, cwd=str(checkout))
    if done.returncode != 0:
        raise RuntimeError(f"the bench with {checkout} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--instances", type=int, default=100_000)
    p.add_argument("--triangles", type=int, default=10_000)
    p.add_argument("--repeat", type=int, default=2)
    p.add_argument("--render", default="160x120", help="the C render's size, or 'none'")
    p.add_argument("--rows", action="store_true", help="the instances as rows of a table of float32 matrices, "
                   "as the add-on hands over geometry nodes' instances (compile.InstancedTable)")
    p.add_argument("--against", type=Path, help="another checkout to measure in turn with this one")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = p.parse_args(argv)
    width, height = (0, 0) if args.render == "none" else (int(v) for v in args.render.split("x"))
    sides = {"this": ROOT} | ({"against": args.against.resolve()} if args.against else {})
    runs = {side: [] for side in sides}
    for _ in range(args.repeat):
        for side, checkout in sides.items():
            runs[side].append(run_child(_TIMED, checkout, args.instances, args.triangles, width, height,
                                        int(args.rows)))
    result = {"machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M:%S"), "instances": args.instances,
              "triangles": args.triangles, "render": args.render, "rows": args.rows, "sides": {k: str(v) for k, v in sides.items()}}
    for side, checkout in sides.items():
        row = {key: [r[key] for r in runs[side]] for key in ("compile_cpu", "render_cpu", "image_sum",
                                                              "peak_growth_per_instance")}
        row["compile_cpu_median"] = statistics.median(row["compile_cpu"])
        row["render_cpu_median"] = statistics.median(row["render_cpu"])
        row.update(run_child(_MEMORY, checkout, args.instances, args.triangles, int(args.rows)))
        result[side] = row
    text = json.dumps(result, indent=1)
    print(text)
    args.out.mkdir(exist_ok=True)
    (args.out / ("mesh_instance_rows.json" if args.rows else "mesh_instances.json")).write_text(text + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
