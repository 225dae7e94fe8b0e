"""Blender's lights in the tracer's units (docs/tracer.md, "Lights"; docs/blender.md, "Blender lights").

No ``bpy`` here: ``blender_lights`` reads a Blender light and its object's matrix and calls these.  Cycles
shades a diffuse surface of albedo rho as rho / pi times the irradiance, the tracer as rho times the light's
colour, so a light's colour is its irradiance (at distance 1, facing it) over pi:

* a point or spot light of P watts radiates P / (4 pi) per steradian: colour P / (4 pi^2), falling off as
  1 / r^2 (the spot's cone cuts it; its power is that of the whole sphere, as in Blender);
* a sun of strength S (W/m^2): colour S / pi;
* an area light of P watts is a Lambertian emitter on one side: P / pi per steradian along its normal,
  so P / (pi^2 A) per unit of its area A.

Each factor was checked against Cycles (bpy 4.5, a diffuse plane under each kind of light: the traced
radiance over the formula's is 0.999 for point and spot lights, 1.000 for the sun, 0.999 for a 0.1 m area
light; tests/test_addon_cycles.py keeps checking it).
"""
from __future__ import annotations

import math

import numpy as np

POINT_FACTOR = 1.0 / (4.0 * math.pi ** 2)
SUN_FACTOR = 1.0 / math.pi
AREA_FACTOR = 1.0 / math.pi ** 2


def _unit(vector) -> tuple[float, float, float]:
    v = np.asarray(vector, dtype=np.float64)
    length = float(np.linalg.norm(v))
    return tuple(float(c) for c in (v / length if length > 0 else np.array([0.0, 0.0, -1.0])))


def _color(rgb, scale: float) -> tuple[float, float, float]:
    return tuple(float(c) * scale for c in rgb)


def point(matrix: np.ndarray, rgb, watts: float, radius: float, samples: int, name=None) -> dict:
    """A Blender point light (its world matrix, colour, power and radius) as Light fields: a sphere light."""
    return dict(kind="sphere", name=name, position=tuple(float(c) for c in matrix[:3, 3]),
                color=_color(rgb, watts * POINT_FACTOR), radius=max(0.0, float(radius)),
                samples=samples if radius > 0 else 1)


def spot(matrix: np.ndarray, rgb, watts: float, radius: float, size: float, blend: float, samples: int,
         name=None) -> dict:
    """A Blender spot light (``size`` its cone's full angle in radians, ``blend`` 0..1): shining along its
    object's -Z."""
    fields = point(matrix, rgb, watts, radius, samples, name)
    fields.update(kind="spot", direction=_unit(-matrix[:3, 2]), spot_size=min(180.0, math.degrees(size)),
                  spot_blend=min(1.0, max(0.0, float(blend))))
    return fields


def sun(matrix: np.ndarray, rgb, strength: float, angle: float, samples: int, name=None) -> dict:
    """A Blender sun (strength in W/m^2, ``angle`` its angular diameter in radians): light travelling along
    its object's -Z."""
    degrees = min(179.0, max(0.0, math.degrees(angle)))
    return dict(kind="sun", name=name, position=(0.0, 0.0, 0.0), direction=_unit(-matrix[:3, 2]),
                color=_color(rgb, strength * SUN_FACTOR), angle=degrees, samples=samples if degrees > 0 else 1)


def area(matrix: np.ndarray, rgb, watts: float, shape: str, size_x: float, size_y: float, samples: int,
         name=None) -> dict:
    """A Blender area light (``shape`` SQUARE, RECTANGLE, DISK or ELLIPSE; sizes along its local X and Y,
    which the object's scale stretches): emitting along its object's -Z."""
    x_axis, y_axis = matrix[:3, 0], matrix[:3, 1]
    if shape in ("SQUARE", "DISK"):
        size_y = size_x
    width = float(size_x) * float(np.linalg.norm(x_axis))
    height = float(size_y) * float(np.linalg.norm(y_axis))
    ellipse = shape in ("DISK", "ELLIPSE")
    surface = max(width * height * (math.pi / 4.0 if ellipse else 1.0), 1e-12)
    return dict(kind="area", name=name, position=tuple(float(c) for c in matrix[:3, 3]),
                direction=_unit(-matrix[:3, 2]), axis=_unit(x_axis), shape="ellipse" if ellipse else "rectangle",
                size=(max(width, 1e-9), max(height, 1e-9)), color=_color(rgb, watts * AREA_FACTOR / surface),
                samples=samples)


def watts_of_sphere_light(color) -> tuple[tuple[float, float, float], float]:
    """(colour scaled to 1 at most, power in W) of a Blender point light for an SDL sphereLight colour."""
    return _as_blender(color, POINT_FACTOR)


def strength_of_sun(color) -> tuple[tuple[float, float, float], float]:
    """(colour, strength in W/m^2) of a Blender sun for an SDL sunLight colour."""
    return _as_blender(color, SUN_FACTOR)


def watts_of_area_light(color, surface: float) -> tuple[tuple[float, float, float], float]:
    """(colour, power in W) of a Blender area light of ``surface`` square units for an SDL area light colour."""
    return _as_blender(color, AREA_FACTOR / max(surface, 1e-12))


def _as_blender(color, factor: float):
    color = tuple(float(c) for c in color)
    peak = max(color)
    if peak <= 0:
        return (1.0, 1.0, 1.0), 0.0
    return tuple(c / peak for c in color), peak / factor
