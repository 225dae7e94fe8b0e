"""Blender's lights as tracer lights.

* A light the importer made from SDL's ``light`` statement (its data keeps ``sdl_color``) stays an SDL point
  light: no falloff, its exact colour and position while Blender still shows the values the import gave it
  (after an edit, colour x power / 1000 W), so SDL files keep SDL's meaning through import and export.
* Every other light is a physical light in Blender's units (addon/pure/light_units.py): a point light a
  sphere light of its radius, a spot light, a sun, an area light; those with an extent cast soft shadows
  with the scene's Light Samples shadow rays.
* Every light keeps its object's name (Light.name), which SDL export writes and import gives back.
* Every light keeps what Cycles lets a user switch off per light (``switches``): its data's Cast Shadow and its
  object's Ray Visibility for Diffuse, Glossy and Transmission (Light.cast_shadow, visible_*).  SDL and USD
  do not carry them (an export writes the light as if they were on, with a warning).
"""
from __future__ import annotations

import dataclasses
import math
from typing import Optional

import numpy as np

from . import props
from .pure import light_units
from .tracer.model import Light

#: An SDL point light made from a Blender sun (an imported light whose type was changed to Sun) is put this
#: far from the scene's origin, against its direction.
SUN_DISTANCE = 1.0e6


def is_sdl_light(data) -> bool:
    """Whether the light came from SDL's ``light`` statement (and so keeps SDL's meaning)."""
    return data.get("sdl_color") is not None


def switches(obj_eval) -> dict:
    """The Light switches of a light object, as Cycles reads them: its data's Cast Shadow (``use_shadow``),
    its object's Ray Visibility (``visible_diffuse``, ``visible_glossy``, ``visible_transmission``: Blender
    3.0+); on where Blender lacks one."""
    return dict(cast_shadow=bool(getattr(obj_eval.data, "use_shadow", True)),
                visible_diffuse=bool(getattr(obj_eval, "visible_diffuse", True)),
                visible_glossy=bool(getattr(obj_eval, "visible_glossy", True)),
                visible_transmission=bool(getattr(obj_eval, "visible_transmission", True)))


def tracer_light(obj_eval, matrix_world: np.ndarray, to_target: np.ndarray, samples: int,
                 warnings: Optional[list] = None) -> Light:
    """The tracer Light of a light object at ``matrix_world`` (Blender's axes), in the frame ``to_target``
    maps Blender's world to, with its switches."""
    return dataclasses.replace(_light(obj_eval, matrix_world, to_target, samples, warnings), **switches(obj_eval))


def _light(obj_eval, matrix_world: np.ndarray, to_target: np.ndarray, samples: int,
           warnings: Optional[list] = None) -> Light:
    data = obj_eval.data
    name = obj_eval.original.name
    if is_sdl_light(data):
        return _sdl_light(obj_eval, matrix_world, to_target, name)
    matrix = to_target @ matrix_world
    rgb, power = tuple(float(c) for c in data.color), float(data.energy)
    kind = data.type
    if kind == "SUN":
        return Light(**light_units.sun(matrix, rgb, power, float(getattr(data, "angle", 0.0)), samples, name))
    if kind == "AREA":
        spread = getattr(data, "spread", math.pi)
        if warnings is not None and spread < math.pi - 1e-6:
            warnings.append(f"{name}: an area light's Spread is traced as 180 degrees")
        return Light(**light_units.area(matrix, rgb, power, data.shape, float(data.size), float(data.size_y),
                                        samples, name))
    radius = float(getattr(data, "shadow_soft_size", 0.0))
    if kind == "SPOT":
        return Light(**light_units.spot(matrix, rgb, power, radius, float(data.spot_size), float(data.spot_blend),
                                        samples, name))
    return Light(**light_units.point(matrix, rgb, power, radius, samples, name))


def _sdl_light(obj_eval, matrix_world: np.ndarray, to_target: np.ndarray, name: str) -> Light:
    position = matrix_world[:3, 3].copy()
    original = obj_eval.original
    exact, shown = original.get("sdl_position"), original.get("sdl_position_shown")
    if exact is not None and shown is not None and [float(v) for v in position] == list(shown):
        position = np.array(list(exact), dtype=np.float64)
    if obj_eval.data.type == "SUN":
        direction = -matrix_world[:3, 2]
        direction /= max(np.linalg.norm(direction), 1e-300)
        position = -SUN_DISTANCE * direction
    position = (to_target @ np.append(position, 1.0))[:3]
    return Light(tuple(float(v) for v in position), props.light_color(obj_eval.data), name=name)
