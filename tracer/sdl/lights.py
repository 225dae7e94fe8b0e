"""The SDL statements of the physical lights (an extension for Blender scenes; docs/sdl.md) both ways:
numbers -> tracer.model.Light for the reader, Light -> statement for the writer.  SDL's own ``light x y z r
g b`` (kind "point") stays the parser's."""
from __future__ import annotations

import math
from typing import Optional, Union

from ..model import MAX_LIGHT_SAMPLES, Light

#: Each extension keyword with its arguments, in order (the reader's USAGE entries).
LIGHT_USAGE = {
    "sphereLight": "x y z r g b radius samples",
    "spotLight": "x y z dx dy dz r g b size blend radius samples",
    "sunLight": "dx dy dz r g b angle samples",
    "areaLight": "x y z dx dy dz ax ay az r g b width height samples",
    "ellipseLight": "x y z dx dy dz ax ay az r g b width height samples",
}
#: The keyword of each (kind, area shape).
_KEYWORD = {("sphere", None): "sphereLight", ("spot", None): "spotLight", ("sun", None): "sunLight",
            ("area", "rectangle"): "areaLight", ("area", "ellipse"): "ellipseLight"}


def argument_count(keyword: str) -> int:
    return len(LIGHT_USAGE[keyword].split())


def light_of(keyword: str, numbers: tuple[float, ...], name: Optional[str] = None) -> Union[Light, str]:
    """The Light a statement gives, or what is wrong with its numbers (one phrase)."""
    values = dict(zip(LIGHT_USAGE[keyword].split(), numbers))
    samples = values["samples"]
    if not (samples.is_integer() and 1 <= samples <= MAX_LIGHT_SAMPLES):
        return f"samples must be a whole number 1..{MAX_LIGHT_SAMPLES}"
    common = dict(color=(values["r"], values["g"], values["b"]), name=name, samples=int(samples))
    direction = (values.get("dx"), values.get("dy"), values.get("dz"))
    if "dx" in values and not any(direction):
        return "the direction is zero"
    position = (values.get("x", 0.0), values.get("y", 0.0), values.get("z", 0.0))
    if keyword == "sunLight":
        light = Light(position, kind="sun", direction=direction, angle=values["angle"], **common)
    elif keyword == "sphereLight":
        light = Light(position, kind="sphere", radius=values["radius"], **common)
    elif keyword == "spotLight":
        light = Light(position, kind="spot", direction=direction, radius=values["radius"], spot_size=values["size"],
                      spot_blend=values["blend"], **common)
    else:
        axis = (values["ax"], values["ay"], values["az"])
        if not _across(direction, axis):
            return "the axis must not be zero or along the direction"
        light = Light(position, kind="area", direction=direction, axis=axis, size=(values["width"], values["height"]),
                      shape="rectangle" if keyword == "areaLight" else "ellipse", **common)
    return light_problem(light) or light


def light_problem(light: Light) -> Optional[str]:
    """What is wrong with a physical light's numbers (one phrase), or None: the rules every reader applies
    (the SDL statements above, USD's lights), so that no reader hands the tracer a light it cannot trace."""
    numbers = (*light.position, *light.color, *light.direction, *light.axis, light.radius, light.angle,
               light.spot_size, light.spot_blend, *light.size)
    if not all(math.isfinite(x) for x in numbers):
        return "its numbers must be finite"
    if light.kind == "sun" and not 0.0 <= light.angle < 180.0:
        return "the sun's angle must be at least 0 and under 180 degrees"
    if light.kind in ("sphere", "spot") and not light.radius >= 0.0:
        return "the radius must not be negative"
    if light.kind == "spot" and not 0.0 < light.spot_size <= 180.0:
        return "the spot size must be over 0 and at most 180 degrees"
    if light.kind == "spot" and not 0.0 <= light.spot_blend <= 1.0:
        return "the spot blend must be 0..1"
    if light.kind == "area" and not (light.size[0] > 0.0 and light.size[1] > 0.0):
        return "the width and height must be over 0"
    return None


def _across(direction, axis) -> bool:
    """Whether ``axis`` has a part perpendicular to ``direction`` (so that it gives the light's frame)."""
    cross = (direction[1] * axis[2] - direction[2] * axis[1], direction[2] * axis[0] - direction[0] * axis[2],
             direction[0] * axis[1] - direction[1] * axis[0])
    size = math.hypot(*direction) * math.hypot(*axis)
    return size > 0.0 and math.hypot(*cross) > 1e-9 * size


def statement_of(light: Light, fmt_all) -> str:
    """The SDL statement of a light (``fmt_all`` writes numbers exactly; the writer's)."""
    if light.kind == "point":
        return f"light {fmt_all(light.position)} {fmt_all(light.color)}"
    keyword = _KEYWORD[light.kind, light.shape if light.kind == "area" else None]
    if light.kind == "sun":
        numbers = (*light.direction, *light.color, light.angle)
    elif light.kind == "sphere":
        numbers = (*light.position, *light.color, light.radius)
    elif light.kind == "spot":
        numbers = (*light.position, *light.direction, *light.color, light.spot_size, light.spot_blend, light.radius)
    else:
        numbers = (*light.position, *light.direction, *light.axis, *light.color, *light.size)
    return f"{keyword} {fmt_all(numbers + (light.samples,))}"
