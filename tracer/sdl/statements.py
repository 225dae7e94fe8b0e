"""Every SDL statement, once: what both readers and the messages know about it.

Each :class:`Statement` names its keyword, the arguments it takes (the usage text of messages: "expected
'translate dx dy dz'"), the Python reader's method that reads it (tracer/sdl/parser.py, the reference), and
the C reader's action, if it reads it (tracer/native/sdl_read.h: the function that does, with an argument and
how many numbers follow the keyword; no action: the C reader declines a text at that keyword and the Python
reader reads it).  ``python -m tracer.native.contract`` generates the C reader's table of actions
(``RT_SDL_ACTIONS`` in contract.h) from :data:`ACTIONS`; tracer/sdl/fastread.py hands it the vocabulary
(:func:`vocabulary`).  Shape statements come from the shape registry (tracer/shapes.py), one ``shape``
action for all, with each kind's count of parameters.

This module imports nothing of the readers, so the contract generator can read it.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

from .. import shapes
from ..model import CSG, MaterialRows
from .lights import LIGHT_USAGE

#: Material keywords taking r g b, and the Material field each sets.
COLOR_MATERIAL = {"ambient": "ambient", "diffuse": "diffuse", "specular": "specular", "emissive": "emissive"}
#: Material keywords taking one number, and the Material field each sets.
FLOAT_MATERIAL = {"specularExponent": "specular_exponent", "reflectivity": "reflectivity",
                  "transparency": "transparency", "speedOfLight": "speed_of_light",
                  "specularFraction": "specular_fraction", "surfaceRoughness": "surface_roughness"}
#: The most numbers ``parameters`` may give (as in the book's material record).
MAX_PARAMETERS = 10


@dataclass(frozen=True)
class Statement:
    keyword: str
    #: The arguments, as messages show them.
    usage: str
    #: The Python reader's method (parser._Reader) that reads it.
    handler: str
    #: The C reader's function that reads it (sdl_read.h), or None: the C reader declines it.
    action: Optional[str] = None
    #: What the action is given: a material field's slot in a MaterialRows row, a shape's kind code.
    argument: int = 0
    #: How many numbers the action reads after the keyword when the statement says (a shape's parameters).
    count: int = 0
    #: Not the book's SDL (docs/sdl.md): the bundled scenes need not use it.
    extension: bool = False


def _settings() -> list[Statement]:
    S = Statement
    return [S("light", "x y z r g b", "_light", "sdl_light"),
            S("globalAmbient", "r g b", "_global_ambient", "sdl_global_ambient"),
            S("background", "r g b", "_background", "sdl_background"),
            S("minReflectivity", "f", "_min_reflectivity", "sdl_min_reflectivity"),
            S("minTransparency", "f", "_min_transparency", "sdl_min_transparency"),
            S("maxRecursionDepth", "n", "_max_recursion_depth", "sdl_max_recursion_depth"),
            S("makePixmap", "i file", "_make_pixmap"),
            S("camera", "ex ey ez lx ly lz ux uy uz viewAngle", "_camera", "sdl_camera")]


def _materials() -> list[Statement]:
    S = Statement
    return ([S(k, "r g b", "_color_material", "sdl_color_material", MaterialRows.SLOTS[f][0])
             for k, f in COLOR_MATERIAL.items()]
            + [S(k, "f", "_float_material", "sdl_float_material", MaterialRows.SLOTS[f][0])
               for k, f in FLOAT_MATERIAL.items()]
            + [S("texture", "t", "_texture", "sdl_texture"),
               S("parameters", "n p1 ... pn", "_parameters", "sdl_parameters"),
               S("defaultMaterials", "", "_default_materials", "sdl_default_materials")])


def _transforms() -> list[Statement]:
    S = Statement
    return [S("translate", "dx dy dz", "_translate", "sdl_translate"),
            S("scale", "sx sy sz", "_scale", "sdl_scale"),
            S("rotate", "angle ux uy uz", "_rotate", "sdl_rotate"),
            S("push", "", "_push", "sdl_push"), S("pop", "", "_pop", "sdl_pop"),
            S("identityAffine", "", "_identity", "sdl_identity")]


def _objects() -> list[Statement]:
    """The shapes of the registry (a mesh's file is left to the Python reader), booleans, macros."""
    S = Statement
    return ([S(e.keyword, e.usage, "_shape", None if e.file_argument else "sdl_shape", code, len(e.parameters),
               e.extension) for code, e in enumerate(shapes.REGISTRY)]
            + [S(op, "object object", "_boolean") for op in CSG.OPS]
            + [S("def", "name { tokens }", "_def"), S("use", "name", "_use")])


def _extensions() -> list[Statement]:
    """Statements for Blender scenes (docs/sdl.md)."""
    S = Statement
    return ([S(k, usage, "_physical_light", extension=True) for k, usage in LIGHT_USAGE.items()]
            + [S("fresnel", "constant|metal|dielectric", "_fresnel", extension=True),
               S("fresnelTint", "r g b", "_fresnel_tint", extension=True),
               S("smoothTerminator", "0|1", "_smooth_terminator", extension=True)])


#: Every statement.
STATEMENTS: tuple[Statement, ...] = (*_settings(), *_materials(), *_transforms(), *_objects(), *_extensions())
#: Keyword -> statement.
BY_KEYWORD: dict[str, Statement] = {s.keyword: s for s in STATEMENTS}
#: The C reader's actions in code order (the code of an action is its index).
ACTIONS: tuple[str, ...] = tuple(dict.fromkeys(s.action for s in STATEMENTS if s.action))

assert len(BY_KEYWORD) == len(STATEMENTS), "two statements share a keyword"


def vocabulary() -> dict[str, tuple[int, int, int]]:
    """Each keyword the C reader reads: (its action's code, argument, count)."""
    code = {action: k for k, action in enumerate(ACTIONS)}
    return {s.keyword: (code[s.action], s.argument, s.count) for s in STATEMENTS if s.action}


#: The keywords the C reader declines (the Python reader reads the text).
DECLINED = frozenset(s.keyword for s in STATEMENTS if not s.action)
