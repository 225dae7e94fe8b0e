"""Lights as UsdLux prims and back (docs/usd.md): SDL's point light as a SphereLight of radius 0, a sphere
light as a SphereLight, a spot as a SphereLight with the ShapingAPI cone, a sun as a DistantLight, an area
light as a RectLight (rectangle) or a DiskLight scaled into its ellipse.  Every Light field is also kept
exactly under ``sdl:`` attributes, used where the prim still agrees with them (a light moved, turned or
resized in another tool follows the edit).  A light's name is ``sdl:name`` and the prim's name."""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..model import Light
from ..sdl.lights import light_problem
from ..numerics import norm3
from . import common as C

A_KIND = "sdl:kind"
A_NAME = "sdl:name"
A_DIRECTION = "sdl:direction"
A_AXIS = "sdl:axis"
A_SIZE = "sdl:size"  # double2
A_RADIUS = "sdl:radius"
A_ANGLE = "sdl:angle"
A_SPOT_SIZE = "sdl:spotSize"
A_SPOT_BLEND = "sdl:spotBlend"
A_SAMPLES = "sdl:samples"  # int

#: USD's light schema of each kind (an area light's by its shape).
SCHEMA = {"point": "SphereLight", "sphere": "SphereLight", "spot": "SphereLight", "sun": "DistantLight",
          "rectangle": "RectLight", "ellipse": "DiskLight"}
#: The light prims this module reads.
READ_TYPES = ("SphereLight", "DistantLight", "RectLight", "DiskLight")


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=np.float64)
    return v / norm3(v)


def light_matrix(light: Light) -> np.ndarray:
    """The light's transform (ours, column vectors): UsdLux lights shine down their local -z; a rect or disk
    light lies in its local xy plane, its x along the light's axis (a disk is scaled into the ellipse)."""
    m = np.eye(4)
    m[:3, 3] = light.position
    if light.kind in ("point", "sphere"):
        return m
    shine = _unit(light.direction)
    axis = np.asarray(light.axis, dtype=np.float64) if light.kind == "area" else _any_across(shine)
    x = _unit(axis - (axis @ shine) * shine)
    y = np.cross(-shine, x)  # (x, y, -shine) right-handed
    m[:3, 0], m[:3, 1], m[:3, 2] = x, y, -shine
    if light.kind == "area" and light.shape == "ellipse":  # a disk of radius 1/2 scaled to the diameters
        m[:3, 0] *= light.size[0]
        m[:3, 1] *= light.size[1]
    return m


def _any_across(v: np.ndarray) -> np.ndarray:
    """A vector not along ``v`` (for the frame of a light that has no axis of its own)."""
    return np.array([1.0, 0.0, 0.0]) if abs(v[0]) < 0.9 else np.array([0.0, 1.0, 0.0])


def light_schema(writer, light: Light):
    """The UsdLux schema of a light's prim, and the API schemas it has (for writer._define_all)."""
    lux_type = getattr(writer.UsdLux, SCHEMA[light.shape if light.kind == "area" else light.kind])
    api = writer.Sdf.TokenListOp.Create(prependedItems=["ShapingAPI"]) if light.kind == "spot" else None
    return lux_type, api


def write_light(writer, light: Light, path: str) -> None:
    """Define the light's prim at ``path`` (``writer``: the USD writer, with its pxr modules and helpers)."""
    lux = light_schema(writer, light)[0].Define(writer.stage, path)
    prim = lux.GetPrim()
    lux.CreateColorAttr(writer.Gf.Vec3f(*map(float, light.color)))
    lux.CreateIntensityAttr(1.0)
    if light.kind in ("point", "sphere", "spot"):
        lux.CreateRadiusAttr(float(light.radius))
        lux.CreateTreatAsPointAttr(light.radius == 0.0)
    if light.kind == "spot":
        shaping = writer.UsdLux.ShapingAPI.Apply(prim)
        shaping.CreateShapingConeAngleAttr(float(light.spot_size) / 2.0)  # (USD's is the half-angle)
        shaping.CreateShapingConeSoftnessAttr(float(light.spot_blend))
    elif light.kind == "sun":
        lux.CreateAngleAttr(float(light.angle))
    elif light.kind == "area" and light.shape == "rectangle":
        lux.CreateWidthAttr(float(light.size[0]))
        lux.CreateHeightAttr(float(light.size[1]))
    elif light.kind == "area":
        lux.CreateRadiusAttr(0.5)
    writer._set_transform(lux, light_matrix(light))
    writer._color(prim, C.A_LIGHT_COLOR, light.color)
    if light.kind != "point":
        _write_exact(writer, prim, light)
    if light.name is not None:
        writer._attr(prim, A_NAME, writer.Sdf.ValueTypeNames.String, light.name)


def _write_exact(writer, prim, light: Light) -> None:
    """Every field of a light of the extensions, exactly."""
    writer._attr(prim, A_KIND, writer.Sdf.ValueTypeNames.Token, light.kind)
    writer._attr(prim, A_SAMPLES, writer.Sdf.ValueTypeNames.Int, int(light.samples))
    if light.kind in ("spot", "sun", "area"):
        writer._vec(prim, A_DIRECTION, light.direction)
    if light.kind in ("sphere", "spot"):
        writer._double(prim, A_RADIUS, light.radius)
    if light.kind == "spot":
        writer._double(prim, A_SPOT_SIZE, light.spot_size)
        writer._double(prim, A_SPOT_BLEND, light.spot_blend)
    if light.kind == "sun":
        writer._double(prim, A_ANGLE, light.angle)
    if light.kind == "area":
        writer._vec(prim, A_AXIS, light.axis)
        writer._attr(prim, A_SIZE, writer.Sdf.ValueTypeNames.Double2, writer.Gf.Vec2d(*map(float, light.size)))


def prim_name(light: Light, index: int, taken: set) -> str:
    """A prim name for the light: its name made a valid identifier (unique among ``taken``), else light_N."""
    from pxr import Tf
    base = Tf.MakeValidIdentifier(light.name) if light.name else f"light_{index}"
    name, count = base, 0
    while name in taken:
        count += 1
        name = f"{base}_{count}"
    taken.add(name)
    return name


# ------------------------------------------------------------------------------------------------ reading


def _agrees(exact, usd_value) -> bool:
    """Whether our exact value is still what the prim's (float) schema attribute says."""
    return usd_value is None or np.allclose(np.float32(exact), np.float32(usd_value), rtol=1e-6, atol=0.0)


def _same_way(exact, found: np.ndarray) -> bool:
    """Whether our exact vector still points the way the prim's transform does (within rounding)."""
    if exact is None:
        return False
    v = np.asarray(exact, dtype=np.float64)
    return float(np.linalg.norm(_unit(v) - found)) < 1e-6


def read_light(reader, prim, type_name: str, color) -> Light:
    """The Light of a UsdLux prim (see _light_of_prim), its numbers checked as SDL's statements check them: a
    ValueError saying what is wrong (a NaN radius, an area light of width 0, a sun's angle of 720 degrees)."""
    light = _light_of_prim(reader, prim, type_name, color)
    problem = None if light.kind == "point" else light_problem(light)
    if problem is not None:
        raise ValueError(problem)
    return light


def _light_of_prim(reader, prim, type_name: str, color) -> Light:
    """The Light of a UsdLux prim we read (``color``: its colour as the reader worked it out).  Ours come back
    exactly; another tool's SphereLight is
    SDL's point light as before, its DistantLight a sun, its RectLight and DiskLight area lights."""
    kind = reader.get(prim, A_KIND)
    name = reader.get(prim, A_NAME)
    name = str(name) if name is not None else (None if reader.get(prim, C.A_LIGHT_COLOR) is not None
                                               else str(prim.GetName()))
    if kind is None and type_name == "SphereLight":
        return Light(tuple(float(x) for x in reader.world(prim)[:3, 3]), color, name=name)
    world = reader.world(prim)
    position = tuple(float(x) for x in world[:3, 3])
    x_axis, y_axis, z_axis = world[:3, 0], world[:3, 1], world[:3, 2]
    z_length = float(np.linalg.norm(z_axis))
    if not z_length > 0:
        raise ValueError("a degenerate transform")
    shine = -z_axis / z_length
    exact_direction = reader.triple(prim, A_DIRECTION)
    direction = exact_direction if _same_way(exact_direction, shine) else tuple(float(x) for x in shine)
    samples = int(reader.get(prim, A_SAMPLES, 1))
    common = dict(color=color, name=name, samples=samples)
    if type_name == "DistantLight":
        angle = _exact_or(reader, prim, A_ANGLE, "inputs:angle", 0.0)
        return Light((0.0, 0.0, 0.0), kind="sun", direction=direction, angle=angle, **common)
    if type_name == "SphereLight":  # ours: a sphere or a spot
        radius = _exact_or(reader, prim, A_RADIUS, "inputs:radius", 0.0)
        if str(kind) == "sphere":
            return Light(position, kind="sphere", radius=radius, **common)
        half = reader.get(prim, "inputs:shaping:cone:angle")
        size = _exact_or(reader, prim, A_SPOT_SIZE, None, 2.0 * float(half) if half is not None else 180.0,
                         None if half is None else 2.0 * float(half))
        blend = _exact_or(reader, prim, A_SPOT_BLEND, "inputs:shaping:cone:softness", 0.0)
        return Light(position, kind="spot", direction=direction, radius=radius, spot_size=size,
                     spot_blend=min(max(blend, 0.0), 1.0), **common)
    x_length, y_length = float(np.linalg.norm(x_axis)), float(np.linalg.norm(y_axis))
    if type_name == "RectLight":
        size = (float(reader.get(prim, "inputs:width", 1.0)) * x_length,
                float(reader.get(prim, "inputs:height", 1.0)) * y_length)
        shape = "rectangle"
    else:
        diameter = 2.0 * float(reader.get(prim, "inputs:radius", 0.5))
        size, shape = (diameter * x_length, diameter * y_length), "ellipse"
    exact_size = reader.get(prim, A_SIZE)
    if exact_size is not None and _agrees(tuple(exact_size), size):
        size = tuple(float(s) for s in exact_size)
    exact_axis = reader.triple(prim, A_AXIS)
    axis = exact_axis if exact_axis is not None and _same_way(_across(exact_axis, shine), x_axis / x_length) else (
        tuple(float(v) for v in x_axis / x_length))
    return Light(position, kind="area", shape=shape, direction=direction, axis=axis, size=size, **common)


def _across(axis, shine: np.ndarray) -> np.ndarray:
    a = np.asarray(axis, dtype=np.float64)
    return a - (a @ shine) * shine


def _exact_or(reader, prim, exact_name: str, usd_name: Optional[str], default: float,
              usd_value: Optional[float] = None) -> float:
    """Our exact number where the prim's schema attribute (``usd_name``, or the value ``usd_value``) still
    agrees with it, else the schema's (else ``default``)."""
    if usd_name is not None:
        found = reader.get(prim, usd_name)
        usd_value = None if found is None else float(found)
    exact = reader.get(prim, exact_name)
    if exact is not None and _agrees(float(exact), usd_value):
        return float(exact)
    return default if usd_value is None else usd_value
