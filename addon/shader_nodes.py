"""A Blender material's shader nodes read as whitted.Surface / Mix / Add values (the rules are whitted's).

What is read: the active Material Output's Surface, through reroutes, as far as Principled, Diffuse, Glossy
(and 3.x's Anisotropic), Glass, Refraction, Emission and Transparent BSDFs, Mix and Add Shaders.  An input
is its own value, or the value of an RGB or Value node plugged into it; an Image Texture node on a Base
Color (or a BSDF's Color) is the picture, looked up through the mesh's UV map.  Anything else plugged into
an input, and any other shader node, is read as its own value (or black), with a warning naming it.

Blender 3.x and 4.x/5.0 name the Principled BSDF's inputs differently: 3.x has Transmission, Specular (the
dielectric reflectance is 0.08 x Specular) and Emission (the colour); 4.x/5.0 have Transmission Weight,
Specular IOR Level (the reflectance of the IOR, times 2 x the level) and Emission Color.
"""
from __future__ import annotations

from typing import NamedTuple, Optional

import bpy

from .pure import whitted

#: Node types followed from the Material Output (bl_idname).
PRINCIPLED, DIFFUSE, GLOSSY, ANISOTROPIC, GLASS, REFRACTION, EMISSION, TRANSPARENT, MIX, ADD = (
    "ShaderNodeBsdfPrincipled", "ShaderNodeBsdfDiffuse", "ShaderNodeBsdfGlossy", "ShaderNodeBsdfAnisotropic",
    "ShaderNodeBsdfGlass", "ShaderNodeBsdfRefraction", "ShaderNodeEmission", "ShaderNodeBsdfTransparent",
    "ShaderNodeMixShader", "ShaderNodeAddShader")
class Picture(NamedTuple):
    """An Image Texture's picture: its file, and whether its values are sRGB (Cycles makes them linear)."""

    path: str
    srgb: bool


#: How deep a shader tree is followed (a Mix of Mixes...); deeper parts are black.
MAX_DEPTH = 32


class Reader:
    """Reads one material's (or world's) nodes; ``warnings`` collects what it could not read (each once)."""

    def __init__(self, owner):
        self.owner = owner
        self.warnings: list[str] = []

    def _warn(self, text: str) -> None:
        message = f"{self.owner.name}: {text}"
        if message not in self.warnings:
            self.warnings.append(message)

    # -- inputs ---------------------------------------------------------------------------------------

    def _linked_node(self, socket):
        """The node plugged into ``socket`` (through reroutes), or None."""
        seen = 0
        while socket is not None and socket.is_linked and seen < MAX_DEPTH:
            link = socket.links[0]
            if not link.is_valid or getattr(link, "is_muted", False):
                return None
            node = link.from_node
            if node.bl_idname != "NodeReroute":
                return node, link.from_socket
            socket = node.inputs[0] if node.inputs else None
            seen += 1
        return None

    def value(self, node, names, default):
        """The first input of ``node`` named in ``names``: a number, or an (r, g, b) colour."""
        socket = next((node.inputs[name] for name in names if name in node.inputs), None)
        if socket is None:
            return default
        linked = self._linked_node(socket)
        if linked is not None:
            source, output = linked
            if source.bl_idname in ("ShaderNodeRGB", "ShaderNodeValue"):
                return _plain(output.default_value)
            self._warn(f"{node.name}'s {socket.name} comes from {source.name}, which the SDL Ray Tracer does not "
                       "evaluate: its own value is used")
        return _plain(socket.default_value) if hasattr(socket, "default_value") else default

    def color(self, node, names, default=(0.8, 0.8, 0.8)):
        """(colour, Picture or None): an Image Texture node plugged into the input gives its picture, the
        colour then being white (the picture is the colour)."""
        socket = next((node.inputs[name] for name in names if name in node.inputs), None)
        linked = self._linked_node(socket) if socket is not None else None
        if linked is not None and linked[0].bl_idname == "ShaderNodeTexImage" and linked[1].name == "Color":
            path = self._picture(linked[0])
            if path is not None:
                return (1.0, 1.0, 1.0), path
        value = self.value(node, names, default)
        return tuple(float(c) for c in (tuple(value) + (0.0, 0.0, 0.0))[:3]), None

    def _picture(self, node) -> Optional["Picture"]:
        image = node.image
        if image is None:
            return None
        if image.source != "FILE" or image.packed_file is not None or not image.filepath:
            self._warn(f"{node.name}: only pictures in files are traced ({image.name} is "
                       f"{'packed' if image.packed_file is not None else image.source.lower()})")
            return None
        vector = self._linked_node(node.inputs["Vector"]) if "Vector" in node.inputs else None
        if vector is not None and not (vector[0].bl_idname == "ShaderNodeUVMap" or
                                       (vector[0].bl_idname == "ShaderNodeTexCoord" and vector[1].name == "UV")):
            self._warn(f"{node.name}: looked up through the UV map, not {vector[0].name}")
        srgb = image.colorspace_settings.name.lower() in ("srgb", "srgb display")  # (values that Cycles linearises)
        return Picture(bpy.path.abspath(image.filepath, library=image.library), srgb and not image.is_float)

    # -- shaders --------------------------------------------------------------------------------------

    def surface(self) -> whitted.Shader:
        """The shader tree on the active Material Output's Surface (None: nothing connected)."""
        output = active_output(self.owner.node_tree)
        if output is None:
            return None
        linked = self._linked_node(output.inputs["Surface"])
        return self.shader(linked[0], 0) if linked is not None else None

    def shader(self, node, depth: int) -> whitted.Shader:
        kind = node.bl_idname
        if depth > MAX_DEPTH:
            return None
        if kind in (MIX, ADD):
            sides = [self._linked_node(s) for s in node.inputs if s.type == "SHADER"]
            first, second = (self.shader(s[0], depth + 1) if s is not None else None for s in sides[:2])
            if kind == ADD:
                return whitted.Add(first, second)
            return whitted.Mix(float(self.value(node, ("Fac", "Factor"), 0.5)), first, second)
        reader = getattr(self, "_" + _READERS.get(kind, "unknown"))
        return reader(node)

    def _principled(self, node) -> whitted.Surface:
        base, image = self.color(node, ("Base Color",))
        ior = float(self.value(node, ("IOR",), 1.5))
        if "Specular IOR Level" in node.inputs:  # 4.x/5.0: the IOR's own reflectance at level 0.5
            f0 = whitted.dielectric_f0(ior) * 2.0 * float(self.value(node, ("Specular IOR Level",), 0.5))
        else:  # 3.x: 0.08 x Specular, whatever the IOR (which there only refracts)
            f0 = 0.08 * float(self.value(node, ("Specular",), 0.5))
        emission, _ = self.color(node, ("Emission Color", "Emission"), (0.0, 0.0, 0.0))
        strength = float(self.value(node, ("Emission Strength",), 1.0))
        return whitted.Surface(
            base_color=base, image=image, metallic=float(self.value(node, ("Metallic",), 0.0)),
            transmission=float(self.value(node, ("Transmission Weight", "Transmission"), 0.0)),
            roughness=float(self.value(node, ("Roughness",), 0.5)), ior=ior, specular_f0=f0,
            emission=tuple(c * strength for c in emission), alpha=float(self.value(node, ("Alpha",), 1.0)))

    def _diffuse(self, node) -> whitted.Surface:
        base, image = self.color(node, ("Color",))
        return whitted.Surface(base_color=base, image=image, roughness=1.0, specular_f0=0.0)

    def _glossy(self, node) -> whitted.Surface:
        base, _ = self.color(node, ("Color",))
        sharp = getattr(node, "distribution", "") == "SHARP"  # (3.x)
        roughness = 0.0 if sharp else float(self.value(node, ("Roughness",), 0.5))
        return whitted.Surface(base_color=base, metallic=1.0, roughness=roughness)

    def _glass(self, node) -> whitted.Surface:
        ior = float(self.value(node, ("IOR",), 1.45))
        sharp = getattr(node, "distribution", "") == "SHARP"
        roughness = 0.0 if sharp else float(self.value(node, ("Roughness",), 0.0))
        base, _ = self.color(node, ("Color",), (1.0, 1.0, 1.0))
        if max(base) < 0.999 or min(base) < 0.999:
            self._warn(f"{node.name}: the glass's colour is not traced (the tracer's glass is clear)")
        return whitted.Surface(base_color=base, transmission=1.0, roughness=roughness, ior=ior,
                               specular_f0=whitted.dielectric_f0(ior))

    def _emission(self, node) -> whitted.Surface:
        color, _ = self.color(node, ("Color",), (1.0, 1.0, 1.0))
        strength = float(self.value(node, ("Strength",), 1.0))
        return whitted.Surface(base_color=(0.0, 0.0, 0.0), roughness=1.0, specular_f0=0.0,
                               emission=tuple(c * strength for c in color))

    def _transparent(self, node) -> whitted.Surface:
        return whitted.Surface(base_color=(0.0, 0.0, 0.0), specular_f0=0.0, alpha=0.0)

    def _unknown(self, node) -> None:
        self._warn(f"{node.name} is a shader the SDL Ray Tracer does not trace: black")
        return None


_READERS = {PRINCIPLED: "principled", DIFFUSE: "diffuse", GLOSSY: "glossy", ANISOTROPIC: "glossy",
            GLASS: "glass", REFRACTION: "glass", EMISSION: "emission", TRANSPARENT: "transparent"}


def _plain(value):
    """A socket value as a float or a tuple of floats."""
    try:
        return tuple(float(v) for v in value)
    except TypeError:
        return float(value)


#: Blender 5.0 gives every material and world nodes, and warns that use_nodes goes in 6.0: read without it.
NODES_ALWAYS = bpy.app.version >= (5, 0)


def node_tree(owner):
    """The node tree a material or world is traced from (None: it uses no nodes)."""
    if NODES_ALWAYS or owner.use_nodes:
        return owner.node_tree
    return None


def use_nodes(owner) -> None:
    """Give a material or world its nodes (Blender 5.0: they always have them)."""
    if not NODES_ALWAYS:
        owner.use_nodes = True


def active_output(tree):
    """The output node a material's or world's node tree is traced from (None: it has none): Cycles' choice,
    the active Material (World) Output among those for all engines or for Cycles."""
    kinds = ("ShaderNodeOutputMaterial", "ShaderNodeOutputWorld")
    outputs = [n for n in tree.nodes if n.bl_idname in kinds]
    usable = [n for n in outputs if getattr(n, "target", "ALL") in ("ALL", "CYCLES")] or outputs
    return next((n for n in usable if n.is_active_output), usable[0] if usable else None)


def material_shader(material, warnings: Optional[list] = None) -> whitted.Shader:
    """The shader tree of a Blender material (its nodes; without nodes, its viewport colour, metallic,
    roughness and specular as a Principled BSDF's).  Problems are appended to ``warnings``."""
    if node_tree(material) is not None:
        reader = Reader(material)
        shader = reader.surface()
        if warnings is not None:
            warnings.extend(reader.warnings)
        return shader
    return whitted.Surface(base_color=tuple(material.diffuse_color)[:3], metallic=float(material.metallic),
                           roughness=float(material.roughness),
                           specular_f0=0.08 * float(getattr(material, "specular_intensity", 0.5)))


def material_fields(material, warnings: Optional[list] = None) -> dict:
    """whitted.whitted of the material's shader: the tracer Material's fields, and ``image``."""
    return whitted.whitted(material_shader(material, warnings))


def world_color(world, warnings: Optional[list] = None) -> tuple[float, float, float]:
    """A Blender world's colour as Cycles lights with it: its Background node's Color x Strength (the one
    plugged into the active World Output), else the world's viewport colour."""
    if node_tree(world) is not None:
        reader = Reader(world)
        output = active_output(world.node_tree)
        linked = reader._linked_node(output.inputs["Surface"]) if output is not None else None
        color = (0.0, 0.0, 0.0)
        if linked is not None and linked[0].bl_idname == "ShaderNodeBackground":
            node = linked[0]
            rgb, _ = reader.color(node, ("Color",), (0.05, 0.05, 0.05))
            color = tuple(c * float(reader.value(node, ("Strength",), 1.0)) for c in rgb)
        elif linked is not None:
            reader._warn(f"{linked[0].name} on the World Output is not traced: a black world")
        if warnings is not None:
            warnings.extend(reader.warnings)
        return color
    return tuple(float(c) for c in world.color)
