"""Import > SDL against Blender's own C++ OBJ importer on the same objects and materials, interleaved.

    python bench/blender_import.py [--counts 1000 10000 100000] [--repeat 2] [--obj-sphere 8x4] [--blender]

For each count N: bench/run.py's scene of N spheres of their own colours above a plane (one SDL line each),
and the same scene as an .obj/.mtl pair: every object its own mesh (OBJ has no instancing) in world
coordinates, every material its own ``newmtl`` with the SDL diffuse, specular and exponent.  The spheres of
the .obj are coarse UV spheres (``--obj-sphere SEGMENTSxRINGS``, 8x4 by default: 26 vertices, 32 faces),
which makes the OBJ importer's share of the work as small as it can be and the comparison hard for us; the
add-on shares one 64x32 sphere mesh among all its objects.

Each import runs in its own process, in the bpy module (and with ``--blender`` under Debian's ``blender -b``
too), into an empty file: ``bpy.ops.import_scene.sdl`` against ``bpy.ops.wm.obj_import``, CPU seconds of the
operator call (the machine is shared: wall time is printed too), ours then theirs, repeated; beside it the
process's resident memory growth over the import, now and at its peak.  Prints the
medians and the ratios as JSON and writes them to bench/results/blender_import.json.
"""
from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent


def write_scenes(count: int, folder: Path, segments: int, rings: int) -> tuple[Path, Path]:
    """The SDL scene of ``count`` spheres and its .obj/.mtl twin, in ``folder``."""
    sys.path[:0] = [str(ROOT), str(ROOT / "bench")]
    from run import sphere_scene

    import tracer
    from addon.pure import primitives

    sdl = folder / f"spheres_{count}.sdl"
    sdl.write_text(sphere_scene(count))
    scene = tracer.load(str(sdl))
    sphere = primitives.sphere(segments, rings)
    square = primitives.square(primitives.PLANE_HALF_SIZE)
    obj_lines, mtl_lines, first = [f"mtllib spheres_{count}.mtl"], [], 1
    for index, shape in enumerate(scene.shapes()):
        mesh = sphere if shape.kind == "sphere" else square
        points = mesh.vertices @ shape.matrix[:3, :3].T + shape.matrix[:3, 3]
        obj_lines.append(f"o {shape.kind}_{index:06d}")
        obj_lines.append("\n".join("v %.6f %.6f %.6f" % tuple(p) for p in points.tolist()))
        obj_lines.append(f"usemtl m{index:06d}")
        obj_lines.append("\n".join("f " + " ".join(str(first + v) for v in face) for face in mesh.faces))
        first += len(points)
        m = shape.material
        mtl_lines.append(f"newmtl m{index:06d}\nKa {m.ambient[0]} {m.ambient[1]} {m.ambient[2]}\n"
                         f"Kd {m.diffuse[0]} {m.diffuse[1]} {m.diffuse[2]}\n"
                         f"Ks {m.specular[0]} {m.specular[1]} {m.specular[2]}\nNs {m.specular_exponent}\n")
    obj = folder / f"spheres_{count}.obj"
    obj.write_text("\n".join(obj_lines) + "\n")
    (folder / f"spheres_{count}.mtl").write_text("".join(mtl_lines))
    return sdl, obj


def _memory() -> dict:
    """This process's resident size now and at its peak (/proc/self/status), bytes."""
    fields = {}
    with open("/proc/self/status") as status:
        for line in status:
            name, _, value = line.partition(":")
            if name in ("VmRSS", "VmHWM"):
                fields[name] = int(value.split()[0]) * 1024
    return fields


def child(kind: str, path: str) -> dict:
    """One import in this process (the bpy module, or Blender's Python under ``blender -b``)."""
    import time

    import bpy

    sys.path.insert(0, str(ROOT))
    import addon

    addon.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()
    before = _memory()["VmRSS"]
    started_cpu, started = time.process_time(), time.perf_counter()
    if kind == "sdl":
        result = bpy.ops.import_scene.sdl(filepath=path)
    else:
        result = bpy.ops.wm.obj_import(filepath=path)
    cpu, wall = time.process_time() - started_cpu, time.perf_counter() - started
    after = _memory()
    return {"result": sorted(result), "cpu": round(cpu, 3), "wall": round(wall, 3),
            "rss_growth_mb": round((after["VmRSS"] - before) / 2**20, 1),
            "peak_growth_mb": round((after["VmHWM"] - before) / 2**20, 1), "objects": len(bpy.data.objects),
            "materials": len(bpy.data.materials), "meshes": len(bpy.data.meshes)}


def run_child(command: list[str], env: dict) -> dict:
    proc = subprocess.run(command, capture_output=True, text=True, env=env, cwd=ROOT)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    if proc.returncode != 0 or not lines:
        raise SystemExit(f"error: {' '.join(command)} failed:\n{proc.stdout[-3000:]}{proc.stderr[-3000:]}")
    return json.loads(lines[-1][len("RESULT "):])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--counts", type=int, nargs="+", default=[1000, 10000])
    parser.add_argument("--repeat", type=int, default=2)
    parser.add_argument("--obj-sphere", default="8x4", help="segments x rings of the .obj's spheres (8x4)")
    parser.add_argument("--blender", action="store_true", help="also under Debian's blender -b")
    parser.add_argument("--out", default=str(ROOT / "bench" / "results" / "blender_import.json"),
                        help="where the JSON goes (bench/results/blender_import.json)")
    parser.add_argument("--child", nargs=2, metavar=("KIND", "PATH"), help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        print("RESULT " + json.dumps(child(*args.child)), flush=True)
        os._exit(0)  # (freeing 10^5 objects at exit measures nothing)
    segments, rings = (int(v) for v in args.obj_sphere.lower().split("x"))
    hosts = {"bpy": ([sys.executable, __file__, "--child"], dict(os.environ, PYTHONPATH=str(ROOT)))}
    blender = shutil.which("blender")
    if args.blender and blender:
        sys.path.insert(0, str(ROOT / "tests"))
        from blender_binary import blender_numpy_path
        hosts["blender_b"] = None  # filled below, once there is a folder for its PYTHONPATH
    runs: dict = {}
    with tempfile.TemporaryDirectory(prefix="blender_import_") as tmp:
        folder = Path(tmp)
        if "blender_b" in hosts:
            hosts["blender_b"] = ([blender, "-b", "--factory-startup", "--python", __file__, "--", "--child"],
                                 dict(os.environ, PYTHONPATH=blender_numpy_path(blender, folder)))
        files = {count: write_scenes(count, folder, segments, rings) for count in args.counts}
        for _ in range(args.repeat):
            for count in args.counts:
                for host, (command, env) in hosts.items():
                    for kind, path in zip(("sdl", "obj"), files[count]):
                        result = run_child(command + [kind, str(path)], env)
                        runs.setdefault(f"{host} {count}", {}).setdefault(kind, []).append(result)
                        print(host, count, kind, json.dumps(result), file=sys.stderr, flush=True)
    import bpy  # (the host this ran in: the bpy module's version)

    summary: dict = {"bpy": bpy.app.version_string, "obj_sphere": args.obj_sphere, "repeat": args.repeat,
                     "runs": runs, "median_cpu": {},
                     "sdl_over_obj_cpu": {}}
    for key, kinds in runs.items():
        medians = {kind: statistics.median(r["cpu"] for r in results) for kind, results in kinds.items()}
        summary["median_cpu"][key] = medians
        summary["sdl_over_obj_cpu"][key] = round(medians["sdl"] / medians["obj"], 3)
        peaks = {kind: statistics.median(r["peak_growth_mb"] for r in results) for kind, results in kinds.items()}
        summary.setdefault("median_peak_growth_mb", {})[key] = peaks
        summary.setdefault("sdl_over_obj_peak", {})[key] = round(peaks["sdl"] / max(peaks["obj"], 1e-9), 3)
    if "blender_b" in hosts:
        summary["blender"] = subprocess.run([blender, "--version"], capture_output=True,
                                            text=True).stdout.splitlines()[0]
    text = json.dumps(summary, indent=1)
    print(json.dumps({k: summary[k] for k in ("median_cpu", "sdl_over_obj_cpu", "median_peak_growth_mb",
                                             "sdl_over_obj_peak")}, indent=1))
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(text + "\n")


if __name__ == "__main__":
    if "--" in sys.argv:  # under blender -b: the script's own arguments follow "--"
        sys.argv = [sys.argv[0]] + sys.argv[sys.argv.index("--") + 1:]
    main()
