"""Render passes of the ray through each pixel's centre (addon/pure/passes.py): Depth, Normal, Diffuse Color
(Albedo), Position and Mist, offered to the compositor where the view layer enables them and right for the
first hit; Normal and Albedo feed the compositor's Denoise node.  Each pass is read back through the
compositor (Render Layers output -> Composite -> a 32-bit EXR)."""
from __future__ import annotations

import bpy
import numpy as np
from bpy_extras.object_utils import world_to_camera_view

from addon import engine
from addon.pure import passes
from blender_scripts.addon_env import SCENES, compositor, fresh, import_sdl, render_rgba, set_resolution, shape_objects

WIDTH, HEIGHT = 96, 72


def _setup():
    fresh()
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(WIDTH, HEIGHT)
    layer = bpy.context.view_layer
    for switch, _, _ in passes.PASSES.values():
        setattr(layer, switch, True)
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    return scene


def _show(scene, output: str, through=None):
    """The compositor's output shows the Render Layers node's ``output`` (optionally through a node
    ``through(tree, rl)``)."""
    tree, composite = compositor(scene)
    layers = tree.nodes.new("CompositorNodeRLayers")
    source = layers.outputs[output] if through is None else through(tree, layers)
    tree.links.new(source, composite)


def _pixel(scene, point) -> tuple[int, int]:
    p = world_to_camera_view(scene, scene.camera, point)
    return int((1.0 - p.y) * HEIGHT), int(p.x * WIDTH)


def test_passes_hold_the_first_hit():
    scene = _setup()
    obj = next(o for o in shape_objects() if o["sdl_kind"] == "sphere" and o.active_material.sdl.diffuse[0] > 0.5)
    centre = np.array(obj.matrix_world.translation)
    radius = float(np.linalg.norm(np.array(obj.matrix_world.col[0])[:3]))
    cam = scene.camera.matrix_world
    eye, forward = np.array(cam.translation), -np.array(cam.col[2])[:3]
    forward /= np.linalg.norm(forward)
    row, col = _pixel(scene, obj.matrix_world.translation)
    images = {}
    for name in ("Depth", "Normal", "DiffCol", "Position", "Mist"):
        _show(scene, name)
        images[name] = render_rgba(engine.ENGINE_ID)
        assert engine.LAST_RENDER["passes_written"] == list(passes.PASSES)
    position = images["Position"][row, col, :3]
    assert abs(np.linalg.norm(position - centre) - radius) < 1e-3 * radius  # on the sphere
    assert np.linalg.norm(position - centre) and np.dot(position - centre, eye - centre) > 0  # its near side
    normal = images["Normal"][row, col, :3]
    np.testing.assert_allclose(normal, (position - centre) / radius, atol=1e-3)  # outward, unit
    assert abs(images["Depth"][row, col, 0] - np.dot(position - eye, forward)) < 1e-3
    np.testing.assert_allclose(images["DiffCol"][row, col, :3], obj.active_material.sdl.diffuse, atol=1e-6)
    world = scene.world.mist_settings
    distance = np.linalg.norm(position - eye)
    expected_mist = passes.mist_factor(np.array([distance]), world.start, world.depth, world.falloff)[0]
    assert abs(images["Mist"][row, col, 0] - expected_mist) < 1e-4
    sky = (0, WIDTH // 2)  # the top row shows the background
    assert images["Depth"][sky][0] == passes.NO_DEPTH and images["Mist"][sky][0] == 1.0
    assert not images["Normal"][sky][:3].any() and not images["DiffCol"][sky][:3].any()


def test_only_enabled_passes_are_offered():
    scene = _setup()
    layer = bpy.context.view_layer
    layer.use_pass_mist = layer.use_pass_position = False
    tree, _ = compositor(scene)
    rl = tree.nodes.new("CompositorNodeRLayers")
    offered = {o.name for o in rl.outputs if o.enabled}
    assert {"Image", "Depth", "Normal", "DiffCol"} <= offered and not {"Mist", "Position"} & offered
    bpy.ops.render.render()
    assert engine.LAST_RENDER["passes_written"] == ["Depth", "Normal", "DiffCol"]


def test_normal_and_albedo_feed_the_denoise_node():
    scene = _setup()
    _show(scene, "Image")
    plain = render_rgba(engine.ENGINE_ID)

    def denoise(tree, layers):
        node = tree.nodes.new("CompositorNodeDenoise")
        tree.links.new(layers.outputs["Image"], node.inputs["Image"])
        tree.links.new(layers.outputs["Normal"], node.inputs["Normal"])
        tree.links.new(layers.outputs["DiffCol"], node.inputs["Albedo"])
        return node.outputs["Image"]

    _show(scene, None, through=denoise)
    denoised = render_rgba(engine.ENGINE_ID)
    # one ray per pixel through its centre has no noise to remove: the denoiser, guided by the passes, keeps
    # the picture (a wrong or missing albedo would blur the shapes' edges into the background)
    difference = np.abs(denoised[..., :3] - plain[..., :3])
    assert np.median(difference) < 0.01 and difference.mean() < 0.03, (np.median(difference), difference.mean())
    assert denoised[..., :3].std() > 0.1
