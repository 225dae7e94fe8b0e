"""F12 in Blender against the tracer on its own, at the same size, interleaved in one run.

    python3 bench/blender_f12.py [--scene scenes/lecture.sdl] [--width 1920] [--height 1080] [--repeat 3]

Per round, in this order: ``python -m tracer render --stats`` (its render time: compile and trace; and its
whole process: start, parse, trace, PNG), then scripts/render_sdl.py under ``blender -b`` (Debian's Blender,
when there is one) and in the bpy module, each timing its F12 (``bpy.ops.render.render()``: scene built from
Blender's data, compiled, traced, shown).  Prints the medians and the F12 / tracer ratios (against the
tracer's render time, and against its whole process) as JSON; writes them to bench/results/blender_f12.json.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import shutil
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "tests"))
from blender_binary import blender_numpy_path  # noqa: E402

F12 = re.compile(r"\(F12: ([0-9.]+) s\)")


def tracer_seconds(scene: Path, out: Path, width: int, height: int) -> tuple[float, float]:
    """The tracer's own render time (--stats: compile and trace) and its whole process (start to PNG)."""
    started = time.perf_counter()
    proc = subprocess.run([sys.executable, "-m", "tracer", "render", str(scene), "-o", str(out), "--width",
                           str(width), "--height", str(height), "--stats"], check=True, cwd=ROOT,
                          capture_output=True, text=True)
    wall = time.perf_counter() - started
    return json.loads(proc.stdout.strip().splitlines()[-1])["seconds"], wall


def f12_seconds(command: list[str], env: dict) -> float:
    proc = subprocess.run(command, cwd=ROOT, env=env, capture_output=True, text=True)
    found = F12.search(proc.stdout)
    if proc.returncode != 0 or not found:
        raise SystemExit(f"error: {' '.join(command)} failed:\n{proc.stdout[-2000:]}{proc.stderr[-2000:]}")
    return float(found.group(1))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--scene", default=str(ROOT / "scenes" / "lecture.sdl"))
    parser.add_argument("--width", type=int, default=1920)
    parser.add_argument("--height", type=int, default=1080)
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--out", default=str(ROOT / "bench" / "results"))
    args = parser.parse_args()
    scene = Path(args.scene).resolve()
    script = str(ROOT / "scripts" / "render_sdl.py")
    size = [str(args.width), str(args.height)]
    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        runs: dict[str, list] = {"tracer": [], "tracer_process": []}
        commands = {}
        blender = shutil.which("blender")
        if blender:
            env = dict(os.environ, PYTHONPATH=blender_numpy_path(blender, tmp_path))
            commands["blender_b"] = ([blender, "-b", "--factory-startup", "--python", script, "--", str(scene),
                                      str(tmp_path / "b.png"), *size], env)
        commands["bpy_module"] = ([sys.executable, script, str(scene), str(tmp_path / "m.png"), *size],
                                  dict(os.environ, PYTHONPATH=""))
        for name in commands:
            runs[name] = []
        for _ in range(args.repeat):
            seconds, wall = tracer_seconds(scene, tmp_path / "t.png", args.width, args.height)
            runs["tracer"].append(seconds)
            runs["tracer_process"].append(wall)
            for name, (command, env) in commands.items():
                runs[name].append(f12_seconds(command, env))
    medians = {name: statistics.median(values) for name, values in runs.items()}
    report = {"scene": scene.name, "width": args.width, "height": args.height, "runs": runs, "median": medians,
              "f12_over_tracer": {name: round(medians[name] / medians["tracer"], 3) for name in commands},
              "f12_over_tracer_process": {name: round(medians[name] / medians["tracer_process"], 3)
                                          for name in commands}}
    if blender:
        report["blender"] = subprocess.run([blender, "--version"], capture_output=True,
                                           text=True).stdout.splitlines()[0]
    text = json.dumps(report, indent=1)
    print(text)
    Path(args.out).mkdir(parents=True, exist_ok=True)
    (Path(args.out) / "blender_f12.json").write_text(text + "\n")


if __name__ == "__main__":
    main()
