"""An SDL file rendered by F12 where Pillow cannot be imported (as in Blender's own Python).

    blender -b --factory-startup --python-exit-code 1 --python render_without_pillow.py -- ROOT SCENE W H OUT
    python render_without_pillow.py ROOT SCENE W H OUT          (the bpy module)

Pillow is made unimportable first; the checkout's add-on is registered, SCENE imported and rendered at
W x H; the render is saved to OUT as a 32-bit EXR (linear, as traced).  Prints ``RESULT {json}``.
"""
import json
import sys

sys.modules["PIL"] = None  # `import PIL` now raises ImportError, whatever is installed

import bpy  # noqa: E402

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
root, scene_path, width, height, out = argv[0], argv[1], int(argv[2]), int(argv[3]), argv[4]
sys.path[:0] = [root, root + "/tests"]

import addon  # noqa: E402
from addon import engine  # noqa: E402
from blender_scripts.addon_env import fresh, import_sdl, set_resolution  # noqa: E402

fresh()
try:
    import_sdl(scene_path)
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    set_resolution(width, height)
    bpy.ops.render.render()
    stats = dict(engine.LAST_RENDER)
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    bpy.data.images["Render Result"].save_render(out, scene=scene)
    print("RESULT " + json.dumps({"blender": bpy.app.version_string, "error": stats.get("error"),
                                  "pillow": "PIL" in sys.modules and sys.modules["PIL"] is not None,
                                  "images_left": [i.name for i in bpy.data.images if i.source == "FILE"
                                                  and i.users == 0]}))
finally:
    addon.unregister()
