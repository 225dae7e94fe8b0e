"""The colour rule (docs/blender.md): after importing an SDL file, F12 shows, and saves, the tracer's PNG.

    blender -b --factory-startup --python-exit-code 1 --python colour_rule.py -- ROOT OUT [WIDTH HEIGHT]
    python colour_rule.py ROOT OUT [WIDTH HEIGHT]          (the bpy module)

For each of lecture.sdl and textures.sdl: imported into an empty file with the importer's defaults, F12 at
64 x 48 (or WIDTH x HEIGHT) with the scene's view settings as the importer left them, the Render Result saved as an 8-bit PNG
(saving applies the view transform, as the Image Editor's display does) to OUT/NAME-blender.png.  Also: a
scene made in Blender keeps Blender's colour management: an import into it leaves it alone, unless asked
for (``colour_management="SDL"``); ``"KEEP"`` leaves it alone whatever the scene.  Prints ``RESULT {json}``; the test compares the PNGs with the tracer's.
"""
import json
import os
import sys

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
root, out = argv[0], argv[1]
size = (int(argv[2]), int(argv[3])) if len(argv) > 3 else (64, 48)
sys.path.insert(0, root)

import addon  # noqa: E402
from addon import engine  # noqa: E402

addon.register()
result = {"blender": bpy.app.version_string, "view": {}}
try:
    bpy.ops.wm.read_homefile()  # Blender's own startup scene: Filmic (3.x) or AgX (4.x) and its look
    native = bpy.context.scene.view_settings.view_transform
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = 64, 48, 100
    bpy.ops.render.render()
    result["native_before"], result["native_after"] = native, scene.view_settings.view_transform
    lecture = os.path.join(root, "scenes", "lecture.sdl")
    assert bpy.ops.import_scene.sdl(filepath=lecture) == {"FINISHED"}  # into the startup scene's objects
    result["kept_by_default"] = scene.view_settings.view_transform
    assert bpy.ops.import_scene.sdl(filepath=lecture, colour_management="SDL") == {"FINISHED"}
    result["asked_for"] = scene.view_settings.view_transform
    bpy.ops.wm.read_homefile(use_empty=True)
    addon.register()
    result["empty_before"] = bpy.context.scene.view_settings.view_transform
    assert bpy.ops.import_scene.sdl(filepath=lecture, colour_management="KEEP") == {"FINISHED"}
    result["kept_when_asked"] = bpy.context.scene.view_settings.view_transform
    for name in ("lecture", "textures"):
        bpy.ops.wm.read_homefile(use_empty=True)
        addon.register()
        assert bpy.ops.import_scene.sdl(filepath=os.path.join(root, "scenes", name + ".sdl")) == {"FINISHED"}
        scene = bpy.context.scene
        scene.render.engine = engine.ENGINE_ID
        scene.render.resolution_x, scene.render.resolution_y, scene.render.resolution_percentage = *size, 100
        scene.render.image_settings.file_format = "PNG"
        scene.render.image_settings.color_depth = "8"
        scene.render.image_settings.color_mode = "RGB"
        bpy.ops.render.render()
        assert "error" not in engine.LAST_RENDER, engine.LAST_RENDER
        bpy.data.images["Render Result"].save_render(os.path.join(out, name + "-blender.png"), scene=scene)
        result["view"][name] = scene.view_settings.view_transform
    print("RESULT " + json.dumps(result))
finally:
    addon.unregister()
