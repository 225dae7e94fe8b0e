"""Instances, traced: each kind of instance Blender makes, rendered alone by Workbench and by SDL_RAYTRACER at
160 x 120; prints ``RESULT {json}`` with each case's silhouette IoU, pixel counts, the objects traced and
the distinct tracer meshes they use, and whether the built objects are rows of a ShapeTable (with float32
matrices, as Blender gives them) rather than a Shape each.

    blender -b --factory-startup --python-exit-code 1 --python instances.py -- ROOT
    python instances.py ROOT                     (the bpy module)

Cases: geometry nodes' Instance on Points (a cone from Object Info on a grid's points), the same joined with
the grid (Join Geometry), a collection's two meshes picked per point (Collection Info, Pick Instance), a
collection instance (an empty) and hair particles drawn as an object.  Works in Blender 3.4 and 4.x/5.0 (the
node group's sockets are made through ``interface`` where there is one).
"""
import gc
import json
import math
import sys
import tracemalloc

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
root = argv[0]
sys.path[:0] = [root, root + "/tests"]

import addon  # noqa: E402
from addon import engine  # noqa: E402
from addon.scene_build import SceneBuilder  # noqa: E402
from blender_scripts.addon_env import fresh, iou, render_rgba, set_resolution  # noqa: E402

WIDTH, HEIGHT = 160, 120


def _node_group(obj, name: str):
    """A geometry nodes modifier on ``obj`` with a new group of one geometry input and output."""
    tree = bpy.data.node_groups.new(name, "GeometryNodeTree")
    if hasattr(tree, "interface"):  # Blender 4.0+
        tree.interface.new_socket("Geometry", in_out="INPUT", socket_type="NodeSocketGeometry")
        tree.interface.new_socket("Geometry", in_out="OUTPUT", socket_type="NodeSocketGeometry")
    else:
        tree.inputs.new("NodeSocketGeometry", "Geometry")
        tree.outputs.new("NodeSocketGeometry", "Geometry")
    obj.modifiers.new(name, "NODES").node_group = tree
    return tree, tree.nodes.new("NodeGroupInput"), tree.nodes.new("NodeGroupOutput")


def _grid():
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=4)
    return bpy.context.object


def _cone():
    bpy.ops.mesh.primitive_cone_add(radius1=0.35, depth=0.8, location=(30, 0, 0))
    cone = bpy.context.object
    cone.hide_render = True  # only its instances show
    return cone


def instance_on_points(join: bool):
    grid, cone = _grid(), _cone()
    tree, group_in, group_out = _node_group(grid, "on points")
    on_points = tree.nodes.new("GeometryNodeInstanceOnPoints")
    info = tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = cone
    tree.links.new(group_in.outputs[0], on_points.inputs["Points"])
    tree.links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    result = on_points.outputs[0]
    if join:
        joined = tree.nodes.new("GeometryNodeJoinGeometry")
        tree.links.new(on_points.outputs[0], joined.inputs[0])
        tree.links.new(group_in.outputs[0], joined.inputs[0])
        result = joined.outputs[0]
    tree.links.new(result, group_out.inputs[0])


def picked_from_a_collection():
    grid = _grid()
    parts = bpy.data.collections.new("parts")
    bpy.context.scene.collection.children.link(parts)
    bpy.ops.mesh.primitive_cube_add(size=0.5)
    cube = bpy.context.object
    bpy.ops.mesh.primitive_ico_sphere_add(radius=0.4, subdivisions=2)
    ball = bpy.context.object
    for obj in (cube, ball):
        bpy.context.scene.collection.objects.unlink(obj)
        parts.objects.link(obj)
    parts.hide_render = True
    tree, group_in, group_out = _node_group(grid, "picked")
    on_points = tree.nodes.new("GeometryNodeInstanceOnPoints")
    info = tree.nodes.new("GeometryNodeCollectionInfo")
    info.inputs["Collection"].default_value = parts
    info.inputs["Separate Children"].default_value = True
    info.inputs["Reset Children"].default_value = True
    pick = tree.nodes.new("FunctionNodeRandomValue")
    pick.data_type = "INT"
    for socket in pick.inputs:  # (the INT sockets: named as the FLOAT and vector ones before them)
        if socket.name == "Min" and socket.type == "INT":
            socket.default_value = 0
        if socket.name == "Max" and socket.type == "INT":
            socket.default_value = 1
    index = next(s for s in pick.outputs if s.type == "INT" and s.enabled)
    on_points.inputs["Pick Instance"].default_value = True
    tree.links.new(group_in.outputs[0], on_points.inputs["Points"])
    tree.links.new(info.outputs[0], on_points.inputs["Instance"])
    tree.links.new(index, on_points.inputs["Instance Index"])
    tree.links.new(on_points.outputs[0], group_out.inputs[0])


def collection_instance():
    bpy.ops.mesh.primitive_monkey_add(size=1.0, location=(30, 0, 0))
    monkey = bpy.context.object
    kept = bpy.data.collections.new("kept")
    bpy.context.scene.collection.objects.unlink(monkey)
    kept.objects.link(monkey)  # (not linked to the scene: seen only through its instances)
    kept.instance_offset = (30, 0, 0)
    for x in (-1.5, 1.5):
        empty = bpy.data.objects.new(f"instance {x}", None)
        empty.instance_type = "COLLECTION"
        empty.instance_collection = kept
        empty.location = (x, 0, 0.5)
        empty.rotation_euler = (0.3, 0.2, x)
        bpy.context.scene.collection.objects.link(empty)


def particles():
    grid = _grid()
    cone = _cone()
    system = grid.modifiers.new("hair", "PARTICLE_SYSTEM").particle_system
    settings = system.settings
    settings.type, settings.count = "HAIR", 12
    settings.render_type, settings.instance_object = "OBJECT", cone
    settings.particle_size = 1.0
    if hasattr(settings, "use_rotation_instance"):
        settings.use_rotation_instance = True
    grid.show_instancer_for_render = False


CASES = {"instance on points": lambda: instance_on_points(False),
         "joined with the grid": lambda: instance_on_points(True),
         "picked from a collection": picked_from_a_collection,
         "collection instance": collection_instance,
         "hair particles": particles}


def measure(make) -> dict:
    fresh()
    make()
    scene = bpy.context.scene
    bpy.ops.object.camera_add(location=(0, -9, 6), rotation=(math.radians(56), 0, 0))
    scene.camera = bpy.context.object
    set_resolution(WIDTH, HEIGHT)
    scene.render.film_transparent = True
    scene.display.render_aa = "OFF"
    s = scene.sdl_render
    s.block_size, s.progressive, s.samples, s.max_recursion_depth = 1, False, 1, 0
    workbench = render_rgba("BLENDER_WORKBENCH")[..., 3] > 0.5
    traced = render_rgba(engine.ENGINE_ID)[..., 3] > 0.5
    done = engine.LAST_RENDER  # (what the render traced: its objects, meshes and instance rows)
    return {"rows": done.get("instance_rows"), "iou": round(iou(workbench, traced), 4),
            "workbench": int(workbench.sum()), "traced": int(traced.sum()), "objects": done.get("objects"),
            "meshes": done.get("meshes"), "error": done.get("error")}


def kept_by_a_build(points: int = 30) -> dict:
    """Python bytes a scene build of ``points`` x ``points`` geometry-nodes instances keeps once its scene is
    dropped, per instance: bpy keeps ~120 for each instance whose object is read (Blender 4.5, 5.0), which
    a build reads only where Blender cannot list the instances without their objects (before 4.3)."""
    fresh()
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=points - 1, y_subdivisions=points - 1, size=points)
    grid, cone = bpy.context.object, _cone()
    grid.rotation_euler, grid.location = (0.3, 0.2, 0.1), (0.5, -0.25, 1.0)
    tree, group_in, group_out = _node_group(grid, "on points")
    on_points, info = tree.nodes.new("GeometryNodeInstanceOnPoints"), tree.nodes.new("GeometryNodeObjectInfo")
    info.inputs["Object"].default_value = cone
    tree.links.new(group_in.outputs[0], on_points.inputs["Points"])
    tree.links.new(info.outputs["Geometry"], on_points.inputs["Instance"])
    tree.links.new(on_points.outputs[0], group_out.inputs[0])
    depsgraph = bpy.context.evaluated_depsgraph_get()
    SceneBuilder(depsgraph).build(bpy.context.scene, skip_hidden_render=True)  # (once first: caches, imports)
    tracemalloc.start()
    built = SceneBuilder(depsgraph).build(bpy.context.scene, skip_hidden_render=True)
    objects = len(built.objects)
    del built
    gc.collect()
    kept = tracemalloc.get_traced_memory()[0]
    tracemalloc.stop()
    return {"objects": objects, "kept_per_instance": round(kept / points ** 2, 1),
            "listed_without_objects": hasattr(bpy.types.Object, "evaluated_geometry")}


try:
    print("RESULT " + json.dumps({"blender": bpy.app.version_string,
                                  "cases": {name: measure(make) for name, make in CASES.items()},
                                  "kept": kept_by_a_build()}))
finally:
    addon.unregister()
