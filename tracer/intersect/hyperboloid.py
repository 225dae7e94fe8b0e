"""The generic hyperboloid of one sheet, an SDL extension with one parameter, its waist radius S
(``hyperboloid S``; docs/sdl.md): the solid ``x^2 + y^2 - (1 - S^2) z^2 <= S^2``, ``-1 <= z <= 1``.

Its wall (part 0) has radius ``sqrt(S^2 + (1 - S^2) z^2)``: S at the waist z = 0 and 1 at both ends, where
the bottom (part 1, z = -1) and top (part 2, z = 1) cap discs of radius 1 close it.  S = 1 is the cylinder
of radius 1, 0 < S < 1 an hourglass, S = 0 the double cone, S > 1 a barrel; only S^2 counts.  This module
holds its NumPy geometry: the line intersection (the C form is ``hits_hyperboloid`` in native/shapes.h),
its bounds, its texture mapping (the tapered cylinders' with the height from -1..1) and the polygons USD and
Blender draw; tracer/shapes.py registers all of it.

A line steeper than the wall's asymptotes (inside the waist's cone of directions) can pass through the
solid twice, in through a cap, out of the wall, in again and out of the other cap: up to four crossings.
"""
from __future__ import annotations

import math

import numpy as np

from ..model import MeshData
from ..numerics import TOLERANCES, Tolerances, gamma
from ..textures.mapping import wall_and_discs_uv
from .hits import HitArrays
from .paraboloid import wall_proven_inside
from .quadratic import solve_quadratic

#: Rings of the tessellation's wall (z evenly spaced from -1 to 1: an even count puts one at the waist) and
#: segments around the z axis.
RINGS = 16
AROUND = 48


def _inside_intervals(a, b, c, slab_lo, slab_hi):
    """Where the line is inside the wall, ``a t^2 + 2 b t + c <= 0``, clipped to the slab between the caps:
    up to two intervals (s1, e1), (s2, e2), NaN where empty, the first one first.

    a >= 0: between the roots (a = b = 0: everywhere or nowhere).  a < 0 (a line steeper than the
    asymptotes): outside the roots, or everywhere when there are none; two intervals that touch (a double
    root) are one."""
    lo, hi, real = solve_quadratic(a, b, c)
    flat = (a == 0.0) & (b == 0.0)
    between_lo = np.where(flat, np.where(c <= 0.0, -np.inf, np.nan), np.where(real, lo, np.nan))
    between_hi = np.where(flat, np.where(c <= 0.0, np.inf, np.nan), np.where(real, hi, np.nan))
    negative = a < 0.0
    s1 = np.where(negative, slab_lo, np.maximum(between_lo, slab_lo))
    e1 = np.where(negative, np.where(real, np.minimum(lo, slab_hi), slab_hi), np.minimum(between_hi, slab_hi))
    s2 = np.where(negative & real, np.maximum(hi, slab_lo), np.nan)
    e2 = np.where(negative & real, slab_hi, np.nan)
    with np.errstate(invalid="ignore"):
        first, second = s1 <= e1, s2 <= e2
        join = first & second & (e1 >= s2)
    e1 = np.where(join, e2, e1)
    second = second & ~join
    # (the nonempty intervals, the first in the first place)
    both = first & second
    return (np.where(first, s1, np.where(second, s2, np.nan)), np.where(first, e1, np.where(second, e2, np.nan)),
            np.where(both, s2, np.nan), np.where(both, e2, np.nan))


def intersect_hyperboloid(origin: np.ndarray, direction: np.ndarray, waist: float,
                          tol: Tolerances = TOLERANCES) -> HitArrays:
    """Every crossing of the whole lines (K = 4: in, out, in, out); parts 0 wall, 1 bottom cap, 2 top cap.
    Where the line is inside between the wall's roots (a >= 0), a pair with a wall crossing counts only
    where it is provably inside between its ends (paraboloid.wall_proven_inside)."""
    w2 = waist * waist
    k = 1.0 - w2
    ox, oy, oz = origin.T
    dx, dy, dz = direction.T
    a = dx * dx + dy * dy - k * dz * dz
    b = ox * dx + oy * dy - k * oz * dz
    c = ox * ox + oy * oy - k * oz * oz - w2
    with np.errstate(divide="ignore", invalid="ignore"):
        t_bottom = (-1.0 - oz) / dz
        t_top = (1.0 - oz) / dz
    parallel = dz == 0.0
    in_slab = (oz >= -1.0) & (oz <= 1.0)
    rising = dz > 0.0
    slab_lo = np.where(parallel, np.where(in_slab, -np.inf, np.nan), np.where(rising, t_bottom, t_top))
    slab_hi = np.where(parallel, np.where(in_slab, np.inf, np.nan), np.where(rising, t_top, t_bottom))
    s1, e1, s2, e2 = _inside_intervals(a, b, c, slab_lo, slab_hi)
    with np.errstate(invalid="ignore"):
        wall = (a >= 0.0) & np.isfinite(s1) & np.isfinite(e1) & ((s1 > slab_lo) | (e1 < slab_hi))
    if wall.any():
        sizes = (dx * dx + dy * dy + np.abs(k) * dz * dz, np.abs(ox * dx) + np.abs(oy * dy) + np.abs(k * oz * dz),
                 ox * ox + oy * oy + np.abs(k) * oz * oz + w2)
        with np.errstate(invalid="ignore"):
            proven = wall_proven_inside(a, b, c, sizes, 0.5 * (s1 + e1), gamma(tol.hit_ulps))
        s1, e1 = np.where(wall & ~proven, np.nan, s1), np.where(wall & ~proven, np.nan, e1)
    hits = HitArrays.empty(origin.shape[0], 4)
    hits.bend = np.zeros_like(hits.t)
    for slot, (t_in, t_out) in enumerate(((s1, e1), (s2, e2))):
        hit = np.isfinite(t_in) & np.isfinite(t_out)
        # An end on the slab's boundary is a cap (ties too).
        part_in = np.where(t_in <= slab_lo, np.where(rising, 1, 2), 0)
        part_out = np.where(t_out >= slab_hi, np.where(rising, 2, 1), 0)
        for end, (t, part) in enumerate(((t_in, part_in), (t_out, part_out))):
            column = 2 * slot + end
            p = origin + np.where(hit, t, 0.0)[:, None] * direction
            wall = np.stack([p[:, 0], p[:, 1], -k * p[:, 2]], axis=1)  # half the gradient
            wall[np.einsum("ij,ij->i", wall, wall) < 1e-300] = (0.0, 0.0, 1.0)  # (the double cone's apex)
            normal = np.where((part == 1)[:, None], (0.0, 0.0, -1.0), np.where((part == 2)[:, None], (0.0, 0.0, 1.0),
                                                                                wall))
            hits.t[:, column] = np.where(hit, t, np.inf)
            hits.entering[:, column] = hit & (end == 0)
            hits.normal[:, column] = np.where(hit[:, None], normal, 0.0)
            hits.part[:, column] = np.where(hit, part, -1)
            # G = (x^2 + y^2 - k z^2 - S^2) / 2 bends by a; its residual is |G|
            wall_hit = hit & (part == 0)
            residual = 0.5 * np.abs(p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1] - k * p[:, 2] * p[:, 2] - w2)
            hits.bend[:, column] = np.where(wall_hit, a, 0.0)
            hits.offset[:, column] = np.where(wall_hit, residual, 0.0)
    return hits


def hyperboloid_bounds(values: np.ndarray) -> np.ndarray:
    """(N, 8, 3) corners of the boxes that hold the hyperboloids of (N, P) parameter rows (the waist
    first): radius max(1, |S|) (at the waist or the caps), -1 <= z <= 1."""
    r = np.maximum(np.abs(values[:, 0]), 1.0)
    corners = np.array([[x, y, z] for z in (-1.0, 1.0) for x, y in ((-1, -1), (-1, 1), (1, -1), (1, 1))],
                       dtype=np.float64)
    points = np.broadcast_to(corners, (len(r), 8, 3)).copy()
    points[:, :, :2] *= r[:, None, None]
    return points


def hyperboloid_uv(points: np.ndarray, parts: np.ndarray):
    """The tapered cylinders' mapping (mapping.wall_and_discs_uv) with the wall's height -1..1 as 0..1: u the
    angle about z, v (z + 1) / 2 on the wall; the caps' x, y over [-1, 1]."""
    half_height = points.copy()
    half_height[:, 2] = (points[:, 2] + 1.0) / 2.0
    return wall_and_discs_uv(half_height, parts)


def hyperboloid_mesh(waist: float, rings: int = RINGS, segments: int = AROUND) -> MeshData:
    """The wall as ``rings`` bands between rings of vertices on the exact surface (a ring of radius 0, the
    double cone's apex, is one vertex), then the bottom and top cap discs; faces counter-clockwise seen from
    outside, exact per-vertex normals.  Vertices ring after ring from z = -1."""
    s = abs(float(waist))
    k = 1.0 - s * s
    angles = 2.0 * math.pi * np.arange(segments) / segments
    cos, sin = np.cos(angles), np.sin(angles)
    vertices, normals, first = [], [], []
    for z in np.linspace(-1.0, 1.0, rings + 1):
        radius = math.sqrt(s * s + k * z * z)
        first.append(len(vertices))
        if radius == 0.0:
            vertices.append((0.0, 0.0, 0.0))
            normals.append((0.0, 0.0, 1.0))  # (not used: the apex's faces keep their other corners')
            continue
        for c, n in zip(cos, sin):
            x, y = radius * c, radius * n
            length = math.sqrt(x * x + y * y + (k * z) ** 2)
            vertices.append((x, y, z))
            normals.append((x / length, y / length, -k * z / length))
    first.append(len(vertices))
    bottom_normal, top_normal = len(normals), len(normals) + 1
    normals += [(0.0, 0.0, -1.0), (0.0, 0.0, 1.0)]

    def at(ring: int, j: int) -> int:
        size = first[ring + 1] - first[ring]
        return first[ring] + (j % segments if size > 1 else 0)

    faces: list[tuple[tuple[int, ...], tuple[int, ...]]] = []
    for ring in range(rings):
        for j in range(segments):
            quad = (at(ring, j), at(ring, j + 1), at(ring + 1, j + 1), at(ring + 1, j))
            if quad[0] == quad[1]:  # the apex below: a triangle, the apex taking its neighbour's normal
                faces.append((quad[1:], (quad[2], quad[2], quad[3])))
            elif quad[2] == quad[3]:  # the apex above
                faces.append((quad[:3], (quad[0], quad[1], quad[1])))
            else:
                faces.append((quad, quad))
    faces.append((tuple(at(0, j) for j in range(segments - 1, -1, -1)), (bottom_normal,) * segments))
    faces.append((tuple(at(rings, j) for j in range(segments)), (top_normal,) * segments))
    return MeshData(np.array(vertices), np.array(normals), faces, f"built-in:hyperboloid {s!r}")
