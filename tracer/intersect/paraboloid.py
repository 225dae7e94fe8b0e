"""The generic paraboloid, an SDL extension: the solid ``x^2 + y^2 <= z <= 1`` (docs/sdl.md).

Its wall ``z = x^2 + y^2`` (part 0) opens upwards from the origin to radius 1 at z = 1, where the cap disc
(part 1) closes it.  This module holds its NumPy geometry: the line intersection (the C form is
``hits_paraboloid`` in native/shapes.h) and the polygons USD and Blender draw.  Its texture mapping is the
tapered cylinders' (wall by angle and height, cap as a square); tracer/shapes.py registers all of it.
"""
from __future__ import annotations

import math

import numpy as np

from ..model import MeshData
from ..numerics import TOLERANCES, Tolerances, gamma
from .analytic import _two_hits, _wall_interval
from .hits import HitArrays

#: Rings of the tessellation's wall (evenly spaced in radius) and segments around the z axis.
RINGS = 16
AROUND = 48


def wall_proven_inside(a, b, c, sizes, t: np.ndarray, rounding: float) -> np.ndarray:
    """Is the quadratic wall function G = a t^2 + 2 b t + c provably negative at t: below minus its rounding,
    ``rounding`` times the size of its terms there (``sizes``: those of a, b and c)?  A pair of crossings
    with the wall, whose middle is not, may be the touching pair rounding makes of a line tangent to the
    wall, or one that misses it by 1e-12 (the paraboloid's and the hyperboloid's; shapes.h's
    quadric_proven_inside)."""
    am, bm, cm = sizes
    at = np.abs(t)
    return (a * t + 2.0 * b) * t + c < -rounding * ((am * at + 2.0 * bm) * at + cm)


def intersect_paraboloid(origin: np.ndarray, direction: np.ndarray, tol: Tolerances = TOLERANCES) -> HitArrays:
    """Entry and exit of the whole line: inside the wall where ``a t^2 + 2 b t + c <= 0`` (a >= 0, so between
    the roots; a vertical line has one root), clipped to the half-space z <= 1 below the cap.  A pair with a
    wall crossing counts only where the line is provably inside between its ends (wall_proven_inside)."""
    ox, oy, oz = origin.T
    dx, dy, dz = direction.T
    a = dx * dx + dy * dy
    b = ox * dx + oy * dy - 0.5 * dz
    c = ox * ox + oy * oy - oz
    with np.errstate(divide="ignore", invalid="ignore"):
        t_cap = (1.0 - oz) / dz
    parallel = dz == 0.0
    below = oz <= 1.0
    rising = dz > 0.0
    slab_lo = np.where(parallel, np.where(below, -np.inf, np.nan), np.where(rising, -np.inf, t_cap))
    slab_hi = np.where(parallel, np.where(below, np.inf, np.nan), np.where(rising, t_cap, np.inf))
    t_in, t_out = _wall_interval(a, b, c, slab_lo, slab_hi)
    hit = np.isfinite(t_in) & np.isfinite(t_out)
    # An end on the half-space's boundary is the cap (ties too).
    part_in = np.where(t_in <= slab_lo, 1, 0)
    part_out = np.where(t_out >= slab_hi, 1, 0)
    wall = hit & ((part_in == 0) | (part_out == 0))
    if wall.any():
        sizes = (a, np.abs(ox * dx) + np.abs(oy * dy) + 0.5 * np.abs(dz), ox * ox + oy * oy + np.abs(oz))
        with np.errstate(invalid="ignore"):
            proven = wall_proven_inside(a, b, c, sizes, 0.5 * (t_in + t_out), gamma(tol.hit_ulps))
        hit &= ~wall | proven
        t_in, t_out = np.where(hit, t_in, np.nan), np.where(hit, t_out, np.nan)

    def normal_at(t, part):
        p = origin + np.where(hit, t, 0.0)[:, None] * direction
        wall = np.stack([2.0 * p[:, 0], 2.0 * p[:, 1], np.full(p.shape[0], -1.0)], axis=1)  # the gradient
        return np.where((part == 1)[:, None], np.array([0.0, 0.0, 1.0]), wall)

    out = _two_hits(t_in, t_out, normal_at(t_in, part_in), normal_at(t_out, part_out), part_in, part_out, hit)
    # The wall's G = x^2 + y^2 - z (the normal its gradient) bends by 2 a; its residual is |G|.
    out.bend = np.zeros_like(out.t)
    for slot, (t, part) in enumerate(((t_in, part_in), (t_out, part_out))):
        p = origin + np.where(hit, t, 0.0)[:, None] * direction
        wall = hit & (part == 0)
        residual = np.abs(p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1] - p[:, 2])
        out.bend[:, slot] = np.where(wall, 2.0 * a, 0.0)
        out.offset[:, slot] = np.where(wall, residual, 0.0)
    return out


def paraboloid_mesh(rings: int = RINGS, segments: int = AROUND) -> MeshData:
    """The wall as a fan round the apex and ``rings - 1`` bands of quads (rings evenly spaced in radius, on
    the surface), then the cap disc; faces counter-clockwise seen from outside, exact per-vertex normals.
    Vertices: the apex, then ring after ring outwards."""
    angles = 2.0 * math.pi * np.arange(segments) / segments
    radii = np.arange(1, rings + 1) / rings
    r = np.repeat(radii, segments)
    c, s = np.tile(np.cos(angles), rings), np.tile(np.sin(angles), rings)
    ring_points = np.column_stack([r * c, r * s, r * r])
    vertices = np.vstack([[[0.0, 0.0, 0.0]], ring_points])
    wall = np.column_stack([2.0 * vertices[:, 0], 2.0 * vertices[:, 1], -np.ones(len(vertices))])
    wall /= np.linalg.norm(wall, axis=1, keepdims=True)
    cap_normal = len(vertices)
    normals = np.vstack([wall, [[0.0, 0.0, 1.0]]])

    def at(ring: int, k: int) -> int:
        return 1 + ring * segments + k % segments

    faces: list[tuple[tuple[int, ...], tuple[int, ...]]] = []
    for k in range(segments):
        fan = (0, at(0, k + 1), at(0, k))
        faces.append((fan, fan))
    for ring in range(rings - 1):
        for k in range(segments):
            quad = (at(ring, k), at(ring, k + 1), at(ring + 1, k + 1), at(ring + 1, k))
            faces.append((quad, quad))
    rim = tuple(at(rings - 1, k) for k in range(segments))
    faces.append((rim, (cap_normal,) * segments))
    return MeshData(vertices, normals, faces, "built-in:paraboloid")
