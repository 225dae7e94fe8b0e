"""The smooth shadow terminator (docs/tracer.md, "Smooth shadow terminator"): shadow feelers of hits on
smooth-shaded mesh triangles start from the point lifted onto the smooth surface of the vertex normals, so
that a low-poly sphere's own flat facets do not cast stair-stepped shadows along its terminator.

The lift is computed in the mesh's generic coordinates (TriangleMesh.smooth_lift) and carried to the world
by the primitive's matrix, written as the inverse of its inverse (Cramer's rule on the 3 x 3 part, as the C
core has no forward matrices): tracer/native/shade.h computes the same numbers in the same order.

The same interpolated normals bend the secondary rays of those hits (docs/tracer.md, "Shading normals and
secondary rays"): near a smooth mesh's silhouette the mirror ray about the interpolated normal can point below
the triangle's own plane, into the mesh (black speckles on a mirror sphere).  Such a ray is bent to leave
just above the triangle's plane (:func:`bent_above`), and starts off the plane along its normal
(:func:`geometric_normals`).  Transmitted rays are left as they are (docs/tracer.md says why)."""
from __future__ import annotations

import numpy as np

from . import numerics, shapes

#: How far (times its length) a bent secondary ray at least rises above the plane of the triangle hit
#: (shade.h's MIN_RISE): about 0.06 degrees.
MIN_RISE = 1e-3


def world_vectors(inverse: np.ndarray, v: np.ndarray) -> np.ndarray:
    """(n, 3) vectors ``v`` (generic) in world coordinates, given (n, 3, 3) linear parts of the inverse
    matrices: the solution x of inverse x = v, by cofactors (C's generic_to_world_vector)."""
    a = inverse
    c00 = a[:, 1, 1] * a[:, 2, 2] - a[:, 1, 2] * a[:, 2, 1]
    c01 = a[:, 1, 2] * a[:, 2, 0] - a[:, 1, 0] * a[:, 2, 2]
    c02 = a[:, 1, 0] * a[:, 2, 1] - a[:, 1, 1] * a[:, 2, 0]
    c10 = a[:, 0, 2] * a[:, 2, 1] - a[:, 0, 1] * a[:, 2, 2]
    c11 = a[:, 0, 0] * a[:, 2, 2] - a[:, 0, 2] * a[:, 2, 0]
    c12 = a[:, 0, 1] * a[:, 2, 0] - a[:, 0, 0] * a[:, 2, 1]
    c20 = a[:, 0, 1] * a[:, 1, 2] - a[:, 0, 2] * a[:, 1, 1]
    c21 = a[:, 0, 2] * a[:, 1, 0] - a[:, 0, 0] * a[:, 1, 2]
    c22 = a[:, 0, 0] * a[:, 1, 1] - a[:, 0, 1] * a[:, 1, 0]
    det = a[:, 0, 0] * c00 + a[:, 0, 1] * c01 + a[:, 0, 2] * c02
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    return np.stack([(c00 * x + c10 * y + c20 * z) / det, (c01 * x + c11 * y + c21 * z) / det,
                     (c02 * x + c12 * y + c22 * z) / det], axis=1)


_MESH_CODES = np.array([e.family == "mesh" for e in shapes.REGISTRY])


def lifted_points(compiled, shape_index: np.ndarray, part: np.ndarray, uv: np.ndarray, entering: np.ndarray,
                  points: np.ndarray) -> np.ndarray:
    """Where the shadow feelers of these hits start from (before the rounding offset): the hit points, lifted
    onto the smooth surface for hits on smooth mesh triangles from their outer side."""
    out = points.copy()
    mesh_rows = np.nonzero(entering & _MESH_CODES[compiled.table.kind[shape_index]])[0]
    for index in np.unique(shape_index[mesh_rows]).tolist():
        rows = mesh_rows[shape_index[mesh_rows] == index]
        prim = compiled.primitives[index]
        lift, has = prim.triangle_mesh.smooth_lift(part[rows], uv[rows, 0], uv[rows, 1])
        rows, lift = rows[has], lift[has]
        inverse = np.broadcast_to(prim.inverse[:3, :3], (len(rows), 3, 3))
        out[rows] = points[rows] + world_vectors(inverse, lift)
    return out


def geometric_normals(compiled, shape_index: np.ndarray, part: np.ndarray, directions: np.ndarray,
                      facing: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The unit world normals (n, 3) of the true surfaces hit, facing the rays (the planes of smooth mesh
    triangles), and which rows are such hits; the other rows get their ``facing`` normals, which are the
    geometric ones there (analytic shapes, flat triangles).  (shade.h's geometric_normal)"""
    out = facing.copy()
    smooth = np.zeros(len(shape_index), dtype=bool)
    mesh_rows = np.nonzero(_MESH_CODES[compiled.table.kind[shape_index]])[0]
    for index in np.unique(shape_index[mesh_rows]).tolist():
        rows = mesh_rows[shape_index[mesh_rows] == index]
        prim = compiled.primitives[index]
        generic, _, has = prim.triangle_mesh.geometric_normals(part[rows])
        world = numerics.normal_to_world(generic[has], prim.inverse[:3, :3])
        rows = rows[has]
        length = numerics.norm3(world)
        usable = length > 0.0
        rows, world = rows[usable], world[usable] / length[usable, None]
        side = np.where(numerics.dot3(world, directions[rows]) > 0.0, -1.0, 1.0)
        out[rows] = side[:, None] * world
        smooth[rows] = True
    return out, smooth


def bent_above(rays: np.ndarray, normals: np.ndarray, rows: np.ndarray) -> np.ndarray:
    """``rays`` (n, 3), where ``rows`` (n,) and where one rises less than MIN_RISE times its length above the
    plane of its unit normal, moved to rise exactly that much (its part along the plane kept) at its own
    length (shade.h's bend_above); the rest as they are."""
    rise = numerics.dot3(rays, normals)
    length = numerics.norm3(rays)
    bend = rows & (rise < MIN_RISE * length)
    if not bend.any():
        return rays
    g, lifted = normals[bend], MIN_RISE * length[bend]
    moved = (rays[bend] - rise[bend, None] * g) + lifted[:, None] * g
    out = rays.copy()
    out[bend] = moved * (length[bend] / numerics.norm3(moved))[:, None]
    return out
