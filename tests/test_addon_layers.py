"""View layers: F12 renders each view layer into its own layer of the render result, with that layer's own
visible collections (Blender calls the engine once per layer).  Checked through the compositor: a Render
Layers node picks one layer's image for the Composite output, which F12 saves."""
from __future__ import annotations

import bpy
import numpy as np

from blender_scripts.addon_env import SCENES, compositor, fresh, import_sdl, render_rgba, set_resolution
from addon import engine


def _composite_layer(scene, name: str) -> None:
    """The compositor's output shows view layer ``name``'s Combined pass."""
    tree, output = compositor(scene)
    layers = tree.nodes.new("CompositorNodeRLayers")
    layers.scene, layers.layer = scene, name
    tree.links.new(layers.outputs["Image"], output)


def test_each_view_layer_renders_its_own_collections():
    fresh()
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(48, 36)
    scene = bpy.context.scene
    scene.render.film_transparent = True  # coverage tells which objects a layer shows
    sdl_collection = next(c for c in bpy.data.collections if c.name.startswith("SDL lecture"))
    first = scene.view_layers[0]
    second = scene.view_layers.new("Empty")
    second.layer_collection.children[sdl_collection.name].exclude = True  # nothing to trace in this layer
    _composite_layer(scene, first.name)
    full = render_rgba(engine.ENGINE_ID)
    assert engine.LAST_RENDER["view_layer"] in (first.name, second.name)
    _composite_layer(scene, second.name)
    empty = render_rgba(engine.ENGINE_ID)
    assert full[..., 3].mean() > 0.3  # the scene's shapes cover much of the frame
    assert np.all(empty[..., 3] == 0)  # the layer without the collection: nothing but background
    second.use = False  # F12 skips a layer that is not used for rendering
    _composite_layer(scene, first.name)
    np.testing.assert_array_equal(render_rgba(engine.ENGINE_ID), full)
