"""Reading big SDL files: N small spheres, one line each (bench/big_scenes.py), parsed and modelled.

    python3 bench/sdl_read.py [--counts 1e4,1e5,1e6] [--repeat 3] [--against DIR] [--memory all|this|none]
                              [--out bench/results]

Each read is ``tracer.load`` in a fresh process, timed inside it (wall and CPU seconds; Python's start-up
and imports not counted).  A second process per count measures memory with tracemalloc: the bytes per shape
the loaded Scene keeps, and the peak above the file's text while reading (tracemalloc slows the read, so
it is never timed).  With ``--against DIR``, DIR is another checkout (a folder holding its ``tracer``
package, e.g. ``git worktree add /tmp/before <commit>``): its reader and this one run in turn, interleaved,
``--repeat`` times each, so that both see the same load on a shared machine; the tables give the fastest run
of each and the ratio of the medians.  ``--memory this`` measures memory for this checkout only (an old
reader under tracemalloc may need several times the memory of the read itself).  Writes the rows into
sdl_read.json in --out, replacing rows of the same size from earlier runs and keeping the others.
"""
from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

from run import machine, sphere_scene  # noqa: E402

#: First in each child: import ``tracer`` from the checkout being measured, not from an editable install
#: (whose import hook would otherwise answer first).
_PRELUDE = """
import sys
sys.meta_path[:] = [finder for finder in sys.meta_path if not type(finder).__module__.startswith("_editable")]
sys.path.insert(0, sys.argv.pop())
"""

#: Run in the child: read the file, print what was measured as JSON.
_TIMED = _PRELUDE + """
import json, sys, time
import tracer
wall, cpu = time.perf_counter(), time.process_time()
scene = tracer.load(sys.argv[1])
print(json.dumps({"wall": time.perf_counter() - wall, "cpu": time.process_time() - cpu,
                  "shapes": len(scene.objects), "tracer": tracer.__file__}))
"""

_MEMORY = _PRELUDE + """
import gc, json, sys, tracemalloc
import tracer.sdl.parser as parser
text = open(sys.argv[1], encoding="utf-8").read()
tracemalloc.start()
before = tracemalloc.get_traced_memory()[0]
scene = parser.parse_sdl(text, file=sys.argv[1])
gc.collect()
kept, peak = tracemalloc.get_traced_memory()
print(json.dumps({"kept_per_shape": (kept - before) / len(scene.objects), "peak_mb": (peak - before) / 1e6}))
"""


def run_child(code: str, checkout: Path, path: Path) -> dict:
    done = subprocess.run([sys.executable, "-c", code, str(path), str(checkout)], capture_output=True, text=True,
                          cwd=str(checkout))
    if done.returncode != 0:
        raise RuntimeError(f"reading {path} with {checkout} failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--counts", default="1e4,1e5,1e6", help="numbers of spheres, comma-separated")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--against", type=Path, help="another checkout to time in turn with this one")
    p.add_argument("--memory", choices=("all", "this", "none"), default="all",
                   help="which sides get the tracemalloc run")
    p.add_argument("--out", type=Path, default=ROOT / "bench" / "results")
    args = p.parse_args(argv)
    sides = {"this": ROOT} | ({"against": args.against.resolve()} if args.against else {})
    out_file = args.out / "sdl_read.json"
    results = json.loads(out_file.read_text()) if out_file.exists() else {"rows": []}
    results["machine"] = machine()
    with tempfile.TemporaryDirectory() as tmp:
        for count in (int(float(c)) for c in args.counts.split(",")):
            path = Path(tmp) / f"spheres{count}.sdl"
            path.write_text(sphere_scene(count))
            row = {"spheres": count, "megabytes": path.stat().st_size / 1e6, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
                   "sides": {side: str(checkout) for side, checkout in sides.items()},
                   "load_average_start": os.getloadavg()}
            runs = {side: [] for side in sides}
            for _ in range(args.repeat):
                for side, checkout in sides.items():
                    runs[side].append(run_child(_TIMED, checkout, path))
            for side in sides:
                row[side] = {"wall": [r["wall"] for r in runs[side]], "cpu": [r["cpu"] for r in runs[side]]}
                if args.memory == "all" or (args.memory == "this" and side == "this"):
                    row[side].update(run_child(_MEMORY, sides[side], path))
            row["load_average_end"] = os.getloadavg()
            results["rows"] = sorted([r for r in results["rows"] if r["spheres"] != count] + [row],
                                     key=lambda r: r["spheres"])
            print(describe(row, sides), flush=True)
            path.unlink()
            args.out.mkdir(parents=True, exist_ok=True)
            out_file.write_text(json.dumps(results, indent=1))
    return 0


def describe(row: dict, sides: dict) -> str:
    parts = [f"{row['spheres']:>9,} spheres ({row['megabytes']:.0f} MB):"]
    for side in sides:
        r = row[side]
        text = f"{side} {min(r['wall']):.2f} s wall, {min(r['cpu']):.2f} s CPU"
        if "kept_per_shape" in r:
            text += f", {r['kept_per_shape']:.0f} B/shape kept, peak {r['peak_mb']:.0f} MB"
        parts.append(text)
    if "against" in sides:
        ratio = statistics.median(row["this"]["wall"]) / statistics.median(row["against"]["wall"])
        parts.append(f"this/against (median wall) {ratio:.2f}")
    return "  ".join(parts)


if __name__ == "__main__":
    sys.exit(main())
