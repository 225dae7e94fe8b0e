"""Run by the bpy module's Python (not by pytest): install an extension zip with Blender's own installer into
the (empty) user folders the environment names, import an SDL file, render it with SDL_RAYTRACER and print
``RESULT {json}``: which tracer package and C core the add-on used, and the render's statistics.

    python install_zip.py ZIP SDL OUT.png
"""
import importlib
import json
import sys

import bpy

zip_path, sdl, out = sys.argv[-3:]
assert bpy.ops.extensions.package_install_files(filepath=zip_path, repo="user_default",
                                                 enable_on_install=True) == {"FINISHED"}
package = "bl_ext.user_default.sdl_raytracer"
tracer = importlib.import_module(package + ".tracer")  # the add-on's vendored copy
native = importlib.import_module(package + ".tracer.native")
for obj in list(bpy.data.objects):
    bpy.data.objects.remove(obj)
bpy.ops.import_scene.sdl(filepath=sdl)
scene = bpy.context.scene
scene.render.engine = "SDL_RAYTRACER"
scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 48, 36, 100
scene.render.filepath = out
bpy.ops.render.render(write_still=True)
stats = sys.modules[package + ".engine"].LAST_RENDER
print("RESULT " + json.dumps({"tracer": tracer.__name__, "tracer_file": tracer.__file__,
                              "library": native._lib._name if native._lib else None,
                              "load_error": native.load_error,
                              "stats": {k: v for k, v in stats.items() if k != "passes"}}))
