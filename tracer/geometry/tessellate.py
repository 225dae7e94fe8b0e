"""Polygon meshes of the generic shapes, for tools that draw polygons: the USD writer (shapes USD has no
implicit prim for) and the Blender add-on (its preview meshes).  The tracer itself never uses them: it
traces the exact shapes.  All meshes are in generic coordinates, faces counter-clockwise seen from outside,
with exact per-corner normals.
"""
from __future__ import annotations

import math

import numpy as np

from ..meshdata import MeshData
from ..shapes import TORUS_TUBE_RADIUS

#: Segments around the z axis (tapered cylinder, torus ring) and around the torus tube.
AROUND = 48
TUBE = 16


def square_mesh() -> MeshData:
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    return MeshData(vertices, np.array([[0.0, 0.0, 1.0]]), [((0, 1, 2, 3), (0, 0, 0, 0))], "built-in:square")


def tapered_cylinder_mesh(small_radius: float, segments: int = AROUND) -> MeshData:
    """Wall from radius 1 at z = 0 to ``small_radius`` at z = 1 (``segments`` faces, first), the base disc
    and (unless it is a point) the cap disc.  Vertices: the bottom ring, then the top ring or the apex.  The
    wall's normal (cos a, sin a, 1 - s) is the gradient of r(z) - |xy|."""
    s = float(small_radius)
    angles = 2.0 * math.pi * np.arange(segments) / segments
    c, n = np.cos(angles), np.sin(angles)
    bottom = np.column_stack([c, n, np.zeros(segments)])
    apex = s == 0.0
    top = np.array([[0.0, 0.0, 1.0]]) if apex else np.column_stack([s * c, s * n, np.ones(segments)])
    vertices = np.vstack([bottom, top])
    wall = np.column_stack([c, n, np.full(segments, 1.0 - s)])
    wall /= np.linalg.norm(wall, axis=1, keepdims=True)
    normals = np.vstack([wall, [[0.0, 0.0, -1.0], [0.0, 0.0, 1.0]]])
    down, up = segments, segments + 1
    faces: list[tuple[tuple[int, ...], tuple[int, ...]]] = []
    for k in range(segments):
        k1 = (k + 1) % segments
        if apex:
            faces.append(((k, k1, segments), (k, k1, k)))  # the apex has no single normal: keep the edge's
        else:
            faces.append(((k, k1, segments + k1, segments + k), (k, k1, k1, k)))
    faces.append((tuple(range(segments - 1, -1, -1)), (down,) * segments))  # base, seen from below
    if not apex:
        faces.append((tuple(range(segments, 2 * segments)), (up,) * segments))
    return MeshData(vertices, normals, faces, f"built-in:taperedCylinder {s!r}")


def torus_mesh(around: int = AROUND, tube: int = TUBE) -> MeshData:
    """Ring radius 1 about the z axis, tube radius TORUS_TUBE_RADIUS: ``around`` x ``tube`` quads."""
    r = TORUS_TUBE_RADIUS
    a = 2.0 * math.pi * np.arange(around) / around
    b = 2.0 * math.pi * np.arange(tube) / tube
    ca, sa = np.cos(a)[:, None], np.sin(a)[:, None]
    cb, sb = np.cos(b)[None, :], np.sin(b)[None, :]
    normals = np.stack([ca * cb, sa * cb, np.broadcast_to(sb, (around, tube))], axis=-1).reshape(-1, 3)
    centres = np.stack([ca, sa, np.zeros_like(ca)], axis=-1).reshape(around, 1, 3)
    vertices = (centres + r * normals.reshape(around, tube, 3)).reshape(-1, 3)
    faces = []
    for i in range(around):
        i1 = (i + 1) % around
        for j in range(tube):
            j1 = (j + 1) % tube
            quad = (i * tube + j, i1 * tube + j, i1 * tube + j1, i * tube + j1)
            faces.append((quad, quad))
    return MeshData(vertices, normals, faces, "built-in:torus")
