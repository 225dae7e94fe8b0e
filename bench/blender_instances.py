"""Instances at scale: geometry nodes put N instances of one mesh of T triangles on a grid's points; the
add-on turns the depsgraph into a tracer scene and compiles it.  What each instance costs, against the mesh
once, in the bpy module:

    python bench/blender_instances.py [--instances 100000] [--triangles 10000] [--render 320x240]

Measured, each in its own step: the scene build (depsgraph -> tracer Scene: a ShapeTable, a row per instance
holding its matrix and the number of the one MeshData they share), compile_scene (primitive rows, bounds, the mesh's BVH once, the object hierarchy) and
an F12 (the engine's whole render, build and compile included; first, so that its growth is not memory the others freed;
its peak sampled every 2 ms while it runs).  Memory is the process's resident size
before and after each step (/proc/self/statm) and, in a second pass, Python's own allocations per step
(tracemalloc: slower, so its times are not reported).  The mesh once is its arrays plus its BVH, measured
alone (one instance).  What a render holds per instance while it traces is counted from the arrays
(held_per_instance: rows, primitive table, the C core's flat tables and object hierarchy).  What bpy itself keeps for each read of an instance's object (which the build avoids
where Blender 4.3+ lists the instances) is measured alone too (bpy_keeps_per_object_read).  Prints JSON and writes
bench/results/blender_instances.json.
"""
from __future__ import annotations

import argparse
import ctypes
import json
import sys
import threading
import time
import tracemalloc
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parent.parent
sys.path[:0] = [str(ROOT), str(ROOT / "tests")]


def _rss() -> int:
    with open("/proc/self/statm") as statm:
        return int(statm.read().split()[1]) * 4096


def _scene(instances: int, triangles: int):
    """A grid of ``instances`` points with a UV sphere of about ``triangles`` triangles on each."""
    import math

    import bpy

    from blender_scripts.addon_env import fresh, set_resolution

    fresh()
    side = max(1, round(math.sqrt(instances)))
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=side - 1, y_subdivisions=side - 1, size=side * 3.0)
    grid = bpy.context.object
    rings = max(3, round(math.sqrt(triangles / 4)))
    bpy.ops.mesh.primitive_uv_sphere_add(segments=2 * rings, ring_count=rings, radius=1.0, location=(0, 0, -50))
    ball = bpy.context.object
    ball.hide_render = ball.hide_viewport = True
    tree = bpy.data.node_groups.new("instances", "GeometryNodeTree")
    if hasattr(tree, "interface"):
        tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
        tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    else:
        tree.inputs.new("NodeSocketGeometry", "Geometry")
        tree.outputs.new("NodeSocketGeometry", "Geometry")
    grid.modifiers.new("instances", "NODES").node_group = tree
    group_in, group_out = tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")
    on_points, info = tree.nodes.new("GeometryNodeInstanceOnPoints"), tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = ball
    tree.links.new(group_in.outputs[0], on_points.inputs["Points"])
    tree.links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    tree.links.new(on_points.outputs[0], group_out.inputs[0])
    bpy.ops.object.light_add(type="SUN", rotation=(0.5, 0.2, 0.0))
    bpy.ops.object.camera_add(location=(0.0, -side * 2.0, side * 1.5), rotation=(0.9, 0.0, 0.0))
    bpy.context.scene.camera = bpy.context.object
    bpy.context.view_layer.update()
    return len(ball.data.polygons), side * side


def _steps(traced: bool) -> dict:
    """Build and compile the evaluated scene; per step CPU seconds, resident growth and (``traced``)
    Python's allocations."""
    import bpy

    from addon import engine
    from addon.tracer.compile import compile_scene

    depsgraph = bpy.context.evaluated_depsgraph_get()
    out = {}
    kept = {}

    def step(name, work):
        before_rss, before_cpu = _rss(), time.process_time()
        if traced:
            tracemalloc.start()
            before = tracemalloc.take_snapshot()
        kept[name] = work()
        entry = {"seconds_cpu": round(time.process_time() - before_cpu, 2), "rss_growth": _rss() - before_rss}
        if traced:
            entry["python_allocated"] = tracemalloc.get_traced_memory()[0]
            growth = tracemalloc.take_snapshot().compare_to(before, "lineno")
            tracemalloc.stop()
            # where it went: the lines that kept the most, per instance
            entry["where"] = {str(stat.traceback[0]).replace(str(ROOT) + "/", ""): stat.size_diff
                              for stat in growth[:8]}
        out[name] = entry

    step("build", lambda: engine.build_scene(depsgraph, "RENDER")[0])
    step("compile", lambda: compile_scene(kept["build"]))
    out["objects"] = len(kept["build"].objects)
    out["meshes"] = _meshes(kept["build"].objects)
    return out, kept


def _first(objects):
    """The first object, without making the others (a ShapeTable's rows stay rows)."""
    from addon.tracer.model import ShapeTable

    return objects.shape_at(0) if isinstance(objects, ShapeTable) else objects[0]


def _meshes(objects) -> int:
    """How many distinct meshes the objects hold (a table's: by its mesh numbers, without making Shapes)."""
    from addon.tracer.model import ShapeTable

    if isinstance(objects, ShapeTable) and objects.columns is not None:
        columns = objects.columns
        return len({id(columns.mesh_of(int(i))) for i in np.unique(columns.mesh_ids, return_index=True)[1]})
    return len({id(s.mesh) for s in objects})


def _mesh_once() -> dict:
    """The bytes of the one mesh, its arrays and its BVH: a scene of one instance of it, compiled first (the
    mesh's BVH is built then, and found again by content by the compile of all the instances)."""
    import bpy

    from addon import engine
    from addon.tracer.compile import compile_scene
    from addon.tracer.model import Scene

    built, _ = engine.build_scene(bpy.context.evaluated_depsgraph_get(), "RENDER")
    first = _first(built.objects)
    mesh = first.mesh
    arrays = sum(a.nbytes for a in (mesh.vertices, mesh.normals) + tuple(mesh.faces.arrays()))
    before = _rss()
    tracemalloc.start()
    compiled = compile_scene(Scene(objects=[first], lights=built.lights, settings=built.settings))
    python = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    _mesh_once.kept = (compiled, built)  # (alive while the instances are compiled: their BVH is this one)
    traced = _arrays_bytes(vars(next(iter(compiled.table.meshes.values())).arrays()).values(), set())
    # (compiled_python_allocated and rss_growth are ~0 when the F12 before made the mesh's BVH: it is found
    # again by content; traced counts the mesh's arrays as the C core walks them, its BVH included)
    return {"triangles": int(len(mesh.faces)), "arrays": int(arrays), "traced_arrays": int(traced),
            "compiled_python_allocated": int(python), "rss_growth": _rss() - before}


def _bpy_object_reads() -> float:
    """Bytes per instance that bpy itself keeps, for good, when ``DepsgraphObjectInstance.object`` is read
    (each read of a geometry-nodes instance's object makes a Python object bpy never frees, in 4.5 and 5.0;
    the scene build reads it once per geometry where Blender lists the instances itself, 4.3+, and once per
    instance before)."""
    import bpy

    depsgraph = bpy.context.evaluated_depsgraph_get()
    tracemalloc.start()
    before = tracemalloc.get_traced_memory()[0]
    count = 0
    for inst in depsgraph.object_instances:
        inst.object
        count += 1
    kept = tracemalloc.get_traced_memory()[0] - before
    tracemalloc.stop()
    return round(kept / count, 1)


def _arrays_bytes(arrays, seen: set) -> int:
    """The bytes of these NumPy arrays' own buffers, each buffer once (``seen``: the ids of the buffers counted
    already; a view counts as its base)."""
    total = 0
    for array in arrays:
        if not isinstance(array, np.ndarray):
            continue
        base = array
        while isinstance(base.base, np.ndarray):
            base = base.base
        if id(base) not in seen:
            seen.add(id(base))
            total += base.nbytes
    return total


def _held(built, compiled, points: int) -> dict:
    """Bytes per instance that a render holds while it traces, by what holds them (counted from the arrays,
    not the resident size, which moves with what earlier steps freed): the scene's table of rows, the
    compiled primitive table, the C core's flat tables beside it and its object hierarchy's pair records."""
    from addon.tracer.native.tracer import NativeTracer, _flat_scene

    seen: set = set()
    table = _arrays_bytes(vars(built.objects.columns).values(), seen) if built.objects.columns is not None else 0
    primitives = _arrays_bytes(vars(compiled.table).values(), seen)
    stored = getattr(compiled.table, "stored", None)  # (an InstancedTable's table of its stored rows)
    if stored is not None:
        primitives += _arrays_bytes(vars(stored).values(), seen)
    flat = _arrays_bytes(_flat_scene(compiled).arrays.values(), seen)
    pairs, items, _ = NativeTracer(compiled, threads=1).object_tree()
    held = {"rows": table, "primitive_table": primitives, "flat_tables": flat,
            "object_hierarchy": len(pairs) + 8 * len(items)}
    return {name: round(size / points, 1) for name, size in held.items()}


def _heap_free() -> int:
    """Bytes malloc holds free in its heap (glibc's mallinfo2; -1 where there is none)."""
    class MallInfo(ctypes.Structure):
        _fields_ = [(name, ctypes.c_size_t) for name in
                    ("arena", "ordblks", "smblks", "hblks", "hblkhd", "usmblks", "fsmblks", "uordblks", "fordblks",
                     "keepcost")]
    try:
        mallinfo = ctypes.CDLL("libc.so.6").mallinfo2
    except (OSError, AttributeError):
        return -1
    mallinfo.restype = MallInfo
    return int(mallinfo().fordblks)


def _f12(size: str) -> dict:
    """The engine's whole render (build, compile, trace) at ``size`` (WxH): CPU seconds and resident growth."""
    import bpy

    from addon import engine
    from blender_scripts.addon_env import set_resolution

    width, height = (int(v) for v in size.split("x"))
    set_resolution(width, height)
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    scene.sdl_render.block_size, scene.sdl_render.progressive = 1, False
    # (what the heap holds free before: Blender leaves tens of MB free after evaluating the scene, which the
    # render takes again without growing; given back first, malloc_trim, the growth is Blender's evaluation
    # of the render's own depsgraph too)
    heap_free = _heap_free()
    before_rss, before_cpu = _rss(), time.process_time()
    peak, done = [before_rss], threading.Event()

    def sample() -> None:  # (the resident size every 2 ms while the render runs: its peak)
        while not done.wait(0.002):
            peak[0] = max(peak[0], _rss())

    sampler = threading.Thread(target=sample)
    sampler.start()
    try:
        bpy.ops.render.render()
    finally:
        done.set()
        sampler.join()
    after = _rss()
    return {"seconds_cpu": round(time.process_time() - before_cpu, 2), "rss_growth": after - before_rss,
            "rss_peak_growth": max(peak[0], after) - before_rss, "heap_free_before": heap_free, "rays": engine.LAST_RENDER.get("rays"),
            "error": engine.LAST_RENDER.get("error")}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--instances", type=int, default=100_000)
    parser.add_argument("--triangles", type=int, default=10_000)
    parser.add_argument("--render", default="320x240", help="F12 size, or 'none'")
    args = parser.parse_args()
    import bpy

    import addon.tracer.native  # noqa: F401  (the C core built before anything is measured)

    triangles, points = _scene(args.instances, args.triangles)
    # (the F12 first, before the steps below free what its growth would take again: it grows by the mesh
    # once, its BVH built, and what the instances cost)
    f12 = _f12(args.render) if args.render != "none" else None
    mesh = _mesh_once()
    timed, kept = _steps(traced=False)
    del kept
    traced, kept = _steps(traced=True)
    held = _held(kept["build"], kept["compile"], points)
    del kept
    steps = ("build", "compile")
    result = {"instances": points, "mesh_polygons": triangles, "blender": bpy.app.version_string,
              "timed": timed, "python_allocated": {k: traced[k]["python_allocated"] for k in steps},
              "mesh_once": mesh,
              "where_per_instance": {k: {line: round(size / points, 1) for line, size in traced[k]["where"].items()}
                                     for k in steps}}
    # (the mesh's BVH was built by _mesh_once and is found again: what build and compile add is per instance)
    result["bytes_per_instance_rss"] = round(sum(timed[k]["rss_growth"] for k in steps) / points, 1)
    result["bytes_per_instance_python"] = round(sum(result["python_allocated"].values()) / points, 1)
    result["held_per_instance"] = held
    result["bpy_keeps_per_object_read"] = _bpy_object_reads()
    if f12 is not None:
        result["f12"] = f12
    text = json.dumps(result, indent=1)
    print(text)
    out = ROOT / "bench" / "results" / "blender_instances.json"
    out.parent.mkdir(exist_ok=True)
    out.write_text(text + "\n")


if __name__ == "__main__":
    main()
