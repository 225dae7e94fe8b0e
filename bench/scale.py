"""Scaling benchmark: big meshes and many objects, this tracer against POV-Ray 3.7, time and peak memory.

    python3 bench/scale.py [--triangles 1e4,1e5,1e6] [--objects 1e3,1e4,1e5,1e6] [--threads 2]
                           [--width 1280 --height 960] [--repeat 1] [--out bench/results]

Rows: a torus mesh of N triangles read from a .3vn file (bench/big_scenes.py), and N small spheres, one SDL
line each (bench/run.py's sphere_scene).  For every row, the whole process of each tracer, interleaved
(ours, POV-Ray, ours, ...): wall time and peak resident memory (the child's ru_maxrss from wait4).  POV-Ray
gets the same geometry from bench/sdl_to_pov.py (mesh2 with the same triangles and normals; one sphere
primitive per sphere), the same camera, lights, size and threads.

For each row also, in a separate process of ours, the split of the time into read (parse the SDL and the
mesh file), build (compile the scene: BVHs and tables; flatten it for the C core), trace and write (the PNG),
and for meshes the bytes per triangle of what the tracer keeps (mesh arrays and BVH).  As a hardware anchor
for the mesh rows: closest-hit rays per CPU second on one thread each, the image's camera rays, of Embree
through the ``embreex`` package when it is installed and of ours (the C core's first_hits), interleaved
(bench/embree_thread.py).

Writes scale.json into --out and, with matplotlib, docs/performance-scale.png.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT))
sys.path.insert(0, str(ROOT / "bench"))

from big_scenes import mesh_scene, write_torus_3vn  # noqa: E402
from run import machine, sphere_scene  # noqa: E402


def measured(command: list[str], env: dict) -> tuple[float, float]:
    """(wall seconds, peak resident MB) of one child process; raises if it fails.

    The peak comes from GNU time (/usr/bin/time -f %M) when it is there: a child forked straight from this
    process would report at least this process's own size (Linux counts the pre-exec copy of the parent
    in the child's maxrss), and this process has held big scenes.  Without it, wait4's ru_maxrss, which is
    then an upper bound."""
    gnu_time = Path("/usr/bin/time").exists()
    with tempfile.NamedTemporaryFile("r", suffix=".rss") as rss:
        wrapped = ["/usr/bin/time", "-f", "%M", "-o", rss.name, *command] if gnu_time else command
        start = time.perf_counter()
        with open(os.devnull, "wb") as sink:
            child = subprocess.Popen(wrapped, env=env, stdout=sink, stderr=subprocess.PIPE)
            _, status, usage = os.wait4(child.pid, 0)
            elapsed = time.perf_counter() - start
            error = child.stderr.read().decode(errors="replace")
            child.stderr.close()
            child.returncode = os.waitstatus_to_exitcode(status)
        if child.returncode != 0:
            raise RuntimeError(f"{' '.join(command)} failed ({child.returncode}):\n{error[-2000:]}")
        text = rss.read().split()
    peak_kb = int(text[-1]) if gnu_time and text else usage.ru_maxrss  # Linux: kilobytes
    return elapsed, peak_kb / 1024.0


def write_row_scene(kind: str, count: int, work: Path) -> Path:
    """The SDL file (and mesh) of one row."""
    if kind == "triangles":
        mesh = work / f"torus{count}.3vn"
        write_torus_3vn(mesh, count)
        sdl = work / f"torus{count}.sdl"
        sdl.write_text(mesh_scene(mesh.name))
    else:
        sdl = work / f"spheres{count}.sdl"
        sdl.write_text(sphere_scene(count))
    return sdl


def phases(sdl: Path, width: int, height: int, threads: int, out: Path) -> dict:
    """Read / build / trace / write seconds of one render in this process, and the mesh's bytes."""
    import tracer
    from tracer.backend import make_tracer
    from tracer.bulk import one_blas_thread
    from tracer.compile import compile_scene
    from tracer.imageio import save_image
    from tracer.render import render

    with one_blas_thread():
        t0 = time.perf_counter()
        scene = tracer.load(sdl)
        t1 = time.perf_counter()
        compiled = compile_scene(scene)
        core = make_tracer(compiled, "c", threads)  # flattens the scene for the C core (kept on `compiled`)
        t2 = time.perf_counter()
        result = render(compiled, width, height, backend="c", threads=threads)
        t3 = time.perf_counter()
        save_image(result.image, out)
        t4 = time.perf_counter()
    row = {"read": t1 - t0, "build": t2 - t1, "trace": t3 - t2, "write": t4 - t3,
           "rays": result.rays.as_dict()}
    meshes = {id(p.triangle_mesh): p for p in compiled.primitives if p.triangle_mesh is not None}
    if meshes:
        prim = next(iter(meshes.values()))
        data = prim.shape.mesh
        mesh = prim.triangle_mesh
        # Each buffer once, by address: the TriangleMesh keeps the MeshData's own vertex, normal and index
        # arrays (views of them), which count as the mesh data's.
        source_arrays = [data.vertices, data.normals] + (
            data.faces.arrays() if hasattr(data.faces, "arrays") else [])
        source_buffers = {a.__array_interface__["data"][0]: a.nbytes for a in source_arrays}
        own = {a.__array_interface__["data"][0]: a.nbytes for a in mesh.kept_arrays()}
        kept = sum(nbytes for address, nbytes in own.items() if address not in source_buffers)
        source = sum(source_buffers.values())
        row["triangles"] = mesh.triangle_count
        # (the C core's own four-wide copy of the tree, tracer/native/mesh_wide.h: 128 bytes a node; the
        # scene's only mesh is the C core's mesh 0)
        wide = 128 * core.mesh_wide_nodes(0) if hasattr(core, "mesh_wide_nodes") else 0
        row["bytes_per_triangle"] = {"bvh_and_tables": kept / mesh.triangle_count,
                                     "mesh_data": source / mesh.triangle_count,
                                     "wide_tree": wide / mesh.triangle_count}
        row["throughput"] = primary_ray_throughput(compiled, width, height, threads)
    return row


def primary_ray_throughput(compiled, width: int, height: int, threads: int) -> dict:
    """Closest-hit camera rays per CPU second on one thread each, ours (the C core's first_hits) and
    Embree's (with embreex), on the mesh alone, the same rays, interleaved (bench/embree_thread.py).  Both
    on one thread whatever --threads is: Embree's binding traces on the calling thread only."""
    from embree_thread import per_thread

    return per_thread(compiled, width, height, rounds=3)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--triangles", default="1e4,1e5,1e6", help="comma-separated triangle counts ('' for none)")
    p.add_argument("--objects", default="1e3,1e4,1e5,1e6", help="comma-separated sphere counts ('' for none)")
    p.add_argument("--width", type=int, default=1280)
    p.add_argument("--height", type=int, default=960)
    p.add_argument("--threads", type=int, default=2)
    p.add_argument("--repeat", type=int, default=1)
    p.add_argument("--out", default=str(ROOT / "bench" / "results"))
    p.add_argument("--plot", default=str(ROOT / "docs" / "performance-scale.png"))
    p.add_argument("--phases", help=argparse.SUPPRESS)  # internal: print one row's phases as JSON
    args = p.parse_args(argv)
    if args.phases:
        with tempfile.TemporaryDirectory() as tmp:
            print(json.dumps(phases(Path(args.phases), args.width, args.height, args.threads, Path(tmp) / "o.png")))
        return 0

    rows = [("triangles", int(float(x))) for x in args.triangles.split(",") if x.strip()]
    rows += [("objects", int(float(x))) for x in args.objects.split(",") if x.strip()]
    env = dict(os.environ, SDL_TRACER_THREADS=str(args.threads), PYTHONPATH=str(ROOT))
    results = {"machine": machine(), "width": args.width, "height": args.height, "threads": args.threads,
               "date": time.strftime("%Y-%m-%d %H:%M:%S"), "load_average_start": os.getloadavg(), "rows": []}
    pov = shutil.which("povray")
    with tempfile.TemporaryDirectory(prefix="sdl-scale-") as tmp:
        work = Path(tmp)
        for kind, count in rows:
            sdl = write_row_scene(kind, count, work)
            row = {"kind": kind, "count": count, "ours": [], "ours_mb": [], "povray": [], "povray_mb": []}
            ours_cmd = [sys.executable, "-m", "tracer", "render", str(sdl), "-o", str(work / "ours.png"),
                        "--width", str(args.width), "--height", str(args.height), "-q", "--backend", "c"]
            pov_cmd = None
            if pov:
                from sdl_to_pov import scene_to_pov
                import tracer
                pov_file = sdl.with_suffix(".pov")
                pov_file.write_text(scene_to_pov(tracer.load(sdl), args.width, args.height))
                pov_cmd = [pov, f"+I{pov_file}", f"+O{work / 'pov.png'}", f"+W{args.width}", f"+H{args.height}",
                           f"+WT{args.threads}", "-D", "-GA", "+FN", "File_Gamma=1.0", "-V"]
            for _ in range(args.repeat):
                seconds, mb = measured(ours_cmd, env)
                row["ours"].append(seconds)
                row["ours_mb"].append(mb)
                if pov_cmd:
                    seconds, mb = measured(pov_cmd, env)
                    row["povray"].append(seconds)
                    row["povray_mb"].append(mb)
            split = subprocess.run([sys.executable, __file__, "--phases", str(sdl), "--width", str(args.width),
                                    "--height", str(args.height), "--threads", str(args.threads)],
                                   env=env, capture_output=True, text=True)
            row["phases"] = json.loads(split.stdout) if split.returncode == 0 else {"error": split.stderr[-500:]}
            row["load_average"] = os.getloadavg()
            results["rows"].append(row)
            print(summary(row), flush=True)
            save(results, Path(args.out))  # after every row: a long run that stops keeps what it measured
            for path in work.glob("*"):  # the big files of this row are not needed any more
                path.unlink()
    out = Path(args.out)
    save(results, out)
    if plot(results, Path(args.plot)):
        print(f"plot: {args.plot}")
    print(f"results: {out / 'scale.json'}")
    return 0


def save(results: dict, out: Path) -> None:
    out.mkdir(parents=True, exist_ok=True)
    (out / "scale.json").write_text(json.dumps(results, indent=1))


def summary(row: dict) -> str:
    ours, ours_mb = min(row["ours"]), max(row["ours_mb"])
    text = f"{row['count']:>9,} {row['kind']:9s} ours {ours:7.2f} s {ours_mb:7.0f} MB"
    if row["povray"]:
        theirs, theirs_mb = min(row["povray"]), max(row["povray_mb"])
        text += f"   povray {theirs:7.2f} s {theirs_mb:7.0f} MB   ratio {ours / theirs:5.2f} time {ours_mb / theirs_mb:5.2f} memory"
    ph = row["phases"]
    if "read" in ph:
        text += f"   [read {ph['read']:.2f} build {ph['build']:.2f} trace {ph['trace']:.2f} write {ph['write']:.2f}]"
    if "bytes_per_triangle" in ph:
        b = ph["bytes_per_triangle"]
        text += f" {b['bvh_and_tables'] + b['mesh_data'] + b.get('wide_tree', 0):.0f} B/triangle"
    if "throughput" in ph:
        t = ph["throughput"]
        text += f"   closest hit, one thread: ours {t['ours_rays_per_cpu_s'] / 1e6:.1f} M rays/CPU-s"
        if "ratio" in t:
            text += f", Embree {t['embree_rays_per_cpu_s'] / 1e6:.1f} M (ratio {t['ratio']:.2f})"
    return text


def plot(results: dict, path: Path) -> bool:
    try:
        import matplotlib
        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        return False
    fig, axes = plt.subplots(1, 2, figsize=(12, 4.4))
    for ax, kind, label in ((axes[0], "triangles", "triangles (one .3vn mesh)"),
                            (axes[1], "objects", "spheres (one SDL line each)")):
        rows = [r for r in results["rows"] if r["kind"] == kind]
        if not rows:
            ax.set_visible(False)
            continue
        n = [r["count"] for r in rows]
        ax.loglog(n, [min(r["ours"]) for r in rows], "o-", label="this tracer: time")
        if all(r["povray"] for r in rows):
            ax.loglog(n, [min(r["povray"]) for r in rows], "s-", label="POV-Ray 3.7: time")
        ax.set_xlabel(label)
        ax.set_ylabel("whole-process wall time (s)")
        twin = ax.twinx()
        twin.loglog(n, [max(r["ours_mb"]) for r in rows], "o--", color="tab:green", label="this tracer: peak MB")
        if all(r["povray"] for r in rows):
            twin.loglog(n, [max(r["povray_mb"]) for r in rows], "s--", color="tab:red", label="POV-Ray: peak MB")
        twin.set_ylabel("peak resident memory (MB), dashed")
        lines = ax.get_legend_handles_labels()
        more = twin.get_legend_handles_labels()
        ax.legend(lines[0] + more[0], lines[1] + more[1], fontsize=8, loc="upper left")
        ax.set_title(f"{results['width']}x{results['height']}, {results['threads']} threads")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    return True


if __name__ == "__main__":
    sys.exit(main())
