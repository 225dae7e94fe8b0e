"""The polygon meshes that stand for SDL's generic shapes in Blender (pure NumPy, no bpy).

Blender draws these; the ray tracer never does: it traces the exact shape named by the object's custom
properties.  They are fine enough that the rasterised silhouette matches the traced one (a 64 x 32 UV
sphere is at most 0.12 % of its radius inside the true sphere), closed and consistently wound (outward)
so that Blender's Boolean modifier can use them, and in the generic coordinates of docs/sdl.md.

A mesh is identified by a *geometry hash* of its float32 vertex positions and its polygon topology, taken
the same way here and from a Blender mesh, so the add-on can tell whether the user has edited one.
"""
from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field
from typing import Optional

import numpy as np

from ..tracer.geometry.tessellate import tapered_cylinder_mesh, torus_mesh
from ..tracer.shapes import KINDS

#: Segments around the sphere, the cylinders and the torus ring; rings of the sphere; segments of the tube.
SEGMENTS = 64
SPHERE_RINGS = 32
TORUS_TUBE_SEGMENTS = 32
#: Half the side of the finite square that stands for SDL's infinite ``plane``.
PLANE_HALF_SIZE = 1000.0


@dataclass
class GenericMesh:
    """Polygons for Blender: vertices (V, 3), faces (tuples of vertex indices, outward winding), a smooth
    flag per face, edges to mark sharp, and optional per-corner normals (in face-corner order)."""

    vertices: np.ndarray
    faces: list[tuple[int, ...]]
    smooth: np.ndarray
    sharp_edges: list[tuple[int, int]] = field(default_factory=list)
    corner_normals: Optional[np.ndarray] = None

    @property
    def loop_vertices(self) -> np.ndarray:
        return np.fromiter((v for f in self.faces for v in f), dtype=np.int32,
                           count=sum(len(f) for f in self.faces))

    @property
    def loop_totals(self) -> np.ndarray:
        return np.array([len(f) for f in self.faces], dtype=np.int32)

    def transformed(self, linear: np.ndarray) -> "GenericMesh":
        """The mesh with its vertices (and normals) mapped by a 3x3 matrix (for shapes Blender cannot shear)."""
        linear = np.asarray(linear, dtype=np.float64)
        if np.array_equal(linear, np.eye(3)):  # exactly as it was (x @ I turns -0.0 into 0.0)
            return GenericMesh(self.vertices.copy(), list(self.faces), self.smooth.copy(), list(self.sharp_edges),
                               None if self.corner_normals is None else self.corner_normals.copy())
        normals = None
        if self.corner_normals is not None:
            normals = self.corner_normals @ np.linalg.inv(linear)
            normals /= np.maximum(np.linalg.norm(normals, axis=1, keepdims=True), 1e-300)
        faces = self.faces
        if np.linalg.det(linear) < 0:  # a mirror image turns the winding inside out
            faces = [tuple(reversed(f)) for f in faces]
            if normals is not None:
                normals = _reverse_corners(normals, self.faces)
        return GenericMesh(self.vertices @ linear.T, faces, self.smooth.copy(), list(self.sharp_edges), normals)

    def hash(self) -> str:
        return geometry_hash(self.vertices, self.loop_vertices, self.loop_totals)


def _reverse_corners(per_corner: np.ndarray, faces) -> np.ndarray:
    out, start = [], 0
    for f in faces:
        out.append(per_corner[start:start + len(f)][::-1])
        start += len(f)
    return np.concatenate(out) if out else per_corner


def geometry_hash(vertices, loop_vertices, loop_totals) -> str:
    """A digest of float32 positions and polygon topology (what Blender stores, read the same way)."""
    digest = hashlib.sha1()
    for array, dtype in ((vertices, np.float32), (loop_vertices, np.int32), (loop_totals, np.int32)):
        data = np.ascontiguousarray(np.asarray(array), dtype=dtype)
        digest.update(str(data.size).encode())
        digest.update(data.tobytes())
    return digest.hexdigest()


def _ring(count: int, radius: float, z: float) -> np.ndarray:
    angles = 2.0 * np.pi * np.arange(count) / count
    return np.column_stack([radius * np.cos(angles), radius * np.sin(angles), np.full(count, float(z))])


def sphere(segments: int = SEGMENTS, rings: int = SPHERE_RINGS) -> GenericMesh:
    """UV sphere of radius 1: poles on the z axis."""
    verts = [np.array([[0.0, 0.0, 1.0]])]
    for i in range(1, rings):
        theta = math.pi * i / rings
        verts.append(_ring(segments, math.sin(theta), math.cos(theta)))
    verts.append(np.array([[0.0, 0.0, -1.0]]))
    vertices = np.concatenate(verts)
    top, bottom = 0, len(vertices) - 1

    def at(ring: int, j: int) -> int:  # ring 1 .. rings-1
        return 1 + (ring - 1) * segments + j % segments

    faces: list[tuple[int, ...]] = [(top, at(1, j), at(1, j + 1)) for j in range(segments)]
    for i in range(1, rings - 1):
        faces += [(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)) for j in range(segments)]
    faces += [(at(rings - 1, j), bottom, at(rings - 1, j + 1)) for j in range(segments)]
    return GenericMesh(vertices, faces, np.ones(len(faces), bool))


def _box_faces(vertices: np.ndarray, planar_axes) -> list[tuple[int, ...]]:
    """Faces of a box-like vertex set: for (axis, sign), the vertices on that side, ordered anticlockwise
    seen from outside."""
    faces = []
    for axis, sign in planar_axes:
        normal = np.zeros(3)
        normal[axis] = sign
        idx = [i for i, v in enumerate(vertices) if v[axis] == sign]
        u = np.zeros(3)
        u[(axis + 1) % 3] = 1.0
        w = np.cross(normal, u)
        centre = vertices[idx].mean(axis=0)
        angle = {i: math.atan2(float((vertices[i] - centre) @ w), float((vertices[i] - centre) @ u)) for i in idx}
        faces.append(tuple(sorted(idx, key=angle.get)))
    return faces


def cube() -> GenericMesh:
    vertices = np.array([[x, y, z] for x in (-1.0, 1.0) for y in (-1.0, 1.0) for z in (-1.0, 1.0)])
    faces = _box_faces(vertices, [(a, s) for a in range(3) for s in (-1.0, 1.0)])
    return GenericMesh(vertices, faces, np.zeros(6, bool))


def square(half: float = 1.0) -> GenericMesh:
    vertices = np.array([[-half, -half, 0.0], [half, -half, 0.0], [half, half, 0.0], [-half, half, 0.0]])
    return GenericMesh(vertices, [(0, 1, 2, 3)], np.zeros(1, bool))


def plane() -> GenericMesh:
    return square(PLANE_HALF_SIZE)


def tapered_cylinder(small_radius: float, segments: int = SEGMENTS) -> GenericMesh:
    """Wall from z = 0 (radius 1) to z = 1 (radius ``small_radius``), with the base and cap discs: the
    tracer's tessellation, the wall smooth and the discs flat, the rims sharp."""
    data = tapered_cylinder_mesh(small_radius, segments)
    faces = [vertices for vertices, _ in data.faces]
    n = segments
    smooth = np.arange(len(faces)) < n  # the wall's faces come first
    sharp = [(j, (j + 1) % n) for j in range(n)]
    if small_radius != 0.0:  # (a cone's top is one apex, no rim)
        sharp += [(n + j, n + (j + 1) % n) for j in range(n)]
    return GenericMesh(np.asarray(data.vertices, dtype=np.float64), faces, smooth, sharp)


def torus(segments: int = SEGMENTS, tube_segments: int = TORUS_TUBE_SEGMENTS) -> GenericMesh:
    """The tracer's tessellation of the generic torus, smooth."""
    data = torus_mesh(segments, tube_segments)
    faces = [vertices for vertices, _ in data.faces]
    return GenericMesh(np.asarray(data.vertices, dtype=np.float64), faces, np.ones(len(faces), bool))


def from_mesh_data(mesh, smooth: bool) -> GenericMesh:
    """A tracer MeshData (polyhedra, teapot, .3vn) as polygons; with ``smooth``, its normals become
    per-corner custom normals where every face has them."""
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    faces = [tuple(int(i) for i in verts) for verts, _ in mesh.faces]
    normals = np.asarray(mesh.normals, dtype=np.float64).reshape(-1, 3)
    corner = None
    if smooth and len(normals) and all(len(n) == len(v) for v, n in mesh.faces):
        corner = normals[[int(i) for _, norms in mesh.faces for i in norms]]
        length = np.linalg.norm(corner, axis=1, keepdims=True)
        corner = np.where(length > 0, corner / np.where(length > 0, length, 1.0), 0.0)
    return GenericMesh(vertices, faces, np.full(len(faces), bool(smooth)), [], corner)


def generic_mesh(kind: str, parameters: tuple[float, ...] = (), mesh_data=None) -> GenericMesh:
    """The Blender mesh of a generic shape with these parameters (Shape.parameters): the builder of this
    module its registry entry names (ShapeKind.blender_mesh), else the tracer's tessellation, else
    ``mesh_data``, the tracer's MeshData of a polyhedron, the teapot or a ``mesh`` shape."""
    entry = KINDS[kind]
    values = entry.traced(parameters or entry.defaults)
    if entry.blender_mesh is not None:
        return globals()[entry.blender_mesh](*values)
    if entry.tessellate is not None:
        return from_mesh_data(entry.function("tessellate")(*values), smooth=True)
    if mesh_data is None:
        raise ValueError(f"the {kind} needs its mesh data")
    return from_mesh_data(mesh_data, smooth=entry.family == "mesh")


def mesh_name(kind: str, parameters: tuple[float, ...] = (), mesh_file: Optional[str] = None) -> str:
    """Name of the shared Blender mesh of one kind and parameters ("SDL sphere", "SDL taperedCylinder 0.5",
    "SDL mesh pawn.3vn")."""
    if KINDS[kind].file_argument:
        import os
        return f"SDL {kind} {os.path.basename(mesh_file or kind)}"
    return " ".join(["SDL", kind, *(f"{float(v):g}" for v in parameters)])


def stored_parameters(parameters: tuple[float, ...]):
    """What the ``sdl_param`` custom property of an object or mesh holds for these parameters: the one number
    (1.0 for a kind that takes none), or the list of them."""
    if len(parameters) <= 1:
        return float(parameters[0]) if parameters else 1.0
    return [float(v) for v in parameters]


def parameters_of(kind: str, stored) -> tuple[float, ...]:
    """The parameters of a ``kind`` whose ``sdl_param`` property holds ``stored`` (None: its defaults)."""
    entry = KINDS[kind]
    if not entry.parameters or stored is None:
        return entry.defaults
    values = [float(v) for v in stored] if hasattr(stored, "__len__") else [float(stored)]
    return tuple(values[:len(entry.parameters)]) + entry.defaults[len(values):]
