"""`convert` at a size and at twice that size: whether SDL <-> USD conversion is linear in lights and in boolean
depth (issue 28 found it quadratic in lights, 5,000 in 2.5 s and 20,000 in 29 s, and a 2,000-deep boolean to
.usdc in 46 s).

    python3 bench/usd_convert_scale.py [--lights 1000] [--depth 1500] [--repeat 3]

For each case the scene is made at size N and 2N, then converted SDL -> USD (.usda and .usdc) and that file back
to SDL, each conversion ``tracer.cli.main(["convert", ...])`` in a fresh process, timed inside it in CPU seconds
(Python's start-up and imports not counted).  The two sizes run in turn, ``--repeat`` times, so that both see the
same load on a shared machine; the table gives the fastest CPU time of each and their ratio: about 2 for a
linear conversion, about 4 for a quadratic one.  A benchmark, not a test: timings on a loaded machine vary.
"""
from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent

#: In the child: this checkout's tracer (not an editable install's, whose import hook would answer first),
#: then one conversion, timed.
_TIMED = """
import json, sys, time
sys.meta_path[:] = [finder for finder in sys.meta_path if not type(finder).__module__.startswith("_editable")]
sys.path.insert(0, sys.argv[3])
import tracer.cli
from tracer.usd.common import pxr
pxr()  # (usd-core's import is not the conversion's time)
cpu = time.process_time()
code = tracer.cli.main(["convert", sys.argv[1], sys.argv[2]])
print(json.dumps({"cpu": time.process_time() - cpu, "code": code}))
"""

CAMERA = "camera 0 0 30  0 0 0  0 1 0  40\n"


def lights_scene(count: int) -> str:
    return CAMERA + "".join(f"light {k % 97 - 48} {k % 13 + 5} {k // 97 % 89 - 44}  0.01 0.01 0.01\n"
                            for k in range(count)) + "sphere\n"


def boolean_scene(depth: int) -> str:
    """Booleans nested ``depth`` deep, each one's left operand the next (the form the reader takes)."""
    ops = ("union", "intersection", "difference")
    return CAMERA + "light 2 3 4 1 1 1\n" + "".join(f"{ops[k % 3]}\n" for k in range(depth)) + "sphere\n" + \
        "".join(f"push translate {k % 7 * 0.01} 0 0 cube pop\n" for k in range(depth))


def convert(source: Path, target: Path) -> float:
    done = subprocess.run([sys.executable, "-c", _TIMED, str(source), str(target), str(ROOT)],
                          capture_output=True, text=True, cwd=str(ROOT))
    result = json.loads(done.stdout.strip().splitlines()[-1]) if done.stdout.strip() else None
    if done.returncode != 0 or result is None or result["code"] != 0:
        raise RuntimeError(f"convert {source} {target} failed:\n{done.stderr[-2000:]}")
    return result["cpu"]


def measure(make, sizes: tuple[int, int], repeat: int, folder: Path, label: str) -> list[dict]:
    rows = []
    for suffix in (".usda", ".usdc"):
        times: dict[tuple[int, str], list[float]] = {}
        for _ in range(repeat):
            for size in sizes:
                sdl = folder / f"{label}{size}.sdl"
                sdl.write_text(make(size))
                usd = folder / f"{label}{size}{suffix}"
                times.setdefault((size, "to"), []).append(convert(sdl, usd))
                times.setdefault((size, "back"), []).append(convert(usd, folder / f"{label}{size}_back.sdl"))
        for direction in ("to", "back"):
            small, large = (min(times[(size, direction)]) for size in sizes)
            what = f"SDL -> {suffix}" if direction == "to" else f"{suffix} -> SDL"
            rows.append({"case": label, "conversion": what, "sizes": sizes, "cpu": [small, large],
                         "ratio": large / small})
            print(f"{label:>9} {what:>14}: {sizes[0]:>6,} {small:6.2f} s CPU, {sizes[1]:>6,} {large:6.2f} s CPU, "
                  f"ratio {large / small:.2f}", flush=True)
    return rows


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--lights", type=int, default=1000, help="the smaller number of lights")
    p.add_argument("--depth", type=int, default=1500, help="the smaller boolean depth")
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args(argv)
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        measure(lights_scene, (args.lights, 2 * args.lights), args.repeat, folder, "lights")
        measure(boolean_scene, (args.depth, 2 * args.depth), args.repeat, folder, "booleans")
    return 0


if __name__ == "__main__":
    sys.exit(main())
