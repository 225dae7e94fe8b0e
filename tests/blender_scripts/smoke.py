"""Run inside ``blender -b --python-exit-code 1 --python smoke.py -- MODE ROOT OUT``: the add-on end to end in
a real Blender (any version from 3.4), raising (so Blender exits 1) on any failure.

MODE ``dev``: the add-on is the checkout's ``addon`` package, registered with ``addon.register()``.
MODE ``zip:PATH``: the legacy zip built by scripts/build_extension.py --legacy, installed through
Blender's add-on installer into an empty user scripts folder and enabled.

Checks: register/unregister twice; import of every bundled scene with each shape at its SDL transform;
export -> re-read gives the same matrices and materials; object names (spaces, non-ASCII) survive export ->
import; a small SDL_RAYTRACER render equal to the tracer's
own; prints ``RESULT {json}``.
"""
import importlib
import json
import os
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:]
mode, root, out = argv[0], argv[1], argv[2]

if mode == "dev":
    sys.path.insert(0, root)
    import addon

    package = "addon"
    for _ in range(2):
        addon.register()
        addon.unregister()
        assert not hasattr(bpy.types, "IMPORT_SCENE_OT_sdl") and not hasattr(bpy.types.Scene, "sdl_render")
    addon.register()
else:
    import addon_utils

    zip_path = mode.split(":", 1)[1]
    bpy.ops.preferences.addon_install(filepath=zip_path, overwrite=True)
    addon_utils.modules_refresh()
    package = "sdl_raytracer"
    addon_utils.enable(package, default_set=True, handle_error=None)
    assert hasattr(bpy.types, "IMPORT_SCENE_OT_sdl"), "the installed add-on did not register"

import numpy as np  # noqa: E402

engine = sys.modules[package + ".engine"]
tracer = importlib.import_module(package + ".tracer")  # the add-on's own (in the checkout: the top-level one)
convert = sys.modules[package + ".pure.convert"]
axes = convert.axis_matrix()


def clear():
    for collection in (bpy.data.objects, bpy.data.meshes, bpy.data.materials, bpy.data.collections):
        for item in list(collection):
            collection.remove(item)


checked = {}
scenes = sorted(f for f in os.listdir(os.path.join(root, "scenes")) if f.endswith(".sdl"))
for name in scenes:
    clear()
    path = os.path.join(root, "scenes", name)
    original = tracer.load(path)
    assert bpy.ops.import_scene.sdl(filepath=path) == {"FINISHED"}
    objs = sorted((o for o in bpy.data.objects if "sdl_kind" in o), key=lambda o: o["sdl_order"])
    assert len(objs) == len(original.shapes()), name
    for shape, obj in zip(original.shapes(), objs):
        mesh_matrix = np.array(list(obj.data.get("sdl_mesh_matrix", np.eye(4).ravel()))).reshape(4, 4)
        shown = np.array([list(r) for r in obj.matrix_world]) @ mesh_matrix
        assert np.allclose(shown, axes @ shape.matrix, atol=1e-5 * max(1, abs(shape.matrix).max())), obj.name
    exported_path = os.path.join(out, name)
    assert bpy.ops.export_scene.sdl(filepath=exported_path) == {"FINISHED"}
    again = tracer.load(exported_path)
    for a, b in zip(original.shapes(), again.shapes()):
        assert np.allclose(a.matrix, b.matrix, atol=1e-6 * max(1, abs(a.matrix).max())), name
        assert a.material == b.material, name
    checked[name] = len(objs)

# Object names (spaces, non-ASCII) survive export -> import through the ``! name:`` comments.
clear()
bpy.ops.import_scene.sdl(filepath=os.path.join(root, "scenes", "lecture.sdl"))
for index, obj in enumerate(o for o in bpy.data.objects if "sdl_kind" in o):
    obj.name = f"Objekt {index} ü✓"
names = sorted(o.name for o in bpy.data.objects if o.type == "MESH")
assert bpy.ops.export_scene.sdl(filepath=os.path.join(out, "named.sdl")) == {"FINISHED"}
clear()
bpy.ops.import_scene.sdl(filepath=os.path.join(out, "named.sdl"))
assert sorted(o.name for o in bpy.data.objects if o.type == "MESH") == names, names

clear()
path = os.path.join(root, "scenes", "lecture.sdl")
bpy.ops.import_scene.sdl(filepath=path)
scene = bpy.context.scene
scene.render.engine = "SDL_RAYTRACER"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 48, 100
scene.render.image_settings.file_format = "OPEN_EXR"
scene.render.filepath = os.path.join(out, "lecture.exr")
scene.render.use_file_extension = False
scene.view_settings.view_transform = "Standard"
bpy.ops.render.render(write_still=True)
image = bpy.data.images.load(scene.render.filepath)
pixels = np.array(image.pixels[:], dtype=np.float32).reshape(48, 64, 4)[::-1, :, :3]
expected = tracer.render(tracer.load(path), 64, 48).image
difference = float(np.abs(pixels - expected).max())
assert difference < 1e-3, difference
stats = dict(engine.LAST_RENDER)
assert "error" not in stats, stats
print("RESULT " + json.dumps({"blender": bpy.app.version_string, "tracer": tracer.__name__, "scenes": checked,
                              "max_difference": difference, "rays": stats["rays"], "seconds": stats["seconds"]}))
