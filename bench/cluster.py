"""What rendering on a Dask cluster costs on this machine (docs/distributed.md).

    python3 bench/cluster.py [--quick] [--rounds N] [--size WxH] [--configs local,local:1,local:2] [--out bench/results]

(a) The table: ``python -m tracer render scenes/glass.sdl`` at 3840x2160 with 16 samples, whole process
    (interpreter start, reading the scene, the cluster's start-up, writing the PNG), plain local render
    against ``--scheduler local:1`` and ``local:2``: wall time, and CPU time of the process and all its
    children (the workers); the configurations are interleaved round by round (the machine is shared, so
    only ratios taken in one run mean anything) and the median of the rounds is kept, with the load
    average before each run.  For the cluster runs the CPU is also split between the render's own process
    (scheduler, nannies, assembling the tiles, the PNG) and its worker processes, as last seen by polling
    them.  The images must be identical.
(b) Start-up: the same commands on a 64 x 48 image (next to nothing to trace) in tiles of 16 pixels,
    interleaved the same way: what a cluster adds to a render whatever its size (starting the worker
    processes, each one's first task, stopping them).
(c) The per-tile overhead: in one process with a running one-worker cluster, scenes/lecture.sdl at 512x512
    (one sample: tracing is cheap, so the overhead shows) cut into tiles of 16 to 256 pixels, on the
    cluster and locally; the CPU time of every process (client, scheduler, worker) beyond the local
    render's, per tile.  Against the CPU time of one tile of the 4K render this decides the tile size.

Writes distributed.json into --out.  --quick: 960x540 and one round, for a check that it runs.
"""
from __future__ import annotations

import argparse
import json
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Sequence

import psutil

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))

import tracer  # noqa: E402
from tracer import distributed as dist  # noqa: E402

CONFIGS = ("local", "local:1", "local:2")


def _cpu_seconds() -> float:
    """CPU time of this process and all its children, living ones included."""
    me = psutil.Process()
    total = sum(me.cpu_times()[:2])
    for child in me.children(recursive=True):
        try:
            total += sum(child.cpu_times()[:2])
        except psutil.NoSuchProcess:
            pass
    return total


def whole_process(width: int, height: int, samples: int, rounds: int, folder: Path,
                  configs: Sequence[str] = CONFIGS, extra: Sequence[str] = ()) -> dict:
    runs: dict[str, list[dict]] = {name: [] for name in configs}
    outputs = {}
    for r in range(rounds):
        for name in configs:
            out = folder / f"{name.replace(':', '_')}.png"
            cmd = [sys.executable, "-m", "tracer", "render", str(ROOT / "scenes" / "glass.sdl"), "-o", str(out),
                   "--width", str(width), "--height", str(height), "--samples", str(samples), "-q", "--stats", *extra]
            if name != "local":
                cmd += ["--scheduler", name]
            run = _timed(cmd)
            runs[name].append(run)
            outputs[name] = out.read_bytes()
            split = (f" (render process {run['own_cpu']:.2f} s, workers {run['workers_cpu']:.2f} s)"
                     if name != "local" else "")
            print(f"round {r + 1}: {name:8s} {run['wall']:8.2f} s wall, {run['cpu']:8.2f} s CPU{split}, load "
                  f"{run['load'][0]:.2f}", flush=True)
    identical = len(set(outputs.values())) == 1
    medians = {name: statistics.median(run["wall"] for run in runs[name]) for name in configs}
    cpu_medians = {name: statistics.median(run["cpu"] for run in runs[name]) for name in configs}
    return {"width": width, "height": height, "samples": samples, "rounds": rounds, "identical_bytes": identical,
            "runs": runs, "median": medians, "cpu_median": cpu_medians,
            "load_median": statistics.median(run["load"][0] for name in configs for run in runs[name]),
            "against_local": {name: medians[name] / medians["local"] for name in medians},
            "cpu_against_local": {name: cpu_medians[name] / cpu_medians["local"] for name in cpu_medians}}


def _timed(cmd: list[str]) -> dict:
    """Runs a command: wall and CPU seconds (its own and all its children's), the CPU of its own process and of
    its children as last seen while it ran, and the load average before it started."""
    load = os.getloadavg()
    cpu_before = _children_cpu()
    started = time.perf_counter()
    process = psutil.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT)
    seen: dict[int, float] = {}
    while process.poll() is None:
        try:
            seen[process.pid] = sum(process.cpu_times()[:2])
            for child in process.children(recursive=True):
                seen[child.pid] = sum(child.cpu_times()[:2])
        except psutil.NoSuchProcess:
            pass
        time.sleep(0.25)
    _, stderr = process.communicate()
    wall = time.perf_counter() - started
    if process.returncode:
        raise SystemExit(f"{' '.join(cmd)} failed: {stderr}")
    own = seen.pop(process.pid, 0.0)
    return {"wall": wall, "cpu": _children_cpu() - cpu_before, "own_cpu": own, "workers_cpu": sum(seen.values()),
            "load": load}


def startup(rounds: int, folder: Path, configs: Sequence[str] = CONFIGS) -> dict:
    """Whole-process renders of a 64 x 48 image: what starting (and stopping) a cluster costs.  Tiles of 16
    pixels, so that every worker gets some and pays its first task (importing the tracer, compiling the
    scene)."""
    table = whole_process(64, 48, 1, rounds, folder, configs, extra=("--tile", "16"))
    return {name: {"wall": table["median"][name], "cpu": table["cpu_median"][name],
                   "wall_over_local": table["median"][name] - table["median"]["local"],
                   "cpu_over_local": table["cpu_median"][name] - table["cpu_median"]["local"]}
            for name in configs} | {"rounds": rounds, "runs": table["runs"]}


def _children_cpu() -> float:
    """User and system CPU of the finished children (and theirs, the cluster's workers included)."""
    usage = resource.getrusage(resource.RUSAGE_CHILDREN)
    return usage.ru_utime + usage.ru_stime


def tile_overhead(sizes=(16, 32, 64, 128, 256)) -> dict:
    path = ROOT / "scenes" / "lecture.sdl"
    scene = dist.read_scene(path)
    bundle = dist.SceneBundle.of(path, scene)
    rows = []
    with dist.connect("local:1") as client:
        client.wait_for_workers(1)
        dist.render_frames(client, bundle, dist.Job(64, 64, threads=1), [None], lambda *a: None)  # warm
        for size in sizes:
            job = dist.Job(512, 512, tile=size, threads=1)
            tiles = len(job.plan().rects)
            cpu, wall = _cpu_seconds(), time.perf_counter()
            dist.render_frames(client, bundle, job, [None], lambda *a: None)
            cluster_cpu, cluster_wall = _cpu_seconds() - cpu, time.perf_counter() - wall
            cpu, wall = _cpu_seconds(), time.perf_counter()
            tracer.render(scene, 512, 512, tile=size, threads=1)
            local_cpu, local_wall = _cpu_seconds() - cpu, time.perf_counter() - wall
            row = {"tile": size, "tiles": tiles, "cluster_cpu": cluster_cpu, "local_cpu": local_cpu,
                   "cluster_wall": cluster_wall, "local_wall": local_wall,
                   "cpu_ms_per_tile": 1000 * (cluster_cpu - local_cpu) / tiles}
            rows.append(row)
            print(f"tile {size:4d}: {tiles:5d} tiles, CPU {cluster_cpu:6.2f} s on the cluster, {local_cpu:6.2f} s "
                  f"locally: {row['cpu_ms_per_tile']:6.2f} ms per tile", flush=True)
    return {"scene": "lecture.sdl", "width": 512, "height": 512, "rows": rows}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--quick", action="store_true")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--out", default=str(ROOT / "bench" / "results"))
    parser.add_argument("--skip-table", action="store_true", help="only the start-up and per-tile overhead")
    parser.add_argument("--size", default="3840x2160", help="the table's image size (default 3840x2160)")
    parser.add_argument("--configs", default=",".join(CONFIGS),
                        help="what the table compares, in order (default local,local:1,local:2; local is needed)")
    args = parser.parse_args()
    configs = args.configs.split(",")
    if "local" not in configs or not all(c == "local" or c.startswith(dist.LOCAL_PREFIX) for c in configs):
        parser.error("--configs: local and local:N, comma-separated")
    results = {"cpus": os.cpu_count(), "load_average_at_start": os.getloadavg()}
    results["tile_overhead"] = tile_overhead()
    with tempfile.TemporaryDirectory() as folder:
        results["startup"] = startup(1 if args.quick else args.rounds, Path(folder), configs)
        print(json.dumps({name: results["startup"][name] for name in configs}))
        if not args.skip_table:
            width, height = (int(n) for n in args.size.split("x"))
            width, height, rounds = (960, 540, 1) if args.quick else (width, height, args.rounds)
            results["table"] = whole_process(width, height, 16, rounds, Path(folder), configs)
            print(json.dumps({k: results["table"][k] for k in ("against_local", "cpu_against_local", "load_median")}))
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    (out / "distributed.json").write_text(json.dumps(results, indent=1))


if __name__ == "__main__":
    main()
