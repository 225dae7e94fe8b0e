"""Closest hit per thread: Embree (PyPI ``embreex``) against this tracer's C core, one thread each, the same rays.

    python3 bench/embree_thread.py [--triangles 1e6] [--width 1280 --height 960] [--rounds 3] [--box-tests]

The rays are the camera rays of bench/scale.py's mesh row (a torus of N triangles read from a .3vn file,
bench/big_scenes.py), traced into the mesh alone (no floor, no lights), closest hit only.  Ours: the C
core's ``first_hits`` on one thread (``NativeTracer(..., threads=1)``: double precision, one ray at a time,
the hit's normal and error bound included).  Embree's: ``EmbreeScene.run`` (single precision), which calls
rtcIntersect1 ray after ray on the calling thread; its BVH is built (on Embree's own threads) before timing.

Both are timed in CPU seconds of this process (time.process_time), interleaved (ours, Embree, ours, ...),
so that other work on a shared machine costs neither of them; a round's rate is rays / CPU seconds, the
best round of each is reported and the ratio ours / Embree.  The wall time is printed beside it: where it
matches the CPU time, the tracer ran on one thread.

--box-tests instead times our core's mesh walks against each other, interleaved in the same way: one
NativeTracer of the mesh per box test (tracer/native/mesh_wide.h: the CPU's best, SDL_TRACER_SIMD=sse2,
SDL_TRACER_SIMD=0 and the binary walk, SDL_TRACER_MESH_BVH=binary; the core reads them when a scene is
made), the best round's CPU seconds of each, and checks that all four find the same hits.
"""
from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from big_scenes import mesh_scene, write_torus_3vn  # noqa: E402


def camera_rays(compiled, width: int, height: int) -> tuple[np.ndarray, np.ndarray]:
    """The image's camera rays, one per pixel, row by row: (origins, directions), each (W H, 3)."""
    from tracer.camera import CameraFrame, scene_camera

    camera = scene_camera(compiled.scene, compiled, width / height)
    frame = CameraFrame.from_camera(camera, width / height)
    rows, cols = np.divmod(np.arange(width * height), width)
    directions = frame.directions(rows, cols, height, width)
    origins = np.ascontiguousarray(np.broadcast_to(frame.eye, directions.shape))
    return origins, np.ascontiguousarray(directions)


def timed(call) -> tuple[float, float, object]:
    """(CPU seconds, wall seconds, result) of call()."""
    cpu, wall = time.process_time(), time.perf_counter()
    result = call()
    return time.process_time() - cpu, time.perf_counter() - wall, result


def per_thread(compiled, width: int, height: int, rounds: int = 3) -> dict:
    """Closest-hit rays per CPU second on one thread, ours and (with embreex) Embree's, interleaved; the
    ratio ours / Embree of the best rounds."""
    from tracer.compile import compile_scene
    from tracer.native.tracer import NativeTracer

    origins, directions = camera_rays(compiled, width, height)
    n = len(origins)
    mesh_prims = [p for p in compiled.primitives if p.triangle_mesh is not None]
    ours = NativeTracer(compile_scene(replace(compiled.scene, objects=[mesh_prims[0].shape])), 1)
    ours.first_hits(origins[:1024], directions[:1024])  # (warm: the scene is handed to the core)
    out = {"rays": n, "rounds": rounds, "ours_cpu_s": [], "ours_wall_s": []}
    embree = None
    try:
        from embreex import rtcore_scene
        from embreex.mesh_construction import TriangleMesh as EmbreeMesh
    except ImportError:
        out["embree"] = "embreex not installed (pip install embreex)"
    else:
        prim = mesh_prims[0]
        tri_v, _ = prim.shape.mesh.triangles()
        world = prim.shape.mesh.vertices @ prim.matrix[:3, :3].T + prim.matrix[:3, 3]
        embree = rtcore_scene.EmbreeScene()
        EmbreeMesh(embree, world.astype(np.float32), tri_v.astype(np.int32))
        o32, d32 = origins.astype(np.float32), directions.astype(np.float32)
        embree.run(o32[:1024], d32[:1024])  # builds Embree's BVH (not timed)
        out.update(embree_cpu_s=[], embree_wall_s=[])
    for _ in range(rounds):
        cpu, wall, hits = timed(lambda: ours.first_hits(origins, directions))
        out["ours_cpu_s"].append(cpu)
        out["ours_wall_s"].append(wall)
        out["ours_hit_fraction"] = float(np.isfinite(hits["t"]).mean())
        if embree is not None:
            cpu, wall, ids = timed(lambda: embree.run(o32, d32))
            out["embree_cpu_s"].append(cpu)
            out["embree_wall_s"].append(wall)
            out["embree_hit_fraction"] = float((ids >= 0).mean())
    out["ours_rays_per_cpu_s"] = n / min(out["ours_cpu_s"])
    if embree is not None:
        out["embree_rays_per_cpu_s"] = n / min(out["embree_cpu_s"])
        out["ratio"] = out["ours_rays_per_cpu_s"] / out["embree_rays_per_cpu_s"]
    return out


#: The settings --box-tests compares (the environment the C core reads when a scene is made).
BOX_TESTS = {"best": {}, "sse2": {"SDL_TRACER_SIMD": "sse2"}, "scalar": {"SDL_TRACER_SIMD": "0"},
             "binary": {"SDL_TRACER_MESH_BVH": "binary"}}


def box_tests(compiled, width: int, height: int, rounds: int = 10) -> dict:
    """CPU seconds of our closest-hit walk with each of BOX_TESTS, one thread, interleaved, best round of each
    (and the test the "best" setting got on this CPU)."""
    import os

    from tracer.compile import compile_scene
    from tracer.native.tracer import NativeTracer

    origins, directions = camera_rays(compiled, width, height)
    mesh_shape = next(p.shape for p in compiled.primitives if p.triangle_mesh is not None)
    saved = {name: os.environ.get(name) for name in ("SDL_TRACER_SIMD", "SDL_TRACER_MESH_BVH")}
    tracers = {}
    try:
        for name, settings in BOX_TESTS.items():
            for variable in saved:
                os.environ.pop(variable, None)
            os.environ.update(settings)
            # (a scene of its own each: a scene is compiled, and handed to the core, once)
            tracers[name] = NativeTracer(compile_scene(replace(compiled.scene, objects=[mesh_shape])), 1)
            tracers[name].first_hits(origins[:1024], directions[:1024])  # (the scene is handed to the core)
    finally:
        for variable, value in saved.items():
            os.environ.pop(variable, None)
            if value is not None:
                os.environ[variable] = value
    got = {name: tracer.mesh_box_test() for name, tracer in tracers.items()}
    if got["sse2"] not in ("sse2", "scalar") or got["scalar"] != "scalar" or got["binary"] != "binary":
        raise AssertionError(f"the switches were not heard: {got}")
    out = {"rays": len(origins), "rounds": rounds, "best_is": got["best"],
           "cpu_s": {name: [] for name in tracers}}
    reference = None
    for _ in range(rounds):
        for name, tracer in tracers.items():
            cpu, _, hits = timed(lambda: tracer.first_hits(origins, directions))
            out["cpu_s"][name].append(cpu)
            if reference is None:
                reference = hits
            elif not all(np.array_equal(reference[k], hits[k], equal_nan=True) for k in reference):
                raise AssertionError(f"the {name} walk found other hits than the {next(iter(tracers))} walk")
    return out


def box_tests_summary(result: dict) -> str:
    best = {name: min(times) for name, times in result["cpu_s"].items()}
    return (f"closest hit, one thread, {result['rays']:,} rays, best of {result['rounds']}, CPU seconds: "
            + ", ".join(f"{name} {seconds:.3f}" for name, seconds in best.items())
            + f" (best is {result['best_is']}; best / sse2 {best['best'] / best['sse2']:.3f}); same hits")


def summary(result: dict) -> str:
    text = (f"closest hit, one thread, {result['rays']:,} rays, best of {result['rounds']}: ours "
            f"{result['ours_rays_per_cpu_s'] / 1e6:.2f} M rays/CPU-s (CPU {min(result['ours_cpu_s']):.2f} s, "
            f"wall {min(result['ours_wall_s']):.2f} s)")
    if "ratio" in result:
        text += (f", Embree {result['embree_rays_per_cpu_s'] / 1e6:.2f} M (CPU {min(result['embree_cpu_s']):.2f} s,"
                 f" wall {min(result['embree_wall_s']):.2f} s): ratio {result['ratio']:.3f}")
    return text


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--triangles", default="1e6")
    p.add_argument("--width", type=int, default=1280)
    p.add_argument("--height", type=int, default=960)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--box-tests", action="store_true", help="time our walk's box tests against each other")
    p.add_argument("--json", help="also write the result here")
    args = p.parse_args(argv)
    import tracer
    from tracer.compile import compile_scene

    with tempfile.TemporaryDirectory(prefix="sdl-embree-") as tmp:
        count = int(float(args.triangles))
        mesh = Path(tmp) / f"torus{count}.3vn"
        write_torus_3vn(mesh, count)
        sdl = Path(tmp) / f"torus{count}.sdl"
        sdl.write_text(mesh_scene(mesh.name))
        compiled = compile_scene(tracer.load(sdl))
        if args.box_tests:
            result = box_tests(compiled, args.width, args.height, args.rounds)
        else:
            result = per_thread(compiled, args.width, args.height, args.rounds)
    result["triangles"] = count
    print(box_tests_summary(result) if args.box_tests else summary(result))
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    return 0


if __name__ == "__main__":
    sys.exit(main())
