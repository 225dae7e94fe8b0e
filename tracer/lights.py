"""The physical lights (sphere, spot, sun, area: docs/tracer.md, "Lights") as the tracers use them: a table of
numbers per light computed once, and the stratified sampling of their shadow rays.

Both backends compute the same numbers in the same order (tracer/native/lights.h is the C side): the
sample shift is a hash of the shaded point's bits, the sample points a rank-1 lattice of the unit square
moved by it, mapped onto a disk or a cone with the C library's sqrt, cos and sin (NumPy's float64 cos and
sin are the C library's).
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from .model import LIGHT_KINDS, LIGHT_SWITCHES, Light
from .numerics import dot3, norm3

#: Each kind's code in the tables (the C core's LIGHT_* codes).
LIGHT_CODES = {kind: code for code, kind in enumerate(LIGHT_KINDS)}
POINT, SPHERE, SPOT, SUN, AREA = (LIGHT_CODES[k] for k in ("point", "sphere", "spot", "sun", "area"))
#: Each switch's bit in LightTable.off, set where the light has it off (the C core's LIGHT_OFF_* bits).
OFF_BITS = {switch: 1 << bit for bit, switch in enumerate(LIGHT_SWITCHES)}
OFF_SHADOW, OFF_DIFFUSE, OFF_GLOSSY, OFF_TRANSMISSION = (OFF_BITS[s] for s in LIGHT_SWITCHES)
#: A light with both of these off adds nothing to any surface's shading.
OFF_SHADING = OFF_DIFFUSE | OFF_GLOSSY
#: The lattice's step along v: the golden ratio's fractional part, (sqrt 5 - 1) / 2.
GOLDEN = 0.6180339887498949
TWO_PI = 6.283185307179586
#: Per light, LightTable.frame: the unit direction, then an area light's half-extent vectors U and V.
FRAME_WIDTH = 9
#: Per light, LightTable.param (see LightTable).
PARAM_WIDTH = 4


@dataclass
class LightTable:
    """The scene's lights as arrays, row l for light l.

    ``kind`` (L,) int32 LIGHT_CODES; ``position``, ``color`` (L, 3); ``frame`` (L, 9): the unit direction
    (spot, area: the way it shines; sun: the way its light travels), an area light's U = axis * width / 2 and
    V = (direction x axis) * height / 2 (axis made unit and perpendicular to the direction); ``param`` (L, 4):
    sphere [radius], spot [radius, cos(size / 2), (1 - cos(size / 2)) * blend], sun [1 - cos(angle / 2)],
    area [area, 1 for an ellipse]; ``samples`` (L,) int32: shadow rays per shaded point (1 for a light with
    no extent); ``off`` (L,) int32: the OFF_BITS of its switches that are off (0: all on)."""

    kind: np.ndarray
    position: np.ndarray
    color: np.ndarray
    frame: np.ndarray
    param: np.ndarray
    samples: np.ndarray
    off: np.ndarray

    @classmethod
    def of(cls, lights: list[Light]) -> "LightTable":
        n = len(lights)
        frame, param = np.zeros((n, FRAME_WIDTH)), np.zeros((n, PARAM_WIDTH))
        for row, light in enumerate(lights):
            frame[row], param[row] = _frame(light), _param(light)
        return cls(kind=np.array([LIGHT_CODES[light.kind] for light in lights], dtype=np.int32).reshape(n),
                   position=np.array([light.position for light in lights], dtype=float).reshape(n, 3),
                   color=np.array([light.color for light in lights], dtype=float).reshape(n, 3),
                   frame=frame, param=param,
                   samples=np.array([light.samples if light.soft else 1 for light in lights],
                                    dtype=np.int32).reshape(n),
                   off=np.array([off_bits(light) for light in lights], dtype=np.int32).reshape(n))


def off_bits(light: Light) -> int:
    """The OFF_BITS of the light's switches that are off."""
    return sum(bit for switch, bit in OFF_BITS.items() if not getattr(light, switch))


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / norm3(v)  # (no overflow or underflow: a direction may be given as 1e-300 or 1e300 long)


def _frame(light: Light) -> np.ndarray:
    out = np.zeros(FRAME_WIDTH)
    if light.kind in ("point", "sphere"):
        return out
    d = _unit(light.direction)
    out[:3] = d
    if light.kind == "area":
        axis = np.asarray(light.axis, dtype=float)
        a = _unit(axis - (axis @ d) * d)
        out[3:6] = a * (light.size[0] / 2.0)
        out[6:9] = np.cross(d, a) * (light.size[1] / 2.0)
    return out


def _param(light: Light) -> list[float]:
    if light.kind == "sphere":
        return [light.radius, 0.0, 0.0, 0.0]
    if light.kind == "spot":
        cos_half = math.cos(math.radians(light.spot_size) / 2.0)
        return [light.radius, cos_half, (1.0 - cos_half) * light.spot_blend, 0.0]
    if light.kind == "sun":  # 1 - cos(angle / 2) = 2 sin^2(angle / 4), without cancellation
        return [2.0 * math.sin(math.radians(light.angle) / 4.0) ** 2, 0.0, 0.0, 0.0]
    if light.kind == "area":
        width, height = light.size
        ellipse = light.shape == "ellipse"
        return [width * height * (math.pi / 4.0 if ellipse else 1.0), float(ellipse), 0.0, 0.0]
    return [0.0, 0.0, 0.0, 0.0]


def seen_lights(table: LightTable, origins: np.ndarray, directions: np.ndarray, t_max: np.ndarray,
                refracted: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Which rays see a light with an extent (Cycles' lights are seen by glossy and transmission rays, not by
    the camera's), and the nearest one's radiance in the tracer's units (a light's colour is what the Lambert
    sum of a white diffuse surface takes: radiance over pi; docs/tracer.md, "Seen lights"):

    * the front of an area light, met before ``t_max``: pi times its colour;
    * the sphere of a sphere or spot light of radius r > 0, met before ``t_max``: colour / r^2 (its colour
      lights a white surface facing it at distance x with colour / (x^2 + r^2): irradiance pi colour /
      (x^2 + r^2), which a sphere of radiance L gives as pi L r^2 / (x^2 + r^2), a disk of its radius facing
      the point as Cycles takes it; so L = colour / r^2, its intensity pi colour over the disk's area pi r^2);
      a spot's times the spot factor of the direction from the light to the ray's origin, as its own light
      is cut (outside its cone it is not seen);
    * a sun of angle > 0, where the ray meets nothing else (``t_max`` infinite, no light met) and its
      direction lies within angle / 2 of the sun's: colour / (2 (1 - cos(angle / 2))) (its colour lights a
      white surface facing it with colour: irradiance pi colour over the solid angle 2 pi (1 - cos(angle / 2))).

    The lights in their order, a later one seen where strictly nearer: the C core's seen_light, in its order
    of operations.  ``refracted``: which rays are transmitted ones (the others reflected), where the lights'
    switches count (the effect light-switches): a light with visible_transmission off is not seen by the
    first, one with visible_glossy off not by the second; None: every light is seen by every ray."""
    n = origins.shape[0]
    seen, color, nearest = np.zeros(n, dtype=bool), np.zeros((n, 3)), np.array(t_max, dtype=float)
    for light in np.flatnonzero(table.kind != POINT).tolist():
        eligible = True
        if refracted is not None:
            off = int(table.off[light])
            eligible = np.where(refracted, (off & OFF_TRANSMISSION) == 0, (off & OFF_GLOSSY) == 0)
            if not eligible.any():
                continue
        kind, param, light_color = int(table.kind[light]), table.param[light], table.color[light]
        if kind == SUN:
            if not param[0] > 0.0:
                continue
            cos_alpha = -dot3(directions, table.frame[light, :3]) / np.sqrt(dot3(directions, directions))
            met = eligible & ~seen & (nearest == np.inf) & (1.0 - cos_alpha <= param[0])
            seen |= met  # (nearest stays infinite: a light met at any distance is in front of the sun)
            color[met] = light_color / (2.0 * param[0])
            continue
        if kind == AREA:
            t = _area_meets(table, light, origins, directions)
            radiance = np.pi * light_color
        else:
            r2 = param[0] * param[0]
            if not r2 > 0.0:
                continue
            t = _sphere_meets(table.position[light], r2, origins, directions)
            factor = _spot_seen(table, light, origins) if kind == SPOT else 1.0
            radiance = light_color / r2 * np.reshape(factor, (-1, 1))
        met = (t > 0.0) & (t < nearest) & eligible
        if kind == SPOT:
            met &= factor > 0.0
        nearest[met] = t[met]
        seen |= met
        color[met] = np.broadcast_to(radiance, color.shape)[met]
    return seen, color


def _area_meets(table: LightTable, light: int, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The distance along each ray (units of its direction) at which it meets the front of area light
    ``light``, or 0 where it does not (its back, or its plane, is not seen): the C core's area_meets."""
    normal, u, v = table.frame[light, :3], table.frame[light, 3:6], table.frame[light, 6:9]
    position = table.position[light]
    facing = dot3(directions, normal)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        t = dot3(position - origins, normal) / facing
        q = origins + t[:, None] * directions - position
        a, b = dot3(q, u) / dot3(u, u), dot3(q, v) / dot3(v, v)
        inside = a * a + b * b <= 1.0 if table.param[light, 1] != 0.0 else (np.abs(a) <= 1.0) & (np.abs(b) <= 1.0)
    return np.where((facing < 0.0) & (t > 0.0) & inside, t, 0.0)


def _sphere_meets(centre: np.ndarray, r2: float, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """The nearest positive root of |o + t d - centre|^2 = r2 per ray, or 0 where it misses the sphere (the
    discriminant as r2 |d|^2 - |d x (o - centre)|^2: it keeps its digits for a light far from the origin); the
    C core's sphere_meets."""
    oc = origins - centre
    d = directions
    across = np.stack([d[:, 1] * oc[:, 2] - d[:, 2] * oc[:, 1], d[:, 2] * oc[:, 0] - d[:, 0] * oc[:, 2],
                       d[:, 0] * oc[:, 1] - d[:, 1] * oc[:, 0]], axis=1)
    a, b = dot3(d, d), dot3(d, oc)
    disc = a * r2 - dot3(across, across)
    with np.errstate(invalid="ignore", divide="ignore"):
        root = np.sqrt(disc)
        near, far = (-b - root) / a, (-b + root) / a
    t = np.where(near > 0.0, near, far)
    return np.where((disc >= 0.0) & (t > 0.0), t, 0.0)


def _spot_seen(table: LightTable, light: int, origins: np.ndarray) -> np.ndarray:
    """Spot light ``light``'s cone factor towards each ray's origin (spot_factor of the direction from the light
    to it, as the spot lights a point there)."""
    to = table.position[light] - origins
    with np.errstate(divide="ignore", invalid="ignore"):  # (an origin at the light's centre: no direction, 0)
        s = to / np.sqrt(dot3(to, to))[:, None]
    _, cos_half, blend_width, _ = table.param[light]
    return spot_factor(-dot3(s, table.frame[light, :3]), cos_half, blend_width)


# ------------------------------------------------------------------------------------------------ sampling

_MASK = np.uint64(0xFFFFFFFFFFFFFFFF)


def _mix(z: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser (uint64 arithmetic wraps, as C's does)."""
    z = z + np.uint64(0x9E3779B97F4A7C15)
    z = (z ^ (z >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    z = (z ^ (z >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return z ^ (z >> np.uint64(31))


def sample_shifts(points: np.ndarray, light: int) -> tuple[np.ndarray, np.ndarray]:
    """Per shaded point (N, 3), the lattice shift (xi1, xi2) in [0, 1)^2 for light number ``light``: a hash of
    the bits of its coordinates rounded to single precision, and the light's number.  (Rounded: the backends
    may find a hit an ulp apart, which the double's bits would turn into other samples altogether.)"""
    bits = np.ascontiguousarray(points, dtype=np.float64).astype(np.float32).view(np.uint32).astype(np.uint64)
    with np.errstate(over="ignore"):
        h = _mix(bits[:, 2] ^ (np.uint64(light + 1) * np.uint64(0x9E3779B97F4A7C15)))
        h = _mix(bits[:, 1] ^ h)
        h = _mix(bits[:, 0] ^ h)
        second = _mix(h)
    scale = 2.0 ** -53
    return (h >> np.uint64(11)).astype(np.float64) * scale, (second >> np.uint64(11)).astype(np.float64) * scale


def lattice(k: int, n: int, xi1: np.ndarray, xi2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Sample k of n of the shifted rank-1 lattice: ((k + xi1) / n, frac(k g + xi2)), in [0, 1)^2."""
    u = (k + xi1) / n
    v = k * GOLDEN + xi2
    return u, v - np.floor(v)


def basis(s: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit vectors (N, 3) perpendicular to the unit vectors ``s`` and to each other (Duff et al.'s
    branchless frame)."""
    x, y, z = s[:, 0], s[:, 1], s[:, 2]
    sign = np.copysign(1.0, z)
    a = -1.0 / (sign + z)
    b = x * y * a
    t1 = np.stack([1.0 + sign * x * x * a, sign * b, -sign * x], axis=1)
    t2 = np.stack([b, sign + y * y * a, -y], axis=1)
    return t1, t2


def disk_point(u: np.ndarray, v: np.ndarray, e1: np.ndarray, e2: np.ndarray) -> np.ndarray:
    """The point of the unit-square sample (u, v) on the disk (ellipse) spanned by e1, e2 (N, 3), uniformly by
    area: radius sqrt(u), angle 2 pi v."""
    rho = np.sqrt(u)
    angle = TWO_PI * v
    c, s = rho * np.cos(angle), rho * np.sin(angle)
    return c[:, None] * e1 + s[:, None] * e2


def cone_direction(u: np.ndarray, v: np.ndarray, axis: np.ndarray, t1: np.ndarray, t2: np.ndarray,
                   one_minus_cos: float) -> np.ndarray:
    """A direction within the cone about the unit ``axis`` whose half-angle has 1 - cos = one_minus_cos,
    uniformly by solid angle: 1 - cos(theta) = u * one_minus_cos, about the axis by 2 pi v."""
    w = u * one_minus_cos
    sin_theta = np.sqrt(w * (2.0 - w))
    angle = TWO_PI * v
    c, s = sin_theta * np.cos(angle), sin_theta * np.sin(angle)
    return (1.0 - w)[:, None] * axis + c[:, None] * t1 + s[:, None] * t2


def spot_factor(cos_alpha: np.ndarray, cos_half: float, blend_width: float) -> np.ndarray:
    """Blender's spot cone: 0 outside (cos alpha <= cos(size / 2)), smoothstep over the blend, 1 inside."""
    x = cos_alpha - cos_half
    if blend_width > 0.0:
        t = np.minimum(x / blend_width, 1.0)
        smooth = t * t * (3.0 - 2.0 * t)
    else:
        smooth = np.ones_like(x)
    return np.where(x > 0.0, smooth, 0.0)
