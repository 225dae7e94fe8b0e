"""Each generic shape's natural surface coordinates (u, v) in [0, 1]^2, for image textures.

| shape | u | v | wraps |
|---|---|---|---|
| sphere | longitude about the generic z axis | latitude, 0 at the south pole (z = -1) | u |
| cylinder, cone wall | angle about z | height z | u |
| their discs, square | x, y over [-1, 1] | | — |
| plane | x, y, one image every 2 units | | u and v |
| cube | each face its own square, upright and unmirrored seen from outside | | — |
| torus | angle about z | angle around the tube, 0 on the outer equator | u and v |
| polyhedra, meshes | longitude / latitude of the direction from the centre | | u |
"""
from __future__ import annotations

import numpy as np

from .. import shapes

TWO_PI = 2.0 * np.pi


def _angle01(y: np.ndarray, x: np.ndarray) -> np.ndarray:
    """atan2 mapped to [0, 1), with the seam at angle 0 (the +x direction)."""
    return np.mod(np.arctan2(y, x) / TWO_PI, 1.0)


def _square(a: np.ndarray, b: np.ndarray):
    return (a + 1.0) / 2.0, (b + 1.0) / 2.0


# Per cube face (part = 2 * axis + (1 on the + side)): (u, v) as functions of the point.
_CUBE_FACES = {
    0: lambda p: ((p[:, 2] + 1) / 2, (p[:, 1] + 1) / 2),  # -x, seen from -x: right is +z
    1: lambda p: ((1 - p[:, 2]) / 2, (p[:, 1] + 1) / 2),  # +x: right is -z
    2: lambda p: ((p[:, 0] + 1) / 2, (p[:, 2] + 1) / 2),  # -y, seen from below: up is +z
    3: lambda p: ((p[:, 0] + 1) / 2, (1 - p[:, 2]) / 2),  # +y, seen from above: up is -z
    4: lambda p: ((1 - p[:, 0]) / 2, (p[:, 1] + 1) / 2),  # -z: right is -x
    5: lambda p: ((p[:, 0] + 1) / 2, (p[:, 1] + 1) / 2),  # +z: right is +x
}


def wall_and_discs_uv(points: np.ndarray, parts: np.ndarray):
    """A wall about z (part 0) by angle and height, its discs (other parts) as squares; u wraps.  The tapered
    cylinders' mapping, and any registered shape's that names it (tracer/shapes.py)."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    u_disc, v_disc = _square(x, y)
    wall = parts == 0
    return (np.where(wall, _angle01(y, x), u_disc), np.where(wall, np.clip(z, 0.0, 1.0), v_disc), True, False)


def sphere_uv(points: np.ndarray, parts: np.ndarray):
    """Longitude about z, latitude from the south pole; u wraps."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    return _angle01(y, x), 0.5 + np.arcsin(np.clip(z, -1.0, 1.0)) / np.pi, True, False


def square_uv(points: np.ndarray, parts: np.ndarray):
    """x and y over [-1, 1]."""
    u, v = _square(points[:, 0], points[:, 1])
    return u, v, False, False


def plane_uv(points: np.ndarray, parts: np.ndarray):
    """x and y, one image every 2 units; both wrap."""
    x, y = points[:, 0], points[:, 1]
    return np.mod((x + 1.0) / 2.0, 1.0), np.mod((y + 1.0) / 2.0, 1.0), True, True


def cube_uv(points: np.ndarray, parts: np.ndarray):
    """Each face (part) its own square, upright and unmirrored seen from outside."""
    u = np.zeros_like(points[:, 0])
    v = np.zeros_like(points[:, 0])
    for face, uv in _CUBE_FACES.items():
        rows = parts == face
        if rows.any():
            u[rows], v[rows] = (c[rows] for c in uv(points))
    return u, v, False, False


def torus_uv(points: np.ndarray, parts: np.ndarray):
    """The angle about z and the angle around the tube (0 on the outer equator); both wrap."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    return _angle01(y, x), _angle01(z, np.hypot(x, y) - 1.0), True, True


def direction_uv(points: np.ndarray, parts: np.ndarray):
    """The direction from the generic centre, as on a globe (polyhedra, meshes); u wraps."""
    x, y, z = points[:, 0], points[:, 1], points[:, 2]
    r = np.maximum(np.linalg.norm(points, axis=1), 1e-300)
    return _angle01(y, x), 0.5 + np.arcsin(np.clip(z / r, -1.0, 1.0)) / np.pi, True, False


def surface_uv(kind: str, points: np.ndarray, parts: np.ndarray):
    """(u, v, wrap_u, wrap_v) for (N, 3) generic points on a shape of ``kind``; parts as the intersector gives
    (the kind's registered mapping, tracer/shapes.py)."""
    return shapes.KINDS[kind].function("uv")(points, parts)
