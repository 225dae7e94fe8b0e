"""Properties the add-on adds to Blender data, and reading/writing them as tracer values.

* ``Material.sdl``: the SDL material (the exact values live beside it, see convert.recall), kept in step
  with a Principled BSDF and the viewport colour that look close to it.
* ``World.sdl``: background, global ambient light and the reflection/transparency thresholds.
* ``Scene.sdl_render``: the render engine's settings (block size, progressive refinement, recursion
  depth, threads, samples per pixel and sampling mode).
"""
from __future__ import annotations

from array import array
from typing import Optional

import bpy
from bpy.props import (BoolProperty, EnumProperty, FloatProperty, FloatVectorProperty, IntProperty,
                       PointerProperty, StringProperty)

from . import shader_nodes
from .pure import convert
from .tracer.appearance import display_roughness
from .tracer.model import Material, Settings

COLOR_FIELDS = ("ambient", "diffuse", "specular", "emissive", "fresnel_tint")
FLOAT_FIELDS = ("specular_exponent", "reflectivity", "transparency", "speed_of_light", "specular_fraction",
                "surface_roughness")
MAX_PARAMETERS = 10
#: Blender light power (W) standing for an SDL light of colour 1 1 1 (SDL lights do not fade with distance,
#: Blender's do, so this only sets a plausible look for Blender's own engines).
LIGHT_WATTS = 1000.0


#: Materials whose SDL properties are being filled in code (set_material): their update callbacks wait, and
#: the filler syncs the Principled BSDF once at the end.  Each sync sets about eight node inputs, and each
#: such set costs Blender time in proportion to the file's node trees, so a sync per property made an
#: import of n materials take time in n squared.
_filling: set = set()


def _sync_material(self, context) -> None:
    material = self.id_data
    if isinstance(material, bpy.types.Material) and material.as_pointer() not in _filling:
        apply_principled(material)


def _sync_world(self, context) -> None:
    world = self.id_data
    if isinstance(world, bpy.types.World) and world.sdl.use_sdl:
        apply_world_colors(world)


def _color(name: str, default, description: str):
    return FloatVectorProperty(name=name, subtype="COLOR", size=3, default=default, min=0.0, soft_max=1.0,
                               description=description, update=_sync_material)


class SDLMaterialSettings(bpy.types.PropertyGroup):
    use_sdl: BoolProperty(name="SDL Material", default=False, update=_sync_material,
                          description="Use these SDL values when ray tracing (otherwise they are derived "
                                      "from the Principled BSDF)")
    ambient: _color("Ambient", (0.1, 0.1, 0.1), "Reflects the global ambient light")
    diffuse: _color("Diffuse", (0.8, 0.8, 0.8), "Lambertian reflection of the lights")
    specular: _color("Specular", (0.0, 0.0, 0.0), "Phong highlight colour")
    emissive: _color("Emissive", (0.0, 0.0, 0.0), "Light the surface gives off")
    specular_exponent: FloatProperty(name="Specular Exponent", default=1.0, min=0.0, soft_max=500.0,
                                     update=_sync_material)
    reflectivity: FloatProperty(name="Reflectivity", default=0.0, min=0.0, max=1.0, update=_sync_material)
    transparency: FloatProperty(name="Transparency", default=0.0, min=0.0, max=1.0, update=_sync_material)
    speed_of_light: FloatProperty(name="Speed of Light", default=1.0, min=1e-6, soft_max=2.0,
                                  update=_sync_material,
                                  description="Relative speed of light inside the object (1 = air)")
    fresnel: EnumProperty(name="Fresnel", default="constant", update=_sync_material, items=[
        ("constant", "Constant", "Reflected and transmitted rays weighted by Reflectivity and Transparency alone"),
        ("metal", "Metal", "The mirror ray weighted by Schlick's Fresnel from Fresnel Tint (SDL: fresnel metal)"),
        ("dielectric", "Dielectric", "Exact Fresnel of the Speed of Light splits the mirror and refracted rays "
                                     "(SDL: fresnel dielectric)")])
    fresnel_tint: _color("Fresnel Tint", (1.0, 1.0, 1.0), "A metal's reflectance at normal incidence "
                                                          "(SDL: fresnelTint)")
    specular_fraction: FloatProperty(name="Specular Fraction", default=0.0, min=0.0, max=1.0)
    surface_roughness: FloatProperty(name="Surface Roughness", default=1.0, min=0.0)
    texture: IntProperty(name="Texture", default=0,
                         description="Texture number (0 = none; -1, -2, -3 solid textures; above 0 the image)")
    image: StringProperty(name="Image", subtype="FILE_PATH",
                          description="The image of a texture above 0 (what SDL's makePixmap gives the number)")
    parameter_count: IntProperty(name="Parameters", default=0, min=0, max=MAX_PARAMETERS)
    parameters: FloatVectorProperty(name="Texture Parameters", size=MAX_PARAMETERS, default=(0.0,) * MAX_PARAMETERS)


class SDLWorldSettings(bpy.types.PropertyGroup):
    use_sdl: BoolProperty(name="SDL World", default=False,
                          description="Use these SDL values when ray tracing (otherwise the world's colour, or its "
                                      "Background node's colour times strength, is the background and the ambient "
                                      "light, as in Cycles); an imported SDL file's world has it ticked")
    smooth_terminator: BoolProperty(name="Smooth Terminator", default=False,
                                    description="Shadow feelers of smooth-shaded meshes start from the smooth "
                                                "surface their normals describe (SDL smoothTerminator); Blender "
                                                "worlds always have it")
    background: FloatVectorProperty(name="Background", subtype="COLOR", size=3, default=(0.0, 0.0, 0.6),
                                    min=0.0, soft_max=1.0, update=_sync_world,
                                    description="Colour of rays that hit nothing")
    global_ambient: FloatVectorProperty(name="Global Ambient", subtype="COLOR", size=3, default=(0.1, 0.1, 0.1),
                                        min=0.0, soft_max=1.0)
    min_reflectivity: FloatProperty(name="Min Reflectivity", default=0.5, min=0.0, max=1.0,
                                    description="Objects at least this reflective get a reflected ray")
    min_transparency: FloatProperty(name="Min Transparency", default=0.5, min=0.0, max=1.0,
                                    description="Objects at least this transparent get a transmitted ray")


class SDLRenderSettings(bpy.types.PropertyGroup):
    block_size: IntProperty(name="Block Size", default=8, min=1, max=256,
                            description="Trace one ray per block of this many pixels square")
    progressive: BoolProperty(name="Progressive Refinement", default=True,
                              description="Refine coarse to fine: block size, half of it, ..., 1")
    max_recursion_depth: IntProperty(name="Max Recursion Depth", default=3, min=0, max=64,
                                     description="Reflection and refraction bounces (SDL maxRecursionDepth)")
    threads: IntProperty(name="Threads", default=0, min=0, max=1024,
                         description="Threads tracing at once (0: $SDL_TRACER_THREADS, else one per CPU)")
    samples: IntProperty(name="Samples", default=1, min=1, max=1024,
                         description="Rays per pixel (anti-aliasing); 1 traces the pixel centre")
    sampling: EnumProperty(name="Sampling", default="JITTERED", items=[
        ("REGULAR", "Regular", "A grid of sub-pixel centres"),
        ("JITTERED", "Jittered", "One random point in each cell of the grid (repeatable)"),
        ("ADAPTIVE", "Adaptive", "About Samples rays per pixel on average: one through each centre, the rest "
                                 "where an error model says they lower the image's error most")])
    # No longer used (adaptive sampling places its rays by an error model, tracer.adaptive) and not shown:
    # kept so that files and scripts that set it still load and run.
    threshold: FloatProperty(name="Threshold", default=0.05, min=0.0, soft_max=1.0,
                             description="Not used: adaptive sampling places its rays by an error model")
    light_samples: IntProperty(name="Light Samples", default=16, min=1, max=1024,
                               description="Shadow rays per shaded point for each light with an extent (a radius, "
                                           "a sun's angle, an area light): soft shadows")
    target_error: FloatProperty(name="Target Error", default=0.0, min=0.0, soft_max=0.1, precision=4,
                                description="Final renders: sample until the image's estimated RMSE (linear colour) is "
                                            "below this, rays going where they lower it most, and report the "
                                            "estimate; 0 is off")


CLASSES = (SDLMaterialSettings, SDLWorldSettings, SDLRenderSettings)


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    bpy.app.handlers.depsgraph_update_post.append(take_material_edits)
    bpy.types.Material.sdl = PointerProperty(type=SDLMaterialSettings)
    bpy.types.World.sdl = PointerProperty(type=SDLWorldSettings)
    bpy.types.Scene.sdl_render = PointerProperty(type=SDLRenderSettings)


def unregister() -> None:
    while take_material_edits in bpy.app.handlers.depsgraph_update_post:
        bpy.app.handlers.depsgraph_update_post.remove(take_material_edits)
    for owner, name in ((bpy.types.Scene, "sdl_render"), (bpy.types.World, "sdl"), (bpy.types.Material, "sdl")):
        if hasattr(owner, name):
            delattr(owner, name)
    for cls in reversed(CLASSES):
        if cls.is_registered:
            bpy.utils.unregister_class(cls)


# ---------------------------------------------------------------------------------------------------------
# Exact values beside float32 properties

def _shown(group, name: str) -> list[float]:
    value = getattr(group, name)
    return [float(v) for v in value] if hasattr(value, "__len__") else [float(value)]


def store_exact(idblock, group, values: dict) -> None:
    """Remember exact values (name -> float or tuple) for ``group``'s fields, with what Blender shows now."""
    idblock["sdl_exact"] = {k: [float(x) for x in (v if isinstance(v, (tuple, list)) else (v,))]
                            for k, v in values.items()}
    idblock["sdl_shown"] = {k: _shown(group, k) for k in values}


def exact_field(idblock, group, name: str) -> list[float]:
    exact = idblock.get("sdl_exact")
    shown = idblock.get("sdl_shown")
    e = list(exact[name]) if exact is not None and name in exact else None
    s = list(shown[name]) if shown is not None and name in shown else None
    return convert.recall(e, s, _shown(group, name))


# ---------------------------------------------------------------------------------------------------------
# Materials

def _principled(material):
    if shader_nodes.node_tree(material) is None:
        return None
    for node in material.node_tree.nodes:
        if node.type == "BSDF_PRINCIPLED":
            return node
    return None


def _set_input(node, names, value) -> None:
    for name in names:
        socket = node.inputs.get(name)
        if socket is not None:
            # Only a change is set: every set, even of the value already there, makes Blender look through
            # all the node trees in the file, so that importing N materials took time in proportion to N².
            if _as_stored(value) != _as_stored(socket.default_value):
                socket.default_value = value
            return


def _as_stored(value) -> tuple:
    """A socket value (a number or a colour) as the single-precision numbers Blender keeps."""
    try:
        numbers = list(value)
    except TypeError:
        numbers = [value]
    return tuple(array("f", numbers))


def _get_input(node, names, default):
    for name in names:
        socket = node.inputs.get(name)
        if socket is not None and hasattr(socket, "default_value"):
            return socket.default_value
    return default


#: On a material: the colour apply_principled last gave its Principled Base Color (or, without nodes, its
#: viewport colour), to tell a user's edit of that colour from the add-on's own.
BASE_SHOWN = "sdl_base_shown"


def _base_color(material) -> tuple:
    node = _principled(material)
    if node is not None:
        return tuple(float(c) for c in _get_input(node, ("Base Color",), (0.8, 0.8, 0.8, 1.0)))[:3]
    return tuple(float(c) for c in material.diffuse_color)[:3]


def edited_base_color(material):
    """The colour the user sees (Principled Base Color, else the viewport colour) when it was edited since
    the add-on set it from the SDL diffuse colour; None when it was not."""
    shown = material.get(BASE_SHOWN)
    if shown is None:
        return None
    base = _base_color(material)
    return base if max(abs(a - b) for a, b in zip(base, shown)) > 1e-6 else None


def take_base_color_edit(material) -> bool:
    """One colour, whichever way it is edited: a Base Color edited by the user becomes the SDL diffuse
    colour (shown in the SDL Material panel, traced and exported), rather than being ignored, or overwritten
    by the SDL colour when SDL Material is ticked or unticked.  True when there was an edit."""
    base = edited_base_color(material)
    if base is None:
        return False
    material[BASE_SHOWN] = list(base)  # first, so that the update below finds nothing more to take
    material.sdl.diffuse = base
    return True


def principled_inputs(s) -> list[tuple[tuple[str, ...], object]]:
    """The Principled BSDF inputs that show an SDL material ``s`` (``Material.sdl``, or anything with its field
    names), each as (its names in the Blender versions that have it, value): Base Color is the diffuse colour."""
    return [(("Base Color",), (*tuple(s.diffuse), 1.0)),
            (("Emission Color", "Emission"), (*tuple(s.emissive), 1.0)),
            (("Emission Strength",), 1.0),
            (("Roughness",), display_roughness(s)),
            (("Specular IOR Level", "Specular"), min(1.0, sum(s.specular) / 3.0)),
            (("Metallic",), s.reflectivity),
            (("Transmission Weight", "Transmission"), s.transparency),
            (("IOR",), min(100.0, 1.0 / max(s.speed_of_light, 1e-6)))]


class PrincipledWriter:
    """Writes the Principled inputs of new materials that are copies of one material (the importer's), all at
    once with ``inputs.foreach_set``, which, unlike setting a socket's value, does not make Blender look
    through every node tree in the file (see _set_input): importing 10^4 materials took minutes that way.
    Only for materials Blender has not evaluated yet (a copy just made): no update is sent.

    ``values`` is every input of the node as one flat list (each input's value, as many numbers as it has),
    read from the node the writer is made for and kept as written last: the copies have that node's values in
    the inputs it does not write.  None (``of`` returns None) where an input's value is not numbers."""

    def __init__(self, slots: dict[str, tuple[int, int]], values: list[float]):
        self.slots = slots  # input name -> (first number, count)
        self.values = values

    @classmethod
    def of(cls, material) -> "Optional[PrincipledWriter]":
        node = _principled(material)
        if node is None:
            return None
        slots, at = {}, 0
        for socket in node.inputs:
            value = getattr(socket, "default_value", None)
            if isinstance(value, (bool, int, float)):
                count = 1
            else:
                try:
                    count = len(value)
                    if not all(isinstance(v, (bool, int, float)) for v in value):
                        return None
                except TypeError:  # a string, a menu, no value at all
                    return None
            slots.setdefault(socket.name, (at, count))
            at += count
        values = [0.0] * at
        try:
            node.inputs.foreach_get("default_value", values)
        except (TypeError, RuntimeError):
            return None
        return cls(slots, values)

    def write(self, material, inputs) -> bool:
        """Give ``material``'s Principled node these inputs (principled_inputs); False where it cannot (no
        Principled node; the caller then sets them one by one)."""
        node = _principled(material)
        if node is None or len(node.inputs) != len(self.slots):
            return False
        values = self.values
        for names, value in inputs:
            for name in names:
                slot = self.slots.get(name)
                if slot is not None:
                    start, count = slot
                    values[start:start + count] = list(value)[:count] if count > 1 else [float(value)]
                    break
        node.inputs.foreach_set("default_value", values)
        return True


def apply_principled(material, take_edits: bool = True, writer: "Optional[PrincipledWriter]" = None) -> None:
    """Make the Principled BSDF and the viewport colour look like the SDL material (after taking a Base
    Color the user edited into it, unless ``take_edits`` is False: the SDL values were just set in code).
    ``writer``: for a new copy of the material the writer was made for (see PrincipledWriter)."""
    if take_edits:
        take_base_color_edit(material)
    s = material.sdl
    diffuse = tuple(s.diffuse)
    material.diffuse_color = (*[min(c, 1.0) for c in diffuse], 1.0)
    roughness = display_roughness(s)
    material.roughness = roughness
    material.metallic = s.reflectivity
    inputs = principled_inputs(s)
    if writer is None or not writer.write(material, inputs):
        node = _principled(material)
        for names, value in inputs:
            if node is not None:
                _set_input(node, names, value)
    material[BASE_SHOWN] = list(_base_color(material))


def set_material(material, sdl_material, before=None, writer: "Optional[PrincipledWriter]" = None) -> None:
    """Fill ``material.sdl`` from a tracer Material, keeping the exact values (the Principled BSDF synced
    once, not once a property).  ``before``: the tracer Material ``material`` already holds (it is a copy of
    the one made from it): only the fields that differ are set."""
    key = material.as_pointer()
    _filling.add(key)
    try:
        _fill_sdl(material, sdl_material, before)
    finally:
        _filling.discard(key)
    # (the diffuse just set wins over an older Base Color edit)
    apply_principled(material, take_edits=False, writer=writer)


def _fill_sdl(material, sdl_material, before=None) -> None:
    s = material.sdl
    params = tuple(sdl_material.parameters)[:MAX_PARAMETERS]
    padded = params + (0.0,) * (MAX_PARAMETERS - len(params))
    values = {name: getattr(sdl_material, name) for name in COLOR_FIELDS + FLOAT_FIELDS}
    values["parameters"] = padded
    if before is not None and material.get("sdl_exact") is not None and material.get("sdl_shown") is not None:
        old = {name: getattr(before, name) for name in COLOR_FIELDS + FLOAT_FIELDS}
        old_params = tuple(before.parameters)[:MAX_PARAMETERS]
        old["parameters"] = old_params + (0.0,) * (MAX_PARAMETERS - len(old_params))
        changed = [name for name in values if values[name] != old[name]]
        for name in changed:
            setattr(s, name, values[name])
        if sdl_material.texture != before.texture:
            s.texture = int(sdl_material.texture)
        if sdl_material.fresnel != before.fresnel:
            s.fresnel = sdl_material.fresnel
        if len(params) != len(old_params):
            s.parameter_count = len(params)
        exact, shown = material["sdl_exact"], material["sdl_shown"]
        for name in changed:
            value = values[name]
            exact[name] = [float(x) for x in (value if isinstance(value, (tuple, list)) else (value,))]
            shown[name] = _shown(s, name)
        return
    for name in COLOR_FIELDS + FLOAT_FIELDS:
        setattr(s, name, values[name])
    s.texture = int(sdl_material.texture)
    s.fresnel = sdl_material.fresnel
    s.parameter_count = len(params)
    s.parameters = padded
    s.use_sdl = True
    store_exact(material, s, values)


def material_to_sdl(material, warnings: Optional[list] = None):
    """The tracer Material for a Blender material (None: SDL's default material): its SDL values where SDL
    Material is ticked, else what its shader nodes make of it (blender_material; a picture on it is left
    out here)."""
    if material is None:
        return Material()
    s = material.sdl
    if s.use_sdl:
        values = {name: tuple(exact_field(material, s, name)) for name in COLOR_FIELDS}
        edited = edited_base_color(material)  # (the handler below takes it in too, where there is a UI)
        if edited is not None:
            values["diffuse"] = tuple(convert.shortest32(c) for c in edited)
        values.update({name: exact_field(material, s, name)[0] for name in FLOAT_FIELDS})
        params = exact_field(material, s, "parameters")[: s.parameter_count]
        return Material(texture=int(s.texture), parameters=tuple(params), fresnel=s.fresnel, **values)
    return blender_material(material, warnings)[0]


def blender_material(material, warnings: Optional[list] = None):
    """(tracer Material, shader_nodes.Picture or None) of a material traced by its shader nodes, by the rules
    of addon/pure/whitted.py; the picture is an Image Texture's on its Base Color, which the caller numbers
    (the Material's texture is 0 here)."""
    fields = shader_nodes.material_fields(material, warnings)
    image = fields.pop("image")
    fields = {name: tuple(convert.shortest32(c) for c in value) if isinstance(value, tuple) else
              (convert.shortest32(value) if isinstance(value, float) else value) for name, value in fields.items()}
    return Material(**fields), image


@bpy.app.handlers.persistent
def take_material_edits(scene, depsgraph) -> None:
    """depsgraph_update_post: a Base Color the user edited shows in the SDL Material panel at once.  Only the
    materials the update names (an edit of a material's nodes names the material too): with 10^5 materials
    in the file, looking at every one took a tenth of a second after each edit; and reading the updates looks
    through every datablock of the depsgraph, so only when Blender says a material was updated)."""
    if not depsgraph.id_type_updated("MATERIAL"):
        return
    for update in depsgraph.updates:
        if isinstance(update.id, bpy.types.Material):
            material = update.id.original
            if material.library is None and BASE_SHOWN in material and material.sdl.use_sdl:
                take_base_color_edit(material)


# ---------------------------------------------------------------------------------------------------------
# World

WORLD_FIELDS = ("background", "global_ambient", "min_reflectivity", "min_transparency")
#: A Blender world's minReflectivity and minTransparency: every mirror and glass gets its rays (what is too
#: faint to matter is left to the tracer's contribution cutoff).
BLENDER_MIN_WEIGHT = 1e-3


def apply_world_colors(world) -> None:
    background = tuple(world.sdl.background)
    world.color = background
    if shader_nodes.node_tree(world) is not None:
        for node in world.node_tree.nodes:
            if node.type == "BACKGROUND":
                node.inputs["Color"].default_value = (*background, 1.0)
                node.inputs["Strength"].default_value = 1.0


def set_world(world, settings) -> None:
    s = world.sdl
    s.use_sdl = True
    s.smooth_terminator = bool(settings.smooth_terminator)
    s.background = settings.background
    s.global_ambient = settings.global_ambient
    s.min_reflectivity = settings.min_reflectivity
    s.min_transparency = settings.min_transparency
    store_exact(world, s, {name: getattr(settings, name) for name in WORLD_FIELDS})
    apply_world_colors(world)


def world_settings(world, max_recursion_depth: int, warnings: Optional[list] = None):
    """Tracer Settings from a world and the render settings' recursion depth: an SDL world's values, or a
    Blender world's (none: black) as Cycles uses it, its colour the background and the ambient light."""
    if world is None or not world.sdl.use_sdl:
        color = shader_nodes.world_color(world, warnings) if world is not None else (0.0, 0.0, 0.0)
        return Settings(global_ambient=color, background=color, min_reflectivity=BLENDER_MIN_WEIGHT,
                        min_transparency=BLENDER_MIN_WEIGHT, max_recursion_depth=int(max_recursion_depth),
                        smooth_terminator=True)
    s = world.sdl
    return Settings(global_ambient=tuple(exact_field(world, s, "global_ambient")),
                    background=tuple(exact_field(world, s, "background")),
                    min_reflectivity=exact_field(world, s, "min_reflectivity")[0],
                    min_transparency=exact_field(world, s, "min_transparency")[0],
                    max_recursion_depth=int(max_recursion_depth), smooth_terminator=bool(s.smooth_terminator))


# ---------------------------------------------------------------------------------------------------------
# Lights

def _light_shown(light) -> list[float]:
    return [float(c) for c in light.color] + [float(light.energy)]


def set_light(light, color) -> None:
    """A Blender point light for an SDL light colour: colour scaled to 1 at most, power for the rest."""
    color = tuple(float(c) for c in color)
    peak = max(color)
    light.color = tuple(c / peak for c in color) if peak > 0 else (1.0, 1.0, 1.0)
    light.energy = peak * LIGHT_WATTS
    light.shadow_soft_size = 0.0
    light["sdl_color"] = list(color)
    light["sdl_shown"] = _light_shown(light)


def light_color(light) -> tuple[float, float, float]:
    exact, shown = light.get("sdl_color"), light.get("sdl_shown")
    now = _light_shown(light)
    if exact is not None and shown is not None and list(shown) == now:
        return tuple(float(c) for c in exact)
    # A sun's strength is already an irradiance, not a power: strength 1 is an SDL light of colour 1 1 1.
    watts = 1.0 if light.type == "SUN" else LIGHT_WATTS
    return tuple(convert.shortest32(c * light.energy / watts) for c in light.color)
