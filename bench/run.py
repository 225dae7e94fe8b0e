"""Benchmarks: this tracer against POV-Ray 3.7, its scaling with the number of objects, and C against NumPy.

    python3 bench/run.py [--quick] [--repeat N] [--threads T] [--out bench/results]

(a) Whole-process wall time of ``python3 -m tracer render`` and ``povray`` on the bundled scenes at
    1280x960 (POV-Ray scenes written by bench/sdl_to_pov.py: same geometry, camera, lights, recursion depth),
    T threads each (POV-Ray's +WT), interleaved runs, median of N; the ratios come from the same run.
(b) The same for scenes of 10 to 10,000 random spheres on a plane, two lights.
(c) In-process render time, C core against the NumPy path, at 320x240.

Writes results.json into --out, and, when matplotlib is installed, docs/performance.png.
Needs ``povray`` on PATH for (a) and (b) (``apt-get install -y povray``); without it those parts are skipped.
"""
from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import tracer  # noqa: E402
from tracer.compile import compile_scene  # noqa: E402

sys.path.insert(0, str(ROOT / "bench"))
from sdl_to_pov import scene_to_pov  # noqa: E402

SCENES = ["lecture", "shapes", "csg", "glass", "jack", "polyhedra", "textures"]
SPHERE_COUNTS = [10, 30, 100, 300, 1000, 3000, 10000]


def machine() -> dict:
    cpu = platform.processor() or platform.machine()
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass

    def version(cmd):
        try:
            out = subprocess.run(cmd, capture_output=True, text=True, timeout=30)
            text = (out.stdout + out.stderr).strip().splitlines()
            return next((l for l in text if l.strip() and "configuration file" not in l), "")
        except (OSError, subprocess.SubprocessError):
            return None

    pov = shutil.which("povray")
    return {"cpu": cpu, "cores": os.cpu_count(), "python": platform.python_version(), "numpy": np.__version__,
            "cc": version([os.environ.get("CC", "cc"), "--version"]),
            "povray": version([pov, "--version"]) if pov else None, "platform": platform.platform()}


def sphere_scene(count: int, seed: int = 1) -> str:
    """``count`` random spheres above a plane, the total volume kept about constant, two lights."""
    rng = np.random.default_rng(seed)
    lines = ["! written by bench/run.py", "camera 0 28 52  0 2 0  0 1 0  40", "light 30 60 40  1 1 1",
             "light -40 30 30  0.4 0.4 0.4", "background 0.1 0.1 0.15", "globalAmbient 0.2 0.2 0.2",
             "push diffuse 0.5 0.5 0.5 specular 0 0 0 rotate -90 1 0 0 plane pop",
             "specular 0.4 0.4 0.4 specularExponent 30"]
    size = 2.2 * (1000.0 / max(count, 1000)) ** (1.0 / 3.0)
    for _ in range(count):
        x, z = rng.uniform(-18, 18, 2)
        y = rng.uniform(0.5, 8.0)
        r = size * rng.uniform(0.25, 0.6)
        c = rng.uniform(0.2, 1.0, 3)
        lines.append(f"diffuse {c[0]:.3f} {c[1]:.3f} {c[2]:.3f} "
                     f"push translate {x:.4f} {y:.4f} {z:.4f} scale {r:.4f} {r:.4f} {r:.4f} sphere pop")
    return "\n".join(lines) + "\n"


def timed(command: list[str], env: dict) -> float:
    start = time.perf_counter()
    result = subprocess.run(command, env=env, capture_output=True, text=True)
    elapsed = time.perf_counter() - start
    if result.returncode != 0:
        raise RuntimeError(f"{' '.join(command)} failed:\n{result.stderr[-2000:]}")
    return elapsed


def compare_with_povray(name: str, sdl: Path, work: Path, width: int, height: int, threads: int, repeat: int) -> dict:
    stem = sdl.stem  # file names without spaces: POV-Ray's option parser splits on them
    pov = work / f"{stem}.pov"
    pov.write_text(scene_to_pov(tracer.load(sdl), width, height))
    env = dict(os.environ, SDL_TRACER_THREADS=str(threads), PYTHONPATH=str(ROOT))
    ours_cmd = [sys.executable, "-m", "tracer", "render", str(sdl), "-o", str(work / f"{stem}-ours.png"),
                "--width", str(width), "--height", str(height), "-q", "--backend", "c"]
    pov_cmd = ["povray", f"+I{pov}", f"+O{work / f'{stem}-pov.png'}", f"+W{width}", f"+H{height}",
               f"+WT{threads}", "-D", "-GA", "+FN", "File_Gamma=1.0", "-V"]
    ours, theirs = [], []
    timed(ours_cmd, env)  # warm the page cache and build the C core if needed
    for _ in range(repeat):
        ours.append(timed(ours_cmd, env))
        theirs.append(timed(pov_cmd, env))
    o, p = statistics.median(ours), statistics.median(theirs)
    print(f"  {name:12s} ours {o:6.3f} s   povray {p:6.3f} s   ratio {o / p:5.2f}", flush=True)
    return {"scene": name, "ours": o, "povray": p, "ratio": o / p, "ours_runs": ours, "povray_runs": theirs,
            "load_average_1min": os.getloadavg()[0]}


def c_versus_numpy(name: str, sdl: Path, width: int, height: int) -> dict:
    from tracer.render import render

    scene = tracer.load(sdl)
    compiled = compile_scene(scene)
    c = render(compiled, width, height, backend="c")
    n = render(compiled, width, height, backend="numpy")
    diff = float(np.abs(c.image.astype(float) - n.image.astype(float)).max())
    print(f"  {name:12s} C {c.seconds:7.3f} s   NumPy {n.seconds:7.3f} s   speed-up {n.seconds / c.seconds:6.1f}x"
          f"   max |difference| {diff:.2g}", flush=True)
    return {"scene": name, "c": c.seconds, "numpy": n.seconds, "speedup": n.seconds / c.seconds,
            "max_difference": diff, "rays": c.rays.as_dict(), "same_counts": c.rays.as_dict() == n.rays.as_dict()}


def plot(results: dict, path: Path) -> bool:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib not installed: no plot", file=sys.stderr)
        return False
    fig, axes = plt.subplots(1, 3, figsize=(15, 4.4))
    if results.get("scenes"):
        ax = axes[0]
        rows = results["scenes"]
        x = np.arange(len(rows))
        ax.bar(x - 0.2, [r["ours"] for r in rows], 0.4, label="this tracer (C core)")
        ax.bar(x + 0.2, [r["povray"] for r in rows], 0.4, label="POV-Ray 3.7")
        ax.set_xticks(x, [r["scene"] for r in rows], rotation=30)
        ax.set_ylabel("whole-process wall time (s)")
        ax.set_title(f"Bundled scenes, {results['width']}x{results['height']}, {results['threads']} threads")
        ax.legend()
    if results.get("spheres"):
        ax = axes[1]
        rows = results["spheres"]
        n = [r["count"] for r in rows]
        ax.loglog(n, [r["ours"] for r in rows], "o-", label="this tracer (C core)")
        ax.loglog(n, [r["povray"] for r in rows], "s-", label="POV-Ray 3.7")
        ax.set_xlabel("spheres")
        ax.set_ylabel("whole-process wall time (s)")
        ax.set_title(f"Scaling, {results['width']}x{results['height']}")
        ax.legend()
    if results.get("numpy"):
        ax = axes[2]
        rows = results["numpy"]
        x = np.arange(len(rows))
        ax.bar(x - 0.2, [r["c"] for r in rows], 0.4, label="C core")
        ax.bar(x + 0.2, [r["numpy"] for r in rows], 0.4, label="NumPy path")
        ax.set_yscale("log")
        ax.set_xticks(x, [r["scene"] for r in rows], rotation=30)
        ax.set_ylabel("render time (s), log scale")
        ax.set_title(f"C core vs NumPy, {results['numpy_size']}")
        ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return True


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--quick", action="store_true", help="smaller images and fewer sphere counts")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--out", default=str(ROOT / "bench" / "results"))
    p.add_argument("--plot", default=str(ROOT / "docs" / "performance.png"))
    args = p.parse_args(argv)
    width, height = (320, 240) if args.quick else (1280, 960)
    counts = [10, 100, 1000] if args.quick else SPHERE_COUNTS
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    results = {"machine": machine(), "width": width, "height": height, "threads": args.threads,
               "repeat": args.repeat, "date": time.strftime("%Y-%m-%d %H:%M:%S"),
               "load_average": {"start": os.getloadavg()}}  # the machine may be shared: say how busy it was
    print(json.dumps(results["machine"], indent=1))
    with tempfile.TemporaryDirectory(prefix="sdl-bench-") as tmp:
        work = Path(tmp)
        if shutil.which("povray"):
            print(f"(a) bundled scenes at {width}x{height}, {args.threads} threads, median of {args.repeat}")
            results["scenes"] = [compare_with_povray(name, ROOT / "scenes" / f"{name}.sdl", work, width, height,
                                                     args.threads, args.repeat) for name in SCENES]
            print(f"(b) random spheres at {width}x{height}")
            results["spheres"] = []
            for count in counts:
                sdl = work / f"spheres{count}.sdl"
                sdl.write_text(sphere_scene(count))
                row = compare_with_povray(f"{count} spheres", sdl, work, width, height, args.threads, args.repeat)
                row["count"] = count
                results["spheres"].append(row)
        else:
            print("povray not found: skipping (a) and (b)  (apt-get install -y povray)")
    size = (160, 120) if args.quick else (320, 240)
    results["numpy_size"] = f"{size[0]}x{size[1]}"
    print(f"(c) C core against the NumPy path, in process, {size[0]}x{size[1]}")
    results["numpy"] = [c_versus_numpy(name, ROOT / "scenes" / f"{name}.sdl", *size) for name in SCENES]
    results["load_average"]["end"] = os.getloadavg()
    load = results["load_average"]
    print(f"load average (1, 5, 15 min): start {load['start']}, end {load['end']}")
    (out / "results.json").write_text(json.dumps(results, indent=1))
    if plot(results, Path(args.plot)):
        print(f"plot: {args.plot}")
    print(f"results: {out / 'results.json'}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
