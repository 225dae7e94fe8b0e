"""Building big scenes: N small spheres (one SDL line each), compiled and flattened for the C core.

    python3 bench/compile_scale.py [--counts 1e4,1e5,1e6] [--repeat 3] [--source sdl|table|list]
                                   [--threads 2] [--against DIR] [--out bench/results]

The build is what bench/scale.py calls "build": ``compile_scene`` (inverses, bounds, material tables, live
effects) and ``make_tracer(compiled, "c", threads)`` (flattening the compiled scene into the C core's arrays
and the C core's object BVH, built on those threads).  Each build runs in a fresh process after the scene
has been made (not timed): wall and CPU seconds of each part.  ``--source`` says how the scene is made:
``sdl`` writes bench/run.py's sphere_scene and reads it with tracer.load (whichever reader that checkout
has); ``table`` makes the same scene directly as a ShapeTable (bench/sphere_table.py: what a columnar reader
hands over); ``list`` makes that table into its list of Shapes (what the Python reader hands over).  A second
process per count measures memory: with tracemalloc, the bytes per object the scene model keeps, those the
compiled scene keeps and those the flattened scene adds (NumPy's arrays and Python's objects; the C core's
own allocations, its object BVH, are not traced) and the peak while building; and the growth of the resident
set over the whole build (which includes the C core's allocations, and whatever freed memory the allocator
keeps).  ``--against DIR`` times another checkout in turn, as bench/sdl_read.py does (with ``--source sdl``
for a checkout without ShapeTable).  Writes compile_scale.json into --out.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

from run import machine, sphere_scene  # noqa: E402
from sdl_read import _PRELUDE, run_child  # noqa: E402

#: Run in the child first: make the scene (sys.argv[1]: an SDL file, or "table:N" / "list:N").
_SCENE = _PRELUDE + """
def make_scene(source):
    import tracer
    kind, _, count = source.partition(":")
    if kind not in ("table", "list"):
        return tracer.load(source)
    sys.path.insert(0, BENCH)
    from sphere_table import sphere_table_scene
    scene = sphere_table_scene(int(count))
    if kind == "list":
        scene.objects = list(scene.objects)
    return scene
"""

#: Run in the child: make the scene, then build, timing compile_scene and make_tracer apart.
_TIMED = """
import json, sys, time
import tracer
import tracer.native  # (loaded, or built, before the clock starts)
from tracer.backend import make_tracer
from tracer.bulk import one_blas_thread
from tracer.compile import compile_scene
scene = make_scene(sys.argv[1])
with one_blas_thread():
    t0, c0 = time.perf_counter(), time.process_time()
    compiled = compile_scene(scene)
    t1, c1 = time.perf_counter(), time.process_time()
    make_tracer(compiled, "c", THREADS)
    t2, c2 = time.perf_counter(), time.process_time()
print(json.dumps({"compile_wall": t1 - t0, "compile_cpu": c1 - c0, "flatten_wall": t2 - t1, "flatten_cpu": c2 - c1,
                  "objects": len(scene.objects), "tracer": tracer.__file__}))
"""

_MEMORY = """
import gc, json, sys, tracemalloc
import tracer
import tracer.native
from tracer.backend import make_tracer
from tracer.bulk import one_blas_thread
from tracer.compile import compile_scene

def resident():
    with open("/proc/self/status") as status:
        return next(int(line.split()[1]) * 1024 for line in status if line.startswith("VmRSS:"))

tracemalloc.start()
scene = make_scene(sys.argv[1])
gc.collect()
model_bytes = tracemalloc.get_traced_memory()[0]
tracemalloc.stop()
rss = resident()
tracemalloc.start()
with one_blas_thread():
    compiled = compile_scene(scene)
    gc.collect()
    compiled_bytes = tracemalloc.get_traced_memory()[0]
    make_tracer(compiled, "c", THREADS)
gc.collect()
total, peak = tracemalloc.get_traced_memory()
n = len(scene.objects)
print(json.dumps({"model_per_object": model_bytes / n, "compiled_per_object": compiled_bytes / n,
                  "flattened_per_object": (total - compiled_bytes) / n, "peak_per_object": peak / n,
                  "resident_growth_per_object": (resident() - rss) / n}))
"""


def child_code(body: str, threads: int) -> str:
    """The code a child runs: make the scene (with this checkout's bench/sphere_table.py), then ``body``."""
    return (_SCENE.replace("BENCH", repr(str(ROOT / "bench"))) + body).replace("THREADS", str(threads))


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--counts", default="1e4,1e5,1e6", help="numbers of spheres, comma-separated")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--against", type=Path, help="another checkout to time in turn with this one")
    p.add_argument("--no-memory", action="store_true", help="skip the memory runs")
    p.add_argument("--source", choices=("sdl", "table", "list"), default="sdl",
                   help="how the scene is made: read from SDL, or made as a ShapeTable or its list of Shapes")
    p.add_argument("--threads", type=int, default=2, help="the C core's threads (its object BVH build)")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = p.parse_args(argv)
    sides = {"this": ROOT} | ({"against": args.against.resolve()} if args.against else {})
    results = {"machine": machine(), "date": time.strftime("%Y-%m-%d %H:%M:%S"), "source": args.source,
               "threads": args.threads, "sides": {k: str(v) for k, v in sides.items()},
               "load_average_start": os.getloadavg(), "rows": []}
    timed, memory = child_code(_TIMED, args.threads), child_code(_MEMORY, args.threads)
    with tempfile.TemporaryDirectory() as tmp:
        for count in (int(float(c)) for c in args.counts.split(",")):
            path = Path(tmp) / f"spheres{count}.sdl"
            if args.source == "sdl":
                path.write_text(sphere_scene(count))
            source = str(path) if args.source == "sdl" else f"{args.source}:{count}"
            row = {"spheres": count}
            runs = {side: [] for side in sides}
            for _ in range(args.repeat):
                for side, checkout in sides.items():
                    runs[side].append(run_child(timed, checkout, source))
            for side in sides:
                row[side] = {key: [r[key] for r in runs[side]]
                             for key in ("compile_wall", "compile_cpu", "flatten_wall", "flatten_cpu")}
                if not args.no_memory:
                    row[side].update(run_child(memory, sides[side], source))
            row["load_average"] = os.getloadavg()
            results["rows"].append(row)
            print(describe(row, sides), flush=True)
            path.unlink(missing_ok=True)
    args.out.mkdir(parents=True, exist_ok=True)
    (args.out / "compile_scale.json").write_text(json.dumps(results, indent=1))
    return 0


def describe(row: dict, sides: dict) -> str:
    parts = [f"{row['spheres']:>9,} spheres:"]
    for side in sides:
        r = row[side]
        build = [a + b for a, b in zip(r["compile_cpu"], r["flatten_cpu"])]
        text = (f"{side} build {min(w + f for w, f in zip(r['compile_wall'], r['flatten_wall'])):.2f} s wall, "
                f"{min(build):.2f} s CPU ({min(r['compile_cpu']):.2f} compile + {min(r['flatten_cpu']):.2f} flatten)")
        if "compiled_per_object" in r:
            text += (f"; model {r['model_per_object']:.0f} B/object, compiled {r['compiled_per_object']:.0f} + "
                     f"flattened {r['flattened_per_object']:.0f} B/object kept, "
                     f"peak {r['peak_per_object']:.0f}, resident +{r['resident_growth_per_object']:.0f}")
        parts.append(text)
    if "against" in sides:
        cpu = {side: statistics.median(a + b for a, b in zip(row[side]["compile_cpu"], row[side]["flatten_cpu"]))
               for side in sides}
        parts.append(f"this/against (median CPU) {cpu['this'] / cpu['against']:.2f}")
    return "  ".join(parts)


if __name__ == "__main__":
    sys.exit(main())
