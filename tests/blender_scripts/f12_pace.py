"""F12 at a real size against the tracer on its own, in one Blender process.

    blender -b --factory-startup --python-exit-code 1 --python f12_pace.py -- ROOT SCENE WIDTH HEIGHT
    python f12_pace.py ROOT SCENE WIDTH HEIGHT          (the bpy module)

Imports SCENE with the checkout's add-on, then twice in turn: ``tracer.render`` of the same file at the same
size, and F12 (``bpy.ops.render.render()``, SDL_RAYTRACER).  Prints ``RESULT {json}`` with both times (the
faster of two each) and the largest difference between F12's image and the tracer's.
"""
import json
import os
import sys
import tempfile
import time

import bpy

argv = sys.argv[sys.argv.index("--") + 1:] if "--" in sys.argv else sys.argv[1:]
root, scene_path, width, height = argv[0], argv[1], int(argv[2]), int(argv[3])
sys.path[:0] = [root, root + "/tests"]

import numpy as np  # noqa: E402

import addon  # noqa: E402
import tracer  # noqa: E402
from addon import engine  # noqa: E402
from blender_scripts.addon_env import fresh, import_sdl, set_resolution  # noqa: E402

fresh()
try:
    import_sdl(scene_path)
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    set_resolution(width, height)
    tracer_times, f12_times = [], []
    for _ in range(2):
        started = time.perf_counter()
        expected = tracer.render(tracer.load(scene_path), width, height).image
        tracer_times.append(time.perf_counter() - started)
        started = time.perf_counter()
        bpy.ops.render.render()
        f12_times.append(time.perf_counter() - started)
        assert "error" not in engine.LAST_RENDER, engine.LAST_RENDER
    # What F12 made, through an EXR (linear, as traced): the Render Result's pixels are not readable in Python.
    exr = os.path.join(tempfile.mkdtemp(), "f12.exr")
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    bpy.data.images["Render Result"].save_render(exr, scene=scene)
    image = bpy.data.images.load(exr)
    pixels = np.empty(width * height * 4, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    difference = float(np.abs(pixels.reshape(height, width, 4)[::-1, :, :3] - expected).max())
    print("RESULT " + json.dumps({"blender": bpy.app.version_string, "tracer_seconds": min(tracer_times),
                                  "f12_seconds": min(f12_times), "difference": difference,
                                  "size": list(image.size)}))
finally:
    addon.unregister()
