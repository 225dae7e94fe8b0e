"""Screenshots of the add-on in Blender's own window, for docs/blender.md (run under a display, e.g. Xvfb):

    xvfb-run -s '-screen 0 1600x1000x24' blender --factory-startup --python scripts/blender_screenshots.py -- OUT_DIR

Imports scenes/lecture.sdl with the checkout's add-on, then, a step at a time on Blender's event loop:
the 3D viewport in Rendered shading; the Properties editor's Material tab (slots, preview, SDL Material);
F12 with the Depth, Normal and Albedo passes and the render result; each saved as a PNG in OUT_DIR with
Blender's own screenshot operator.  Writes OUT_DIR/screenshots.json (material preview time and size) and
quits.
"""
import json
import os
import sys
import time

import bpy

OUT = os.path.abspath(sys.argv[sys.argv.index("--") + 1])
CHECKOUT = os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
sys.path.insert(0, CHECKOUT)

import addon  # noqa: E402
from addon import engine  # noqa: E402

report = {}


def _areas(kind):
    return [a for a in bpy.context.window.screen.areas if a.type == kind]


def _shot(name):
    window = bpy.context.window
    with bpy.context.temp_override(window=window, screen=window.screen, area=window.screen.areas[0]):
        bpy.ops.screen.screenshot(filepath=os.path.join(OUT, name), check_existing=False)


def setup():
    addon.register()
    bpy.ops.wm.read_homefile(use_empty=True)
    addon.register()
    bpy.ops.import_scene.sdl(filepath=os.path.join(CHECKOUT, "scenes", "lecture.sdl"))
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    scene.render.resolution_x, scene.render.resolution_y = 640, 480
    return 1.0


def viewport():
    for area in _areas("VIEW_3D"):
        space = area.spaces.active
        space.shading.type = "RENDERED"
        space.region_3d.view_perspective = "CAMERA"
        with bpy.context.temp_override(area=area, region=[r for r in area.regions if r.type == "WINDOW"][0]):
            bpy.ops.view3d.view_center_camera()
    return 15.0


def shoot_viewport():
    _shot("blender-viewport.png")
    obj = next(o for o in bpy.context.scene.objects if o.get("sdl_kind") == "sphere")
    for o in bpy.context.view_layer.objects:
        o.select_set(o == obj)
    bpy.context.view_layer.objects.active = obj
    return 1.0  # (the Properties editor offers the Material tab once it has redrawn for the object)


def material_tab():
    for area in _areas("PROPERTIES"):
        area.spaces.active.context = "MATERIAL"
    return 15.0  # (selecting restarted the viewport's refinement)


def shoot_material():
    _shot("blender-material.png")
    preview = bpy.context.object.active_material.preview
    report["material_preview_size"] = list(preview.image_size) if preview else None
    report["icon_size"] = list(preview.icon_size) if preview else None
    if preview and preview.icon_size[0]:
        import numpy as np
        pixels = np.array(preview.icon_pixels_float[:]).reshape(-1, 4)
        report["icon_mean"] = pixels.mean(axis=0).tolist()
        icon = bpy.data.images.new("material icon", *preview.icon_size)
        icon.pixels.foreach_set(pixels.ravel().astype("float32"))
        icon.filepath_raw = os.path.join(OUT, "material-icon.png")
        icon.file_format = "PNG"
        icon.save()
    report["last_render"] = {k: v for k, v in engine.LAST_RENDER.items() if k in ("width", "height", "seconds")}
    return 0.5


def passes_render():
    """F12 with Depth, Normal and Diffuse Color on, in an Image Editor beside a compositor with the
    Render Layers node (its pass outputs) wired to a Denoise node."""
    scene = bpy.context.scene
    layer = bpy.context.view_layer
    layer.use_pass_z = layer.use_pass_normal = layer.use_pass_diffuse_color = True
    scene.use_nodes = True
    tree = scene.node_tree
    tree.nodes.clear()
    layers = tree.nodes.new("CompositorNodeRLayers")
    layers.location = (-300, 0)
    denoise = tree.nodes.new("CompositorNodeDenoise")
    composite = tree.nodes.new("CompositorNodeComposite")
    composite.location = (250, 0)
    tree.links.new(layers.outputs["Image"], denoise.inputs["Image"])
    tree.links.new(layers.outputs["Normal"], denoise.inputs["Normal"])
    tree.links.new(layers.outputs["DiffCol"], denoise.inputs["Albedo"])
    tree.links.new(denoise.outputs["Image"], composite.inputs["Image"])
    view3d = _areas("VIEW_3D")[0]
    view3d.type = "NODE_EDITOR"
    view3d.spaces.active.tree_type = "CompositorNodeTree"
    bpy.ops.render.render()
    report["f12_seconds"] = engine.LAST_RENDER.get("seconds")
    report["passes_written"] = engine.LAST_RENDER.get("passes_written")
    return 2.0


def shoot_passes():
    area = _areas("NODE_EDITOR")[0]
    with bpy.context.temp_override(area=area, region=[r for r in area.regions if r.type == "WINDOW"][0]):
        bpy.ops.node.view_all()
    _shot("blender-passes.png")
    return 0.5


def finish():
    with open(os.path.join(OUT, "screenshots.json"), "w") as handle:
        json.dump({k: v for k, v in report.items() if k != "preview_started"}, handle)
    bpy.ops.wm.quit_blender()
    return None


STEPS = [setup, viewport, shoot_viewport, material_tab, shoot_material, passes_render, shoot_passes, finish]


def run_steps():
    step = STEPS.pop(0)
    delay = step()
    return delay if STEPS else None


os.makedirs(OUT, exist_ok=True)
bpy.app.timers.register(run_steps, first_interval=2.0, persistent=True)  # (survives read_homefile)
