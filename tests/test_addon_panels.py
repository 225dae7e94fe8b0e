"""The Properties editor with the SDL Ray Tracer as the render engine, as with Cycles: the material slot
list with New (Blender 3.4-5.0 call that panel EEVEE_MATERIAL_PT_context_material), the SDL Material panel,
a light's colour and power with the SDL light colour they make, and material previews traced by the engine.
(Drawing needs a window; these check that each panel offers itself for the engine's data.)"""
from __future__ import annotations

import bpy

from addon import engine, ui
from blender_scripts.addon_env import SCENES, fresh, import_sdl, shape_objects


def _polls(panel, **context) -> bool:
    with bpy.context.temp_override(**context):
        return bool(panel.poll(bpy.context))


def test_material_and_light_panels_show_for_the_engine():
    fresh()
    import_sdl(SCENES / "lecture.sdl")
    bpy.context.scene.render.engine = engine.ENGINE_ID
    obj = shape_objects()[0]
    slots = bpy.types.EEVEE_MATERIAL_PT_context_material
    assert engine.ENGINE_ID in slots.COMPAT_ENGINES
    assert _polls(slots, object=obj, material=obj.active_material)
    assert _polls(ui.SDL_PT_material, material=obj.active_material)
    assert engine.ENGINE_ID in bpy.types.MATERIAL_PT_preview.COMPAT_ENGINES
    assert engine.SDLRenderEngine.bl_use_preview  # the preview is traced by the engine itself
    light = next(o for o in bpy.data.objects if o.type == "LIGHT")
    assert _polls(ui.SDL_PT_light, light=light.data)
    bpy.context.scene.render.engine = "BLENDER_WORKBENCH"
    assert not _polls(ui.SDL_PT_light, light=light.data)


class _Layout:
    """Records what a panel's draw asks of its layout (drawing itself needs a window)."""
    def __init__(self):
        self.calls = []

    def template_node_view(self, tree, node, socket):
        self.calls.append(("nodes", tree, node, socket.identifier))

    def label(self, text="", icon="NONE"):
        self.calls.append(("label", text))

    def prop(self, data, name, **kwargs):
        self.calls.append(("prop", name))


def _glass():
    material = bpy.data.materials.new("Glass")
    material.use_nodes = True
    principled = material.node_tree.nodes["Principled BSDF"]
    principled.inputs["IOR"].default_value = 1.45
    spare = material.node_tree.nodes.new("ShaderNodeOutputMaterial")  # not the active one
    spare.is_active_output = False
    output = next(n for n in material.node_tree.nodes if n.bl_idname == "ShaderNodeOutputMaterial" and n != spare)
    output.is_active_output = True
    return material, output


def test_a_blender_material_and_world_show_their_nodes_for_the_engine():
    """A material made in Blender is traced from its nodes: with this engine its Principled inputs are edited in
    the Material tab as with Cycles (Blender's Surface panels list only Blender's engines), likewise the world's
    Background; the panel says when SDL Material is ticked instead."""
    fresh()
    material, output = _glass()
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    assert _polls(ui.SDL_PT_surface, material=material)
    scene.render.engine = "CYCLES"
    assert not _polls(ui.SDL_PT_surface, material=material)  # Cycles draws its own
    scene.render.engine = engine.ENGINE_ID
    layout = _Layout()
    ui.draw_surface(layout, material, material.sdl.use_sdl, ())
    assert layout.calls == [("nodes", material.node_tree, output, "Surface")]
    material.sdl.use_sdl = True
    layout = _Layout()
    ui.draw_surface(layout, material, material.sdl.use_sdl, ())
    assert layout.calls[0][0] == "label" and "not traced" in layout.calls[0][1] and layout.calls[1][0] == "nodes"
    world = bpy.data.worlds.new("Dark")
    world.use_nodes = True
    scene.world = world
    assert _polls(ui.SDL_PT_world_surface, world=world)
    layout = _Layout()
    ui.draw_surface(layout, world, world.sdl.use_sdl, ("color",))
    background_output = next(n for n in world.node_tree.nodes if n.bl_idname == "ShaderNodeOutputWorld")
    assert layout.calls == [("nodes", world.node_tree, background_output, "Surface")]
