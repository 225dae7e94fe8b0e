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
