"""Panels: the engine's render settings, and the SDL material, light, world and shape of the active data."""
from __future__ import annotations

import bpy

from . import blender_lights, meshes, object_cache, props, scene_build, shader_nodes
from .engine import ENGINE_ID


class _PropertiesPanel:
    """Where the panels live: a tab of the Properties editor (bl_context names the tab)."""
    bl_space_type = "PROPERTIES"
    bl_region_type = "WINDOW"


class SDL_PT_render(_PropertiesPanel, bpy.types.Panel):
    bl_idname = "SDL_PT_render"
    bl_label = "SDL Ray Tracer"
    bl_context = "render"
    COMPAT_ENGINES = {ENGINE_ID}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        settings = context.scene.sdl_render
        col = layout.column()
        col.prop(settings, "block_size")
        col.prop(settings, "progressive")
        if not settings.progressive and settings.block_size > 1:
            col.label(text=f"F12 traces one ray per {settings.block_size} x {settings.block_size} block",
                      icon="ERROR")
        col.prop(settings, "max_recursion_depth")
        col.prop(settings, "threads")
        col = layout.column()
        col.prop(settings, "samples")
        sub = col.column()
        sub.active = settings.samples > 1
        sub.prop(settings, "sampling")
        layout.column().prop(settings, "light_samples")
        layout.column().prop(settings, "target_error")
        # Blender's own switch (Cycles shows it under Performance): keep this engine between final renders,
        # so that F12 after moving a light or editing a material rebuilds only what changed.
        layout.column().prop(context.scene.render, "use_persistent_data")


def draw_surface(layout, owner, sdl_wins: bool, plain: tuple) -> None:
    """The shader nodes the engine traces, as Cycles' Surface panel shows them: the inputs of the node on the
    active output's Surface (template_node_view), or, without nodes (before Blender 5.0), Use Nodes and the
    ``plain`` settings read instead."""
    if sdl_wins:  # (the greyed inputs below stay editable: unticking brings them back)
        layout.label(text="SDL settings are ticked: these nodes are not traced", icon="INFO")
    tree = shader_nodes.node_tree(owner)
    if tree is None:
        layout.prop(owner, "use_nodes", icon="NODETREE")
        for name in plain:
            layout.prop(owner, name)
        return
    output = shader_nodes.active_output(tree)
    if output is None:
        layout.label(text="No output node")
        return
    layout.template_node_view(tree, output, output.inputs["Surface"])


class SDL_PT_surface(_PropertiesPanel, bpy.types.Panel):
    """A material's shader nodes, which the engine traces unless SDL Material is ticked (Blender's own Surface
    panels list only Blender's engines: without this one a material made in Blender could not be edited here)."""
    bl_idname = "SDL_PT_surface"
    bl_label = "Surface"
    bl_context = "material"
    COMPAT_ENGINES = {ENGINE_ID}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and getattr(context, "material", None) is not None

    def draw(self, context):
        material = context.material
        draw_surface(self.layout, material, material.sdl.use_sdl,
                     ("diffuse_color", "metallic", "roughness", "specular_intensity"))


class SDL_PT_world_surface(_PropertiesPanel, bpy.types.Panel):
    """The world's nodes (its background and ambient light unless SDL World is ticked)."""
    bl_idname = "SDL_PT_world_surface"
    bl_label = "Surface"
    bl_context = "world"
    COMPAT_ENGINES = {ENGINE_ID}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and getattr(context, "world", None) is not None

    def draw(self, context):
        world = context.world
        draw_surface(self.layout, world, world.sdl.use_sdl, ("color",))


class SDL_PT_material(_PropertiesPanel, bpy.types.Panel):
    bl_idname = "SDL_PT_material"
    bl_label = "SDL Material"
    bl_context = "material"

    @classmethod
    def poll(cls, context):
        return getattr(context, "material", None) is not None

    def draw_header(self, context):
        self.layout.prop(context.material.sdl, "use_sdl", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.material.sdl
        col = layout.column()
        col.active = s.use_sdl
        for name in ("ambient", "diffuse", "specular", "emissive", "specular_exponent", "reflectivity",
                     "transparency", "speed_of_light", "fresnel", "fresnel_tint", "specular_fraction",
                     "surface_roughness", "texture",
                     "image", "parameter_count"):
            col.prop(s, name)
        if s.parameter_count:
            row = col.row(align=True)
            for i in range(s.parameter_count):
                row.prop(s, "parameters", index=i, text="")


class SDL_PT_light(_PropertiesPanel, bpy.types.Panel):
    """What the engine makes of a light: an imported SDL light keeps SDL's meaning (colour x power / 1000 W,
    no falloff); any other is a physical light in Blender's units, with its extent (soft shadows)."""
    bl_idname = "SDL_PT_light"
    bl_label = "SDL Light"
    bl_context = "data"
    COMPAT_ENGINES = {ENGINE_ID}
    #: Per Blender light type, the settings that shape it for the tracer.
    SHAPE = {"POINT": ("shadow_soft_size",), "SPOT": ("shadow_soft_size", "spot_size", "spot_blend"),
             "SUN": ("angle",), "AREA": ("shape", "size", "size_y")}

    @classmethod
    def poll(cls, context):
        return context.engine in cls.COMPAT_ENGINES and getattr(context, "light", None) is not None

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        light = context.light
        layout.prop(light, "color")
        layout.prop(light, "energy", text="Strength" if light.type == "SUN" else "Power")
        if blender_lights.is_sdl_light(light):
            rgb = props.light_color(light)
            layout.label(text="SDL light colour: " + " ".join(f"{c:g}" for c in rgb), icon="LIGHT")
            return
        for name in self.SHAPE.get(light.type, ()):
            if name == "size_y" and light.shape not in ("RECTANGLE", "ELLIPSE"):
                continue
            layout.prop(light, name, text="Radius" if name == "shadow_soft_size" else None)
        layout.prop(context.scene.sdl_render, "light_samples")


class SDL_PT_world(_PropertiesPanel, bpy.types.Panel):
    bl_idname = "SDL_PT_world"
    bl_label = "SDL World"
    bl_context = "world"

    @classmethod
    def poll(cls, context):
        return context.world is not None

    def draw_header(self, context):
        self.layout.prop(context.world.sdl, "use_sdl", text="")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        s = context.world.sdl
        col = layout.column()
        col.active = s.use_sdl
        for name in ("background", "global_ambient", "min_reflectivity", "min_transparency", "smooth_terminator"):
            col.prop(s, name)



class SDL_PT_object(_PropertiesPanel, bpy.types.Panel):
    bl_idname = "SDL_PT_object"
    bl_label = "SDL Shape"
    bl_context = "object"

    @classmethod
    def poll(cls, context):
        obj = context.object
        return obj is not None and obj.type == "MESH"

    def draw(self, context):
        obj = context.object
        info = meshes.cached_generic_info(obj.data)  # hashes the mesh only after it changed
        layout = self.layout
        if info is None:
            text = "Edited generic shape: traced as a mesh" if "sdl_kind" in obj.data else "Traced as a mesh"
            layout.label(text=text, icon="MESH_DATA")
            return
        label = " ".join([info.kind, *(f"{v:g}" for v in info.parameters)])
        # as the final render decides (scene_build.SceneBuilder.object_node)
        others = [m for m in scene_build.enabled_modifiers(obj) if m.type != "BOOLEAN"]
        if others:
            layout.label(text=f"Generic {label} with modifier {others[0].name}: traced as a mesh", icon="MESH_DATA")
            return
        layout.label(text=f"Generic {label}: traced exactly", icon="SHADING_RENDERED")
        if info.mesh_file:
            layout.label(text=info.mesh_file)
        if "sdl_source" in obj:
            layout.label(text=f"From {obj['sdl_source']}")


CLASSES = (SDL_PT_render, SDL_PT_surface, SDL_PT_material, SDL_PT_light, SDL_PT_world_surface, SDL_PT_world,
           SDL_PT_object)


def _cache_handlers() -> tuple:
    """The handlers that keep the add-on's caches in step with Blender's data (panels' and engine's)."""
    return meshes.HANDLERS + object_cache.HANDLERS


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for name, handler in _cache_handlers():
        getattr(bpy.app.handlers, name).append(handler)


def unregister() -> None:
    for name, handler in _cache_handlers():
        handlers = getattr(bpy.app.handlers, name)
        while handler in handlers:
            handlers.remove(handler)
    meshes.forget_all()
    object_cache.forget_everything()
    for cls in reversed(CLASSES):
        if cls.is_registered:
            bpy.utils.unregister_class(cls)
