"""Scene model -> what the tracer runs: primitives with inverse matrices, CSG trees, material and light
tables, and the set of *live effects*.

Deciding here, once per scene, which effects exist (shadows, reflection, refraction, CSG, each shape
kind, textures) is what lets the tracer do no work at all for the others: the shading code branches on
``CompiledScene.effects`` once per batch, never per ray.
"""
from __future__ import annotations

import hashlib
import operator
import os
import weakref
from collections.abc import Sequence
from dataclasses import astuple, dataclass, field, replace
from functools import cached_property
from itertools import chain, repeat
from operator import attrgetter
from typing import Callable, Optional, Union

import numpy as np

from . import instances, numerics, shapes
from .batches import LeafHits
from .bulk import collector_paused, one_blas_thread
from .errors import SceneError, TracerError
from .geometry import builtin_mesh
from .intersect import analytic
from .intersect.csg import combine, sheet_to_pairs
from .intersect.hits import HitArrays
from .lights import LightTable
from .model import (CSG, FRESNEL_MODES, MESH_KINDS, POLYHEDRON_KINDS, FaceList, Material, MaterialRows, MeshData, Scene,
                    SceneObject, Shape, ShapeColumns, ShapeTable, matrices_of_affines as _matrices_of_affines,
                    parameter_rows)
from .transforms import transform_points


#: Closed analytic shapes whose normals must agree with their entering flags (ShapeKind.normals_agree).
SOLID_ANALYTIC_KINDS = tuple(e.keyword for e in shapes.REGISTRY if e.family == "analytic" and e.normals_agree)


def blocks_between(hits: HitArrays, t_min: np.ndarray, t_max: np.ndarray) -> np.ndarray:
    """(N,) bool: a hit lies between t_min and t_max with its whole error interval (a shadow feeler's blocker).

    The same rule at both ends: a feeler leaving a surface never finds that surface at its start, and one
    ending on a light that sits on a surface (a lamp on a wall, a light in the floor's plane) is not blocked
    by that surface at its end, however the hit's time rounds."""
    if hits.slots == 0:
        return np.zeros(hits.count, dtype=bool)
    inside = (hits.t - hits.error > t_min[:, None]) & (hits.t + hits.error < t_max[:, None])
    return inside.any(axis=1)


def first_after(hits: HitArrays, t_min: np.ndarray, t_max: np.ndarray) -> HitArrays:
    """The first hit per ray with t_min < t < t_max (K = 1; t = inf where there is none).

    A hit is after t_min only when its whole error interval is: a ray leaving a surface never finds that
    surface again at a t that rounding put just after its start."""
    valid = (hits.t - hits.error > t_min[:, None]) & (hits.t < t_max[:, None])
    if hits.slots == 0:
        return HitArrays.empty(hits.count, 1)
    first = np.argmax(valid, axis=1)[:, None]
    out = hits.take(first)
    out.t[~valid.any(axis=1), 0] = np.inf
    return out


def _checked_inverse(shape: Shape) -> np.ndarray:
    """The inverse of a shape's matrix, or a TracerError naming the shape if it has none."""
    where = f"{shape.source}: " if shape.source else ""
    m = shape.matrix
    if not np.all(np.isfinite(m)) or np.any(m[3] != (0, 0, 0, 1)):
        raise TracerError(f"{where}{shape.kind} has a transform that is not a finite affine matrix")
    try:
        inverse = np.linalg.inv(m)
    except np.linalg.LinAlgError:
        inverse = None
    if inverse is None or not np.all(np.isfinite(inverse)):
        raise TracerError(f"{where}{shape.kind} has a singular transform (a scale of 0?)")
    return inverse


#: The eight corners of the generic cube, for the bounding spheres of the closed-form shapes.
#: (Shared by every primitive, so read-only.)
_CORNERS = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=float)
#: The corners of each registered kind's generic box.
_BOX_CORNERS = {e.keyword: np.asarray(e.box[0]) + _CORNERS * np.asarray(e.box[1])
                for e in shapes.REGISTRY if e.box is not None}
for _constant in (_CORNERS, *_BOX_CORNERS.values()):
    _constant.setflags(write=False)


def _analytic_generic_points(shape: Shape) -> Optional[np.ndarray]:
    """Points whose hull holds a closed-form shape's generic solid (its box's corners, or what its kind's
    bounds give for its parameters), or None for the plane, polyhedra and meshes."""
    kind = shape.kind
    if kind in _BOX_CORNERS:
        return _BOX_CORNERS[kind]
    entry = shapes.KINDS[kind]
    if entry.bounds is not None:
        return entry.function("bounds")(_traced_rows([entry.traced(shape.parameters)]))[0]
    return None


def _traced_rows(values: Sequence[tuple[float, ...]]) -> np.ndarray:
    """(N, shapes.MAX_PARAMETERS) rows of values that kinds' intersections take, 0 after each row's own."""
    rows = np.zeros((len(values), shapes.MAX_PARAMETERS))
    for i, row in enumerate(values):
        rows[i, :len(row)] = row
    return rows


def _sphere_around(world: np.ndarray):
    """Bounding sphere (centre, radius) of the (K, 3) world points' box, padded by 1e-9 relatively."""
    lo, hi = world.min(axis=0), world.max(axis=0)
    center = 0.5 * (lo + hi)
    return center, float(np.linalg.norm(hi - lo) * 0.5) * (1 + 1e-9)


def _stacked_matrices(shapes: list[Shape]) -> Optional[np.ndarray]:
    """The shapes' matrices as one (N, 4, 4) array, or None if any is not a float64 4x4 array."""
    matrices = list(map(attrgetter("matrix"), shapes))
    if not matrices:
        return np.zeros((0, 4, 4))
    # (checked as sets of types, dtypes and shapes, joined by one np.concatenate: a tenth of a second less
    # for 100,000 shapes than np.stack's checks of each array)
    if (set(map(type, matrices)) != {np.ndarray} or set(map(attrgetter("dtype"), matrices)) != {np.dtype(np.float64)}
            or set(map(attrgetter("shape"), matrices)) != {(4, 4)}):
        return None
    return np.concatenate(matrices).reshape(-1, 4, 4)


def _stack_checked(shapes: Sequence[Shape]) -> np.ndarray:
    """The shapes' matrices stacked as float64 (N, 4, 4), for shapes of which some matrix is not a float64
    4x4 array: each is checked on its own, in order (with its mesh built), so that the first bad one raises
    _checked_inverse's error naming it."""
    for shape in shapes:
        _checked_inverse(shape)
        if shape.kind in MESH_KINDS:
            shared_triangle_mesh(shape.mesh)
    return np.stack([np.asarray(s.matrix, dtype=np.float64) for s in shapes]) if len(shapes) else np.zeros((0, 4, 4))


def _batched_inverses(stack: Optional[np.ndarray]) -> Optional[np.ndarray]:
    """The inverses of all the shapes' matrices (``stack``, see _stacked_matrices) from one (N, 4, 4)
    np.linalg.inv call, which gives each matrix the same LAPACK solve as a call of its own.  None if any
    matrix would fail _checked_inverse's checks (or is not a float64 4x4): then each shape is checked on its
    own, in order, so that the error names the first bad shape exactly as before."""
    if stack is None:
        return None
    if not len(stack):
        return np.zeros((0, 4, 4))
    if not (np.isfinite(stack).all() and (stack[:, 3] == (0, 0, 0, 1)).all()):
        return None
    try:
        inverses = np.linalg.inv(stack)
    except np.linalg.LinAlgError:
        return None
    return inverses if np.isfinite(inverses).all() else None


class Primitive:
    """One shape, ready to intersect world rays.

    ``inverse`` and ``bounds`` (centre, radius), when given, are what _checked_inverse and the bounding
    sphere would compute.  compile_scene makes none of these itself: it computes every primitive's numbers
    at once into a :class:`PrimitiveTable`, and its primitives are views of the table's rows, made when
    first asked for (see :meth:`of_row`)."""

    def __init__(self, shape: Shape, index: int, material_id: int, mesh_cache: Optional[dict] = None,
                 inverse: Optional[np.ndarray] = None, bounds: Optional[tuple] = None):
        self.shape = shape
        self.index = index
        self.kind = shape.kind
        self.material_id = material_id
        self.matrix = shape.matrix
        self.inverse = _checked_inverse(shape) if inverse is None else inverse
        # World normal = generic normal through the inverse-transpose; as row vectors: n_g @ inverse[:3,:3].
        self.normal_matrix = self.inverse[:3, :3]
        self._take_kind(numerics.TOLERANCES)
        #: numerics.inverse_rounding of the matrix (compile_scene fills it for all shapes at once)
        self.inverse_error: Optional[float] = None
        self._mesh = None
        self._planes = None
        if shape.kind in POLYHEDRON_KINDS:
            # deferred: the polyhedra's tables are loaded by the first scene with one, not by import tracer
            from .geometry.polyhedra import face_planes
            self._planes = face_planes(shape.kind)
        elif shape.kind in MESH_KINDS:
            # Instances of one mesh (the same MeshData) share one BVH, and so do meshes of the same content.
            cache = {} if mesh_cache is None else mesh_cache
            key = id(shape.mesh)
            if key not in cache:
                cache[key] = (shape.mesh, shared_triangle_mesh(shape.mesh))
            self._mesh = cache[key][1]
        self.center, self.radius = self._world_bounding_sphere() if bounds is None else bounds

    def _take_kind(self, tolerances: numerics.Tolerances) -> None:
        """What the shape registry says about this primitive's kind."""
        entry = shapes.KINDS[self.kind]
        self.thin = entry.thin
        self.bounded = entry.bounded
        self._entry = entry
        self._intersect = entry.function("intersect")
        self._normals_agree = entry.normals_agree
        self.tolerances = tolerances

    @classmethod
    def of_row(cls, table: "PrimitiveTable", index: int) -> "Primitive":
        """The primitive of row ``index`` of a compiled scene's table: its numbers are the table's (views
        of its arrays, no copies), so both backends read the same ones."""
        self = cls.__new__(cls)
        shape = table.shapes[index]
        self.shape, self.index, self.kind = shape, index, shape.kind
        self.table = table  # (whose rows tracer.batches traces many at once)
        self.material_id = int(table.material_ids[index])
        self.matrix = shape.matrix
        numbers = table.numbers_of(index)
        self.inverse = numbers["inverses"]
        self.normal_matrix = self.inverse[:3, :3]
        self._take_kind(table.tolerances)
        terms, sphere, box = numbers["rounding_terms"], numbers["spheres"], numbers["boxes"]
        self.inverse_error = float(terms[0])
        self._mesh = table.meshes.get(id(shape.mesh)) if shape.kind in MESH_KINDS else None
        self._planes = None
        if shape.kind in POLYHEDRON_KINDS:
            # deferred: the polyhedra's tables are loaded by the first scene with one, not by import tracer
            from .geometry.polyhedra import face_planes
            self._planes = face_planes(shape.kind)
        bounded = self.bounded
        self.center = sphere[:3] if bounded else None
        self.radius = float(sphere[3]) if bounded else np.inf
        self.__dict__["box"] = (box[:3], box[3:]) if bounded else None
        # (the cached properties' values, from the table)
        self.__dict__["generic_size"] = float(terms[1])
        linear, translation = terms[2:].tolist()
        self.__dict__["inverse_norms"] = (linear, translation)
        return self

    @classmethod
    def of_rows(cls, table: "PrimitiveTable", rows: np.ndarray) -> "Primitive":
        """Rows ``rows`` of the table, all of one kind with the same traced parameters and none a mesh, as one
        Primitive whose numbers are per ray: ray i meets primitive rows[i].  Its arithmetic is that of each
        row's own Primitive (numerics applies a matrix per ray, in the same order), so that many top-level
        primitives are traced as one batch of (ray, primitive) pairs with the same bits (tracer.batches).  The
        caller has culled the pairs by their bounding spheres: may_hit passes every ray."""
        first = cls.of_row(table, int(rows[0]))
        self = cls.__new__(cls)
        self.__dict__.update(first.__dict__)  # kind, registry entry, parameters, planes, size: every row's
        self.index = rows[:, None]
        self.material_id = self.matrix = None  # (per row: read from the table where needed)
        numbers = table.numbers_of(rows)
        self.inverse = numbers["inverses"]
        self.normal_matrix = self.inverse[:, None, :3, :3]
        terms = numbers["rounding_terms"]
        self.inverse_error = terms[:, 0][:, None]
        self.__dict__["inverse_norms"] = (terms[:, 2], terms[:, 3])
        self.center, self.radius = None, np.inf
        self.__dict__["box"] = None
        return self

    @property
    def triangle_mesh(self):
        """The :class:`tracer.intersect.mesh.TriangleMesh` of a mesh or teapot (shared by its instances), else None."""
        return self._mesh

    @property
    def face_planes(self) -> Optional[tuple[np.ndarray, np.ndarray]]:
        """A convex polyhedron's face planes (normals (F, 3), offsets (F,): n . p <= offset), else None."""
        return self._planes

    def _generic_points(self) -> Optional[np.ndarray]:
        if self._mesh is not None or self._planes is not None:
            return np.asarray(self.shape.mesh.vertices, dtype=np.float64)
        return _analytic_generic_points(self.shape)  # None for the plane

    def _world_bounding_sphere(self):
        pts = self._generic_points()
        if pts is None:
            return None, np.inf
        return _sphere_around(transform_points(self.matrix, pts))

    @cached_property
    def generic_size(self) -> float:
        """The generic shape's extent (its hit points' coordinates are of this size): the largest coordinate of
        the points its bounds are made from, 1 for the plane."""
        pts = self._generic_points()
        return float(np.max(np.abs(pts))) if pts is not None and pts.size else 1.0

    @property
    def rounding(self) -> float:
        """Relative rounding of this primitive's generic hit points: the hit computation's gamma plus the
        error of the inverse matrix itself."""
        if self.inverse_error is None:
            self.inverse_error = float(numerics.inverse_rounding(self.inverse[None], self.matrix[None])[0])
        return numerics.gamma(self.tolerances.hit_ulps) + self.inverse_error

    @cached_property
    def inverse_norms(self) -> tuple[float, float]:
        """(max row sum of |inverse[:3, :3]|, max |inverse[:3, 3]|): bound the size of a transformed origin,
        before any cancellation, as ``first * max|o| + second``."""
        return (float(np.max(np.abs(self.inverse[:3, :3]).sum(axis=1))), float(np.max(np.abs(self.inverse[:3, 3]))))

    def bound_hits(self, origins, o_generic, d_generic, hits: HitArrays) -> None:
        """Fill in the bounds of ``hits`` (generic normals still) for world rays from ``origins``: ``error``,
        the rounding of t (plus the shape's own root error, where it has one), and ``offset``, how far the
        generic point may be from the surface (the shape's residual over |n|, its first-order distance, plus
        the line's error; the C core's hit_bounds).  A mesh's triangle is flat: the line's error moves its
        crossing by that error over the rate the line crosses the triangle's own plane (its winding normal's,
        not the interpolated normal's: with that and a unit-curvature floor the bound was up to 5e8 times
        short at grazing incidence); its offset keeps the floor's bound times |d|, which is at least the
        line's error (the C core's hit_bounds).  (The caller ignores floating-point warnings.)"""
        linear, translation = self.inverse_norms
        raw_scale = linear * numerics.max_abs3(origins) + translation
        size = self.generic_size
        error = numerics.point_errors(hits.t, raw_scale, o_generic, d_generic, size, self.rounding)
        nn = numerics.dot3(hits.normal, hits.normal)
        length = np.sqrt(nn)
        mesh = self._mesh is not None
        if mesh:
            dd = numerics.dot3(d_generic, d_generic)[:, None]
            hits.bend = 2.0 * length * dd / size
        elif hits.bend is None:  # a flat face
            hits.bend = 0.0
        bound = numerics.time_errors(error, hits, d_generic, size, nn, length)
        if mesh:
            hits.offset = (hits.error + bound) * np.sqrt(dd)
            winding = self._mesh.winding_normals(hits.part)
            bound = numerics.crossing_shift(np.sqrt(numerics.dot3(winding, winding)) * (size * error),
                                            np.abs(numerics.dot3(winding, d_generic[:, None, :])), 0.0)
        else:
            hits.offset = np.where(nn > 0.0, hits.offset / length, hits.offset) + size * error
        hits.error = hits.error + bound
        hits.bend = None  # (read; take and the others need not carry it)

    def to_world(self, hits: HitArrays) -> None:
        """World normals (the C core's sums) and the offsets along them (numerics.world_offsets)."""
        world = numerics.normal_to_world(hits.normal, self.normal_matrix)
        hits.offset = numerics.world_offsets(hits.offset, hits.normal, world)
        hits.normal = world

    @cached_property
    def box(self) -> Optional[tuple[np.ndarray, np.ndarray]]:
        """The world box (lo, hi) of the points the bounding sphere is made from; None when unbounded."""
        corners = self.world_corners()
        return None if corners is None else (corners.min(axis=0), corners.max(axis=0))

    def world_corners(self) -> Optional[np.ndarray]:
        pts = self._generic_points()
        return None if pts is None else transform_points(self.matrix, pts)

    def generic_hits(self, o: np.ndarray, d: np.ndarray) -> HitArrays:
        """Every crossing of the generic lines: the kind's registered intersection, given what its family
        takes (tracer/shapes.py, ShapeKind)."""
        if self._planes is not None:
            return self._intersect(o, d, *self._planes)
        if self._mesh is not None:
            return self._intersect(o, d, self._mesh)
        entry = self._entry
        budget = (self.tolerances,) if entry.budget else ()
        return self._intersect(o, d, *entry.traced(self.shape.parameters), *budget)

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> HitArrays:
        """All hits along the whole world lines, world normals, ``shape`` = this primitive's index."""
        n = origins.shape[0]
        candidates = self.may_hit(origins, directions)
        idx = np.nonzero(candidates)[0]
        o, d = self.to_generic(origins[idx], directions[idx])
        # Move each generic origin to the line's point nearest the generic centre: every shape's
        # equation then has O(1) coefficients, however far away the ray started.
        with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
            shift = -numerics.dot3(o, d) / numerics.dot3(d, d)
            shift = np.where(np.isfinite(shift), shift, 0.0)
            centred = o + shift[:, None] * d
            local = self.generic_hits(centred, d)
            if self._normals_agree:
                analytic.agree_with_crossing(local, d)
            local.t = local.t + shift[:, None]
            self.bound_hits(origins[idx], centred, d, local)
            self.to_world(local)
        np.copyto(local.shape, self.index, where=np.isfinite(local.t))  # (an index per ray: of_rows)
        if self.thin:
            local = sheet_to_pairs(local)
        if idx.size == n:
            return local
        full = HitArrays.empty(n, local.slots)
        for name in ("t", "entering", "normal", "part", "uv", "shape", "inside_at_start", "error", "offset"):
            getattr(full, name)[idx] = getattr(local, name)
        return full

    def first_hit(self, origins, directions, t_min, t_max) -> HitArrays:
        """The first hit with t_min < t < t_max per ray (K = 1); meshes prune with their BVH."""
        if self._mesh is None:
            return first_after(self.intersect(origins, directions), t_min, t_max)
        n = origins.shape[0]
        idx = np.nonzero(self.may_hit(origins, directions))[0]
        out = HitArrays.empty(n, 1)
        if idx.size:
            o, d = self.to_generic(origins[idx], directions[idx])
            local = self._mesh.closest_hits(o, d, t_min[idx], t_max[idx])
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                self.bound_hits(origins[idx], o, d, local)
                self.to_world(local)
            local.shape[np.isfinite(local.t)] = self.index
            for name in ("t", "entering", "normal", "part", "uv", "shape", "error", "offset"):
                getattr(out, name)[idx] = getattr(local, name)
        return out

    def occludes(self, origins, directions, t_min, t_max) -> np.ndarray:
        """Whether anything of this shape lies on each ray between t_min and t_max, with its whole error
        interval (shadow feelers, see blocks_between).  A mesh is asked for any hit first, and for the
        intervals of its hits only where the feeler ends within its bounding sphere, where a light may sit on
        its surface (a light on a mesh's face shadowed 12.7 % of a room's pixels; the C core's prim_occludes)."""
        if self._mesh is None:
            return blocks_between(self.intersect(origins, directions), t_min, t_max)
        blocked = np.zeros(origins.shape[0], dtype=bool)
        idx = np.nonzero(self.may_hit(origins, directions))[0]
        if idx.size:
            o, d = self.to_generic(origins[idx], directions[idx])
            blocked[idx] = self._mesh.any_hit(o, d, t_min[idx], t_max[idx])
            ends = origins[idx] + t_max[idx, None] * directions[idx] - self.center
            near = blocked[idx] & (numerics.dot3(ends, ends) <= self.radius * self.radius)
            if near.any():
                rows = idx[near]
                blocked[rows] = self.mesh_blocks_between(origins[rows], o[near], d[near], t_min[rows], t_max[rows])
        return blocked

    def mesh_blocks_between(self, origins, o, d, t_min, t_max) -> np.ndarray:
        """Which world rays from ``origins`` (generic o + t d) meet this mesh with a hit whose whole error
        interval lies between t_min and t_max (blocks_between).  Hits are taken first to last: one whose
        interval reaches t_max ends the search, one that reaches t_min is passed (the C core's
        mesh_blocks_between)."""
        blocked = np.zeros(len(o), dtype=bool)
        lower, todo = t_min.copy(), np.arange(len(o))
        while todo.size:
            h = self._mesh.closest_hits(o[todo], d[todo], lower[todo], t_max[todo])
            with np.errstate(invalid="ignore", divide="ignore", over="ignore"):
                self.bound_hits(origins[todo], o[todo], d[todo], h)
            t, error = h.t[:, 0], h.error[:, 0]
            before_end = np.isfinite(t) & (t + error < t_max[todo])
            after_start = before_end & (t - error > t_min[todo])
            blocked[todo[after_start]] = True
            onward = before_end & ~after_start
            lower[todo[onward]] = t[onward]
            todo = todo[onward]
        return blocked

    def to_generic(self, origins, directions):
        return numerics.affine_points(self.inverse, origins), numerics.linear_vectors(self.inverse, directions)

    def may_hit(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Rays whose line passes within the bounding sphere (all rays for unbounded shapes)."""
        return numerics.lines_near_spheres(self.center, self.radius, origins, directions)


class CSGNode:
    def __init__(self, op: str, left: "Node", right: "Node"):
        self.op = op
        self.left = left
        self.right = right
        self.thin = False
        self.bounded = left.bounded and (op != "union" or right.bounded)
        self.center, self.radius = self._bound()

    def _bound(self):
        """The bounding sphere round the node's box (boolean_box of its children's): made from boxes, not
        from the children's spheres, it does not grow with the nesting (a sphere round the box of two
        spheres is up to sqrt(3) times larger than they are: 2,000 nested unions overflowed to inf)."""
        self.box = boolean_box(self.op, self.left.box, self.right.box)
        if self.box is None:
            return None, np.inf
        return _sphere_around(np.stack(self.box))

    def leaves(self):
        """The primitives under this node, left to right (without recursion, as everywhere a tree is walked:
        booleans read from a file may nest deeper than Python's stack)."""
        todo = [self.right, self.left]
        while todo:
            node = todo.pop()
            if isinstance(node, CSGNode):
                todo += (node.right, node.left)
            else:
                yield node

    def may_hit(self, origins, directions):
        return numerics.lines_near_spheres(self.center, self.radius, origins, directions)

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> HitArrays:
        known = LeafHits(list(self.leaves()), origins, directions)

        def hits_of(prim: Primitive) -> HitArrays:
            hits = known.pop(prim)
            return prim.intersect(origins, directions) if hits is None else hits

        return fold_tree(self, hits_of, lambda node, left, right: combine(node.op, left, right))


    def first_hit(self, origins, directions, t_min, t_max) -> HitArrays:
        return first_after(self.intersect(origins, directions), t_min, t_max)

    def occludes(self, origins, directions, t_min, t_max) -> np.ndarray:
        return blocks_between(self.intersect(origins, directions), t_min, t_max)


Node = Union[Primitive, CSGNode]


def boolean_box(op: str, left, right):
    """The world box (lo, hi) that holds a boolean's solid, from its operands' boxes (None: unbounded)."""
    if op == "union":
        return None if left is None or right is None else (np.minimum(left[0], right[0]),
                                                           np.maximum(left[1], right[1]))
    if op == "intersection":
        if left is None or right is None:
            return left if right is None else right
        return np.maximum(left[0], right[0]), np.minimum(left[1], right[1])
    return left  # difference: inside the left solid


def fold_tree(root, leaf: Callable, join: Callable):
    """Evaluate a tree of booleans bottom-up without recursion: ``leaf(primitive)`` for each leaf, left to
    right, and ``join(node, left_value, right_value)`` for each boolean once its children are done.  Works
    for compiled trees (CSGNode) and for the model's (tracer.model.CSG) alike."""
    if not isinstance(root, (CSG, CSGNode)):
        return leaf(root)
    values: list = []
    todo: list = [(root, False)]
    while todo:
        node, children_done = todo.pop()
        if not isinstance(node, (CSG, CSGNode)):
            values.append(leaf(node))
        elif children_done:
            right = values.pop()
            values.append(join(node, values.pop(), right))
        else:
            todo += ((node, True), (node.right, False), (node.left, False))
    return values[0]


#: The deepest nesting of booleans any backend traces (tracer.backend refuses deeper trees, for every backend).
#: The C core evaluates a boolean tree recursively, about 100 bytes of a worker's stack per level; the NumPy
#: path walks it iteratively but its time grows with pixels x depth (5,000 levels at 64x48: 48 s), so a deeper
#: tree (only ever seen in generated or hostile files) is refused up front rather than traced for hours.
MAX_CSG_DEPTH = 2000


def boolean_depth(root) -> int:
    """How deeply booleans nest in ``root`` (0 for a primitive), for a compiled or a model tree."""
    return fold_tree(root, lambda _: 0, lambda _, left, right: 1 + max(left, right))


_COLOR_FIELDS = ("ambient", "diffuse", "specular", "emissive")
_NUMBER_FIELDS = ("specular_exponent", "specular_fraction", "surface_roughness", "reflectivity", "transparency",
                  "speed_of_light")


@dataclass
class MaterialTable:
    """Materials as arrays indexed by material id (so shading gathers per ray)."""

    materials: Sequence[Material]  # a list, or a MaterialRows
    ambient: np.ndarray = field(init=False)
    diffuse: np.ndarray = field(init=False)
    specular: np.ndarray = field(init=False)
    emissive: np.ndarray = field(init=False)
    specular_exponent: np.ndarray = field(init=False)
    specular_fraction: np.ndarray = field(init=False)
    surface_roughness: np.ndarray = field(init=False)
    reflectivity: np.ndarray = field(init=False)
    transparency: np.ndarray = field(init=False)
    speed_of_light: np.ndarray = field(init=False)
    #: The texture number (0: none).
    texture: np.ndarray = field(init=False)
    #: The Material.fresnel mode's index in FRESNEL_MODES, and the tint (a metal's F0).
    fresnel: np.ndarray = field(init=False)
    fresnel_tint: np.ndarray = field(init=False)

    def __post_init__(self) -> None:
        # A few thousand materials at a time (they stay in the cache while each of their fields is read:
        # a million scattered objects read once per field would be a cache miss per field), a field at a
        # time: either the one object they all hold is filled in (materials mostly differ in a colour or two;
        # the rest is the object the reader's defaults or state gave them all) or np.fromiter reads them.
        if isinstance(self.materials, MaterialRows):  # (columns already: a million materials read as rows)
            for name in _COLOR_FIELDS + _NUMBER_FIELDS + ("texture",):
                setattr(self, name, self.materials.column(name))
            self.fresnel = np.zeros(len(self.materials), dtype=np.int32)  # (rows keep SDL's materials only)
            self.fresnel_tint = np.ones((len(self.materials), 3))
            return
        n = len(self.materials)
        for name in _COLOR_FIELDS:
            setattr(self, name, np.empty((n, 3)))
        for name in _NUMBER_FIELDS:
            setattr(self, name, np.empty(n))
        self.texture = np.empty(n, dtype=np.int64)
        for start in range(0, n, _MATERIALS_AT_ONCE):
            rows = slice(start, min(n, start + _MATERIALS_AT_ONCE))
            materials = self.materials[rows]
            for name in (*_COLOR_FIELDS, *_NUMBER_FIELDS, "texture"):
                values = list(map(attrgetter(name), materials))
                column = getattr(self, name)
                if all(map(operator.is_, values, repeat(values[0]))):
                    column[rows] = values[0]
                elif name in _COLOR_FIELDS:
                    column[rows] = np.fromiter(chain.from_iterable(values), float, 3 * len(values)).reshape(-1, 3)
                else:
                    column[rows] = np.fromiter(values, column.dtype, len(values))
        self._fresnel_columns()

    def _fresnel_columns(self) -> None:
        """Material.fresnel and fresnel_tint, which only materials made for Blender scenes change from their
        defaults (looked at one by one only where some material does)."""
        n = len(self.materials)
        self.fresnel = np.zeros(n, dtype=np.int32)
        self.fresnel_tint = np.ones((n, 3))
        modes = list(map(attrgetter("fresnel"), self.materials))
        tints = list(map(attrgetter("fresnel_tint"), self.materials))
        default = Material()  # (its values are the very objects every material has that keeps them)
        if all(map(operator.is_, modes, repeat(default.fresnel))) and all(
                map(operator.is_, tints, repeat(default.fresnel_tint))):
            return
        self.fresnel[:] = [FRESNEL_MODES.index(mode) for mode in modes]
        self.fresnel_tint[:] = tints

    def put(self, material: Material, row: Optional[int] = None) -> int:
        """Write ``material`` into ``row`` (None: a new row at the end, every array then a new one, longer by
        one); returns the row (tracer.edit)."""
        if not isinstance(self.materials, list):
            self.materials = list(self.materials)
        if row is None:
            row = len(self.materials)
            self.materials.append(material)
            for name in (*_COLOR_FIELDS, *_NUMBER_FIELDS, "texture", "fresnel", "fresnel_tint"):
                column = getattr(self, name)
                setattr(self, name, np.concatenate([column, np.zeros((1,) + column.shape[1:], column.dtype)]))
        else:
            self.materials[row] = material
        for name in (*_COLOR_FIELDS, *_NUMBER_FIELDS, "texture", "fresnel_tint"):
            getattr(self, name)[row] = getattr(material, name)
        self.fresnel[row] = FRESNEL_MODES.index(material.fresnel)
        return row


#: Materials read at a time by MaterialTable (their objects stay in the cache while each field is read).
_MATERIALS_AT_ONCE = 8192


@dataclass
class CompiledScene:
    scene: Scene
    objects: Sequence[Node]  # (a CompiledObjects from compile_scene)
    primitives: Sequence[Primitive]  # (a PrimitiveList from compile_scene)
    materials: MaterialTable
    light_positions: np.ndarray  # (L, 3)
    light_colors: np.ndarray  # (L, 3)
    effects: frozenset[str]
    #: Every light's numbers (tracer.lights.LightTable; its position and color are the two above).
    lights: Optional["LightTable"] = None
    textures: Optional[object] = None  # tracer.textures.TextureSet when the scene uses textures
    tolerances: numerics.Tolerances = field(default_factory=lambda: numerics.TOLERANCES)
    #: All primitives' numbers as arrays (what ``primitives`` are views of)
    table: Optional["PrimitiveTable"] = None

    @property
    def settings(self):
        return self.scene.settings


class PrimitiveTable:
    """Every primitive of a compiled scene as stacked arrays, row i for primitive i (the shapes in
    iter_shapes order over the scene's objects): what the NumPy path's Primitive objects read (each a view of
    its row, made only when asked for) and what flatten.py hands to the C core, computed once for all.

    ``inverses`` (N, 4, 4); ``inverse_error`` (N,) (numerics.inverse_rounding); ``inverse_norms`` (N, 2)
    (Primitive.inverse_norms); ``generic_size`` (N,) (these three: the columns of ``rounding_terms`` (N, 4),
    inverse error, generic size, the two norms); ``spheres`` (N, 4), the world bounding spheres'
    centres and radii (radius inf and centre 0 for unbounded shapes; ``centers`` and ``radii`` are views of
    it); ``boxes`` (N, 6), world boxes (lo, hi) the spheres are made round (of the generic box's corners, a
    polyhedron's vertices; for a mesh, MeshBound.world_box, which holds its vertices exactly; not padded,
    meaningless for unbounded shapes); ``material_ids`` (N,);
    ``kind`` (N,), the index of the shape's kind in shapes.REGISTRY; ``parameters`` (N,
    shapes.MAX_PARAMETERS), the values each kind's intersection takes (ShapeKind.traced: its parameters, or
    its fixed values; 0 after them); ``meshes``: the TriangleMesh of each mesh by the id of
    its MeshData.  The matrices themselves are the shapes' own (not kept twice)."""

    def __init__(self, shapes: Sequence[Shape], kind: np.ndarray, parameters: np.ndarray,
                 matrices: Optional[np.ndarray], material_ids: np.ndarray):
        """``shapes``: a list of Shapes, or a _RowShapes that makes them from a ShapeTable's rows when asked
        (the table is then compiled without making any); ``kind`` (N,) their kind codes; ``parameters``
        (N, shapes.MAX_PARAMETERS) their Shape.parameters (ShapeTable.parameters); ``matrices``: (N, 4, 4)
        stacked (see _stacked_matrices) or a table's (N, 12) affines, None when some matrix is not a float64
        4x4."""
        n = len(shapes)
        self._take_rows(shapes, kind, material_ids)
        if matrices is None:  # (a matrix that is not a float64 4x4: _checked_inverse says which, or copes)
            matrices = _stack_checked(shapes)
        self._matrices = matrices
        self.inverses = np.empty((n, 4, 4))
        self.rounding_terms = np.empty((n, 4))
        self.rounding_terms[:, 1] = 1.0
        self._rounding_views()
        self.spheres = np.zeros((n, 4))
        self.spheres[:, 3] = np.inf
        self.centers, self.radii = self.spheres[:, :3], self.spheres[:, 3]
        self.boxes = np.zeros((n, 6))
        for rows in row_chunks(n):  # (each chunk's matrices made once, for all that is computed from them)
            self._fill_rows(rows, self.matrix_rows(rows))
        for mesh, _ in self.mesh_groups():
            self._build_mesh(mesh)
        self.parameters = _traced_parameters(self.kind, parameters)
        self._fill_sizes_and_bounds()
        self._matrices = None  # (the shapes' or the table's own: not kept twice)

    def _take_rows(self, shapes: Sequence[Shape], kind: np.ndarray, material_ids: np.ndarray) -> None:
        """What every table keeps of its rows as given: the shapes, kinds and material ids; the tolerances;
        no mesh built yet."""
        self.shapes = shapes
        self.tolerances = numerics.TOLERANCES
        self.material_ids = material_ids
        self.kind = np.asarray(kind, dtype=np.int16)
        self.meshes: dict[int, object] = {}
        self._mesh_owners: dict[int, MeshData] = {}

    def _fill_rows(self, rows, matrix: np.ndarray) -> None:
        """Inverses, their rounding and norms, and the bounds of the kinds with a fixed generic box, of
        ``rows`` (a slice or an index array) whose matrices are ``matrix``: each row's numbers depend on
        its own matrix alone, computed the same whichever rows come with it."""
        inverse = _batched_inverses(matrix)
        if inverse is None:  # some matrix fails the checks: find the first, in order, for its message
            inverse = self._checked_inverses(rows)
        self.inverses[rows] = inverse
        self.inverse_error[rows] = numerics.inverse_rounding(inverse, matrix)
        # (the sums in Primitive's order: rows of three, left to right; spelt out, as NumPy's
        # reductions over axes of three take several times longer)
        linear, translation = np.abs(inverse[:, :3, :3]), np.abs(inverse[:, :3, 3])
        sums = linear[:, :, 0] + linear[:, :, 1] + linear[:, :, 2]
        self.inverse_norms[rows, 0] = np.maximum(np.maximum(sums[:, 0], sums[:, 1]), sums[:, 2])
        self.inverse_norms[rows, 1] = np.maximum(np.maximum(translation[:, 0], translation[:, 1]),
                                                 translation[:, 2])
        self._bound_generic_boxes(rows, matrix)

    def refill(self, rows: np.ndarray, shapes: Sequence[Shape]) -> None:
        """Put these Shapes (matrices checked) in ``rows`` (sorted indices) and compute every number of those
        rows from them: kind, taper, mesh, inverse, bounds; the numbers a compile of the shapes from scratch
        gives, bit for bit.  (Material ids are the caller's.)"""
        index = rows.tolist()
        old_meshes = [self.shapes[i].mesh for i in index]
        for i, shape in zip(index, shapes):
            self.shapes[i] = shape
        old_kinds = self.kind[rows].copy()
        self.kind[rows] = [_KIND_INDEX[s.kind] for s in shapes]
        if "kind_counts" in self.__dict__:
            np.subtract.at(self.kind_counts, old_kinds, 1)
            np.add.at(self.kind_counts, self.kind[rows], 1)
        self.parameters[rows] = _traced_parameters(self.kind[rows], parameter_rows([s.parameters for s in shapes]))
        mesh_codes = list(_MESH_CODES)
        if np.isin(old_kinds, mesh_codes).any() or np.isin(self.kind[rows], mesh_codes).any():
            self.__dict__.pop("_mesh_groups", None)
            if any(a is not b.mesh for a, b in zip(old_meshes, shapes)):
                self._prune_meshes()
            for shape in shapes:
                if shape.kind in MESH_KINDS:
                    self._build_mesh(shape.mesh)
        # (the defaults a compile starts every row from: what an unbounded kind keeps)
        self.generic_size[rows], self.spheres[rows], self.boxes[rows] = 1.0, (0.0, 0.0, 0.0, np.inf), 0.0
        for part in row_chunks(len(rows)):
            self._fill_rows(rows[part], self.matrix_rows(rows[part]))
        self._fill_sizes_and_bounds(rows)

    def resize(self, keep: np.ndarray, added: list[Shape], added_material_ids: np.ndarray) -> None:
        """Keep the rows where ``keep`` is true (in order) and append rows for the ``added`` shapes (matrices
        checked) with these material ids, computed as refill computes them.  Every array is a new one."""
        kept = np.flatnonzero(keep)
        delete_positions(self.shapes, np.flatnonzero(~keep).tolist())
        self.shapes.extend(added)
        extra = len(added)

        def grown(array: np.ndarray, fill=0) -> np.ndarray:
            out = np.empty((len(kept) + extra,) + array.shape[1:], dtype=array.dtype)
            out[:len(kept)] = array[kept]
            out[len(kept):] = fill
            return out

        self.material_ids = np.concatenate([self.material_ids[kept], np.asarray(added_material_ids, np.int32)])
        self.kind = grown(self.kind)
        self.parameters = grown(self.parameters, 0.0)
        self.inverses = grown(self.inverses)
        self.rounding_terms = grown(self.rounding_terms, (0.0, 1.0, 0.0, 0.0))
        self._rounding_views()
        self.spheres = grown(self.spheres)
        self.centers, self.radii = self.spheres[:, :3], self.spheres[:, 3]
        self.boxes = grown(self.boxes)
        self.__dict__.pop("kind_counts", None)
        self.__dict__.pop("_mesh_groups", None)
        self._prune_meshes()
        if extra:
            self.refill(np.arange(len(kept), len(kept) + extra), self.shapes[len(kept):])

    def _rounding_views(self) -> None:
        """inverse_error, generic_size and inverse_norms as the columns of rounding_terms (what the C core
        reads of each primitive, SceneDesc.prim_rounding: one table, not a copy beside these)."""
        self.inverse_error, self.generic_size = self.rounding_terms[:, 0], self.rounding_terms[:, 1]
        self.inverse_norms = self.rounding_terms[:, 2:]

    def _prune_meshes(self) -> None:
        """Forget the built meshes no row holds any longer (kept, an id freed could name another mesh later)."""
        used = {id(mesh) for mesh, _ in self.mesh_groups()}
        for gone in [k for k in self.meshes if k not in used]:
            del self.meshes[gone]
            self._mesh_owners.pop(gone, None)

    def __len__(self) -> int:
        return len(self.shapes)

    def numbers_of(self, rows, names=None) -> dict[str, np.ndarray]:
        """The inverses, rounding terms, spheres and boxes (or those ``names`` of them) of these rows (an
        index: views of its rows; or an index array)."""
        return {name: getattr(self, name)[rows] for name in names or _NUMBERS}

    def primitives_of_rows(self, rows: np.ndarray) -> Primitive:
        """Rows of one kind and parameters as one Primitive with numbers per ray (Primitive.of_rows)."""
        return Primitive.of_rows(self, rows)

    def matrix_rows(self, rows) -> np.ndarray:
        """The (k, 4, 4) matrices of these rows (a slice or an index array)."""
        m = self._matrices
        if m is None:  # (compiled: the shapes' own, as tracer.edit refills rows from them)
            shapes = self.shapes
            return np.stack([np.asarray(shapes[i].matrix, dtype=np.float64)
                             for i in np.arange(len(self))[rows].tolist()]).reshape(-1, 4, 4)
        return m[rows] if m.ndim == 3 else _matrices_of_affines(m[rows])

    def _checked_inverses(self, rows: slice) -> np.ndarray:
        """The inverses of a chunk of rows one by one, as Primitive computes them: the first bad matrix
        raises _checked_inverse's error naming its shape.  (Meshes are built on the way, in order, as
        they were when every shape was checked this way: an earlier bad mesh is still reported first.)"""
        for mesh, mesh_rows in self.mesh_groups():
            if mesh_rows.size and mesh_rows[0] < rows.start:
                self._build_mesh(mesh)
        out = np.empty((rows.stop - rows.start, 4, 4))
        for k, i in enumerate(range(rows.start, rows.stop)):
            shape = self.shapes[i]
            out[k] = _checked_inverse(shape)
            if shape.kind in MESH_KINDS:
                self._build_mesh(shape.mesh)
        return out

    def rows(self, kinds) -> np.ndarray:
        """The rows of the shapes of these kinds (SDL keywords), in order."""
        codes = [_KIND_INDEX[k] for k in kinds]
        if not self.kind_counts[codes].any():  # (no pass over a million rows for a kind that has none)
            return np.zeros(0, dtype=np.int64)
        return np.flatnonzero(np.isin(self.kind, codes))

    def kinds_present(self) -> set[str]:
        """The SDL kinds of the rows."""
        return {_KEYWORDS[code] for code in np.flatnonzero(self.kind_counts).tolist()}

    @cached_property
    def kind_counts(self) -> np.ndarray:
        """How many rows each kind code has."""
        return np.bincount(self.kind, minlength=len(shapes.REGISTRY))

    def mesh_of(self, i: int) -> Optional[MeshData]:
        """The MeshData of row i (None for the closed-form kinds)."""
        shapes = self.shapes
        return shapes.mesh_of(i) if isinstance(shapes, _RowShapes) else shapes[i].mesh

    def mesh_groups(self) -> list[tuple[MeshData, np.ndarray]]:
        """(mesh, rows) of each mesh the mesh-kind rows (teapots, meshes) hold: rows of one MeshData
        together, in order of first use."""
        kept = self.__dict__.get("_mesh_groups")
        if kept is None:
            kept = self.__dict__["_mesh_groups"] = self._groups(MESH_KINDS)
        return kept

    def _groups(self, kinds) -> list[tuple[MeshData, np.ndarray]]:
        """(mesh, rows) of the rows of these kinds, a group per MeshData object, in order of first use."""
        rows = self.rows(kinds)
        if isinstance(self.shapes, _RowShapes):  # (a table's rows of a kind share its built-in mesh or hold
            # one of the table's meshes: a group per kind and mesh number, in order of first use)
            columns = self.shapes.columns
            own = columns.mesh_ids[rows] if columns.mesh_ids is not None else np.full(len(rows), -1)
            if len(rows) and (own == own[0]).all() and (self.kind[rows] == self.kind[rows[0]]).all():
                return [(self.shapes.mesh_of(int(rows[0])), rows)]  # (one mesh: no sort of a million rows)
            group = self.kind[rows].astype(np.int64) * (len(columns.meshes) + 1) + (own + 1)
            values, first, which = np.unique(group, return_index=True, return_inverse=True)
            members = rows[np.argsort(which.reshape(-1), kind="stable")]  # (each group's rows, in order)
            ends = np.cumsum(np.bincount(which.reshape(-1), minlength=len(values)))
            out = []
            for k in np.argsort(first).tolist():
                chosen = members[(ends[k - 1] if k else 0):ends[k]]
                out.append((self.shapes.mesh_of(int(chosen[0])), chosen))
            return out
        groups: dict[int, tuple[MeshData, list]] = {}
        for i in rows.tolist():
            mesh = self.shapes[i].mesh
            groups.setdefault(id(mesh), (mesh, []))[1].append(i)
        return [(mesh, np.array(members, dtype=np.int64)) for mesh, members in groups.values()]

    def _build_mesh(self, mesh: MeshData) -> None:
        if id(mesh) not in self.meshes:
            self.meshes[id(mesh)] = shared_triangle_mesh(mesh)
            self._mesh_owners[id(mesh)] = mesh  # (its id names it for as long as the entry is kept)

    def _fill_sizes_and_bounds(self, subset: Optional[np.ndarray] = None) -> None:
        """generic_size and the bounding spheres of the kinds without a fixed generic box (those are done a
        chunk at a time with the inverses): per chunk of a kind whose bounds depend on its parameters, and
        per mesh (or polyhedron vertex set) with its instances.  Of every row, or of the rows in ``subset``
        (sorted indices)."""
        for kinds, bounds in _PARAMETER_BOUNDS:
            rows = self.rows(kinds)
            if subset is not None:
                rows = np.intersect1d(rows, subset)
            for part in row_chunks(rows.size):
                points = bounds(self.parameters[rows[part]])
                self.generic_size[rows[part]] = np.abs(points).reshape(len(points), -1).max(axis=1)
                self._bound(rows[part], points)
        groups: dict = {}
        if subset is None:
            vertex_rows = self._groups(POLYHEDRON_KINDS) + self.mesh_groups()
        else:  # (the subset's rows that hold vertices, a group per mesh object)
            vertex_rows = {}
            for i in subset[_HAS_VERTICES[self.kind[subset]]].tolist():
                mesh = self.mesh_of(i)
                vertex_rows.setdefault(id(mesh), (mesh, []))[1].append(i)
            vertex_rows = [(mesh, np.array(members, dtype=np.int64)) for mesh, members in vertex_rows.values()]
        for mesh, rows in vertex_rows:
            if len(rows) and self.kind[rows[0]] in _MESH_CODES:  # (a mesh: bounded from its own box and sphere)
                self._bound_mesh_instances(mesh, rows)
                continue
            vertices = np.asarray(mesh.vertices, dtype=np.float64)
            # (polyhedra read elsewhere may each have a MeshData of their own: the same vertices, grouped by
            # their bytes)
            groups.setdefault(vertices.tobytes(), (vertices, []))[1].append(rows)
        for vertices, rows in [(vertices, np.sort(np.concatenate(rows))) for vertices, rows in groups.values()]:
            self.generic_size[rows] = float(np.max(np.abs(vertices))) if vertices.size else 1.0
            # (a mesh without vertices has no surface: its bounds are a point at its origin)
            points = vertices.reshape(-1, 3) if vertices.size else np.zeros((1, 3))
            per_chunk = max(1, _CHUNK // max(1, len(points)))
            for start in range(0, len(rows), per_chunk):
                self._bound(rows[start:start + per_chunk], points)

    def _bound_mesh_instances(self, mesh: MeshData, rows: np.ndarray) -> None:
        """generic_size, world boxes and bounding spheres of the instances of one mesh (``rows``) from the
        mesh's generic box and bounding sphere (MeshBound, made once per mesh content): a few numbers per
        instance, however many vertices the mesh has (carrying every vertex to the world took 23 CPU seconds
        for 10^5 instances of a 10^4-triangle mesh)."""
        bound = mesh_bound(mesh, self.meshes.get(id(mesh)))
        self.generic_size[rows] = bound.generic_size
        for part in row_chunks(len(rows)):
            m = self.matrix_rows(rows[part])
            lo, hi = bound.world_box(m[:, :3, :3], m[:, :3, 3])
            self._keep_bounds(rows[part], lo, hi)

    def _bound_generic_boxes(self, rows, matrix: np.ndarray) -> None:
        """generic_size, world boxes and bounding spheres of the chunk's rows whose kind has a fixed generic
        box (``matrix``: the chunk's matrices).  Each world bound is the sum of the extreme terms, in the
        order of the product (matrix row . corner, then the translation): the extreme of that sum over the
        box's corners, since rounding is monotonic, without carrying the 8 corners through."""
        codes = self.kind[rows]
        has_box = _HAS_BOX[codes]
        every = bool(has_box.all())
        local = None if every else np.flatnonzero(has_box)
        if not every and not local.size:
            return
        linear = matrix[:, :3, :3] if every else matrix[local, :3, :3]
        translation = matrix[:, :3, 3] if every else matrix[local, :3, 3]
        codes = codes if every else codes[local]
        at_lo = linear * _BOX_LO[codes][:, None, :]  # (k, 3, 3): [r, j] = matrix[r, j] * corner j
        at_hi = linear * _BOX_HI[codes][:, None, :]
        low, high = np.minimum(at_lo, at_hi), np.maximum(at_lo, at_hi)
        lo = low[:, :, 0] + low[:, :, 1] + low[:, :, 2] + translation
        hi = high[:, :, 0] + high[:, :, 1] + high[:, :, 2] + translation
        if isinstance(rows, slice):
            where = np.arange(rows.start, rows.stop) if every else rows.start + local
        else:
            where = rows if every else rows[local]
        self.generic_size[where] = _BOX_SIZE[codes]
        self._keep_bounds(where, lo, hi)

    def _keep_bounds(self, rows, lo: np.ndarray, hi: np.ndarray) -> None:
        """World boxes (lo, hi) of these rows, and the bounding spheres round them (radius padded by 1e-9
        relatively, as _sphere_around does)."""
        self.boxes[rows, :3], self.boxes[rows, 3:] = lo, hi
        self.centers[rows] = 0.5 * (lo + hi)
        extent = hi - lo
        self.radii[rows] = np.sqrt(np.einsum("ij,ij->i", extent, extent)) * 0.5 * (1 + 1e-9)

    def _bound(self, rows: np.ndarray, points: np.ndarray) -> None:
        """World boxes and bounding spheres of ``rows`` whose generic solids lie in the hull of ``points``
        ((K, 3) for all, or (len(rows), K, 3)), carried to the world by one stacked product: what
        transform_points and _sphere_around give, to rounding in the last place (which the radius's 1e-9
        padding covers)."""
        for part in row_chunks(len(rows)):
            m = self.matrix_rows(rows[part])
            p = points if points.ndim == 2 else points[part]
            world = p @ m[:, :3, :3].transpose(0, 2, 1) + m[:, None, :3, 3]
            self._keep_bounds(rows[part], world.min(axis=1), world.max(axis=1))



class InstancedTable(PrimitiveTable):
    """The PrimitiveTable of a ShapeTable whose matrices are single precision (Blender's): its mesh rows are
    *instance rows* (tracer.instances), which hold no inverse, rounding or bounds of their own but their
    float32 affine (the scene's row, not copied) and their world box in single precision (``object_boxes``,
    what the C core's hierarchy is built from); both backends compute the rest from those when asked, the
    same way.  10^5 instances of a mesh then cost ~30 compiled bytes each instead of 248.

    ``slot`` (N,) int32: each row's index into ``stored``, the PrimitiveTable of the other rows (analytic
    shapes, and any mesh row whose cofactor inverse or box is not finite or whose matrix LAPACK refuses), or
    -1 for an instance row.  ``object_boxes`` (N, 6) float32: every row's padded world box rounded outward
    (flatten's object boxes).  The NumPy path reads the numbers of the rows it asks for (numbers_of), and
    every row's as a PrimitiveTable's (``inverses``, ``rounding_terms``, ``spheres``, ``boxes`` and their
    views), made for all rows at once, past _ROWS_ALONE rows asked for one by one.  Never edited in place:
    tracer.edit makes a table into Shapes first."""

    def __init__(self, shapes: "_RowShapes", kind: np.ndarray, parameters: np.ndarray, material_ids: np.ndarray):
        columns = shapes.columns
        n = len(shapes)
        self._take_rows(shapes, kind, material_ids)
        self._asked = 0  # (rows whose numbers numbers_of computed alone)
        self.affines = columns.affines
        traced = _traced_parameters(self.kind, parameters)
        # (the table's own where they are what the kinds trace, as a mesh's zeros: not held twice)
        self.parameters = parameters if np.array_equal(traced, parameters) else traced
        self.object_boxes = np.empty((n, 6), dtype=np.float32)
        #: each instance row's mesh's generic size (MeshBound.generic_size), by id of its built TriangleMesh
        self.generic_sizes: dict[int, float] = {}
        instance = np.zeros(n, dtype=bool)
        for mesh, rows in self.mesh_groups():
            self._build_mesh(mesh)
            built = self.meshes[id(mesh)]
            bound = mesh_bound(mesh, built)
            self.generic_sizes[id(built)] = bound.generic_size
            for part in row_chunks(len(rows)):
                chosen = rows[part]
                affines = self.affines[chosen]
                inverse = instances.affine_inverses(affines)
                error = instances.affine_inverse_rounding(inverse, affines)
                matrix = _matrices_of_affines(affines)
                with np.errstate(all="ignore"):
                    lo, hi = bound.world_box(matrix[:, :3, :3], matrix[:, :3, 3])
                    boxes = instances.single_boxes(instances.padded_boxes(lo, hi))
                # (a row whose numbers are not all finite, or whose matrix LAPACK would refuse, is stored, and
                # checked as any other shape is: a singular matrix is refused by name, as from a Shape)
                instance[chosen] = (np.isfinite(inverse).all(axis=(1, 2)) & np.isfinite(error)
                                    & np.isfinite(boxes).all(axis=1) & _invertible(matrix))
                self.object_boxes[chosen] = boxes
        stored = np.flatnonzero(~instance)
        self.slot = np.full(n, -1, dtype=np.int32)
        self.slot[stored] = np.arange(len(stored), dtype=np.int32)
        subset = _row_subset(columns, stored)
        self.stored = PrimitiveTable(_RowShapes(subset), self.kind[stored], subset.parameters, subset.affines,
                                     material_ids[stored])
        for part in row_chunks(len(stored)):
            boxes = self.stored.boxes[part]
            self.object_boxes[stored[part]] = instances.single_boxes(instances.padded_boxes(boxes[:, :3],
                                                                                          boxes[:, 3:]))

    def refill(self, rows, shapes) -> None:
        raise TypeError("an InstancedTable is not edited in place (tracer.edit compiles the scene's Shapes)")

    def resize(self, keep, added, added_material_ids) -> None:
        self.refill(keep, added)

    def mesh_groups(self) -> list[tuple[MeshData, np.ndarray]]:
        """PrimitiveTable.mesh_groups, made anew when asked (a few milliseconds for 10^5 rows), not kept: the
        index arrays would be 8 bytes an instance."""
        return self._groups(MESH_KINDS)

    def instance_rows(self) -> np.ndarray:
        """The rows whose numbers are computed from their affines, in order."""
        return np.flatnonzero(self.slot < 0)

    def numbers_of(self, rows, names=None) -> dict[str, np.ndarray]:
        """PrimitiveTable.numbers_of: of these rows alone (a query, a pass, the NumPy path's one primitive),
        not of every row (what the NumPy path's whole traces read, made once and kept)."""
        kept = self.__dict__.get("_every_row_arrays")
        if kept is None and np.ndim(rows) == 0:  # (one primitive made: past a few, a whole NumPy trace's)
            self._asked += 1
            if self._asked > _ROWS_ALONE:
                kept = self._every_row()
        if kept is not None:
            return {name: kept[name][rows] for name in names or _NUMBERS}
        chosen = np.atleast_1d(np.asarray(rows))
        out = _empty_numbers(len(chosen))
        slot = self.slot[chosen]
        stored = slot >= 0
        for name in _NUMBERS:
            out[name][stored] = getattr(self.stored, name)[slot[stored]]
        at = np.flatnonzero(~stored)
        sizes = [self.generic_sizes[id(self.meshes[id(self.mesh_of(i))])] for i in chosen[at].tolist()]
        self._instance_numbers(chosen[at], np.asarray(sizes), out, at)
        return out if np.ndim(rows) else {name: array[0] for name, array in out.items()}

    def _instance_numbers(self, rows: np.ndarray, sizes, out: dict, at) -> None:
        """The numbers of instance rows ``rows`` (their meshes' generic sizes ``sizes``) into ``out``'s
        arrays at ``at`` (tracer.instances, as numeric.h's instance_* compute them)."""
        affines = self.affines[rows]
        inverse = instances.affine_inverses(affines)
        terms = np.empty((len(rows), 4))
        terms[:, 0] = instances.affine_inverse_rounding(inverse, affines)
        terms[:, 1] = sizes
        terms[:, 2], terms[:, 3] = instances.inverse_norms(inverse)
        out["inverses"][at], out["rounding_terms"][at] = inverse, terms
        out["spheres"][at] = instances.spheres_of_boxes(self.object_boxes[rows])
        out["boxes"][at] = self.object_boxes[rows]

    def _every_row(self) -> dict[str, np.ndarray]:
        """Every row's numbers as a PrimitiveTable holds them (the stored rows' copied, the instance rows'
        computed), made when first asked for and kept."""
        kept = self.__dict__.get("_every_row_arrays")
        if kept is not None:
            return kept
        stored = np.flatnonzero(self.slot >= 0)
        out = _empty_numbers(len(self))
        for name in _NUMBERS:
            out[name][stored] = getattr(self.stored, name)
        for mesh, rows in self.mesh_groups():
            rows = rows[self.slot[rows] < 0]
            size = self.generic_sizes[id(self.meshes[id(mesh)])]
            for part in row_chunks(len(rows)):
                self._instance_numbers(rows[part], size, out, rows[part])
        self.__dict__["_every_row_arrays"] = out
        return out

    inverses = property(lambda self: self._every_row()["inverses"])
    rounding_terms = property(lambda self: self._every_row()["rounding_terms"])
    spheres = property(lambda self: self._every_row()["spheres"])
    boxes = property(lambda self: self._every_row()["boxes"])
    inverse_error = property(lambda self: self.rounding_terms[:, 0])
    generic_size = property(lambda self: self.rounding_terms[:, 1])
    inverse_norms = property(lambda self: self.rounding_terms[:, 2:])
    centers = property(lambda self: self.spheres[:, :3])
    radii = property(lambda self: self.spheres[:, 3])


#: What PrimitiveTable.numbers_of gives of each row.
_NUMBERS = ("inverses", "rounding_terms", "spheres", "boxes")
#: Rows an InstancedTable computes one at a time (a query, a pass's few) before it computes every row's
#: numbers at once and keeps them (a whole NumPy trace, which makes every primitive).
_ROWS_ALONE = 64


def _invertible(stack: np.ndarray) -> np.ndarray:
    """Per (k, 4, 4) matrix, whether LAPACK inverts it to finite numbers (what _checked_inverse asks of a
    Shape's matrix)."""
    with np.errstate(all="ignore"):
        try:
            return np.isfinite(np.linalg.inv(stack)).all(axis=(1, 2))
        except np.linalg.LinAlgError:  # (some matrix of the chunk is singular: each on its own)
            return np.array([_invertible(m[None])[0] if len(stack) > 1 else False for m in stack], dtype=bool)


def _empty_numbers(n: int) -> dict[str, np.ndarray]:
    return {"inverses": np.empty((n, 4, 4)), "rounding_terms": np.empty((n, 4)), "spheres": np.empty((n, 4)),
            "boxes": np.empty((n, 6))}


def _row_subset(columns: ShapeColumns, rows: np.ndarray) -> ShapeColumns:
    """The ShapeColumns of these rows of a table (their own sources, meshes and materials; no names)."""
    def take(array):
        return None if array is None else array[rows]

    return replace(columns, kinds=columns.kinds[rows], affines=columns.affines[rows],
                   material_ids=columns.material_ids[rows], parameters=columns.parameters[rows],
                   lines=take(columns.lines), columns=take(columns.columns), names=None,
                   mesh_ids=take(columns.mesh_ids))


#: Index of each kind in the shape registry (PrimitiveTable.kind).
_KIND_INDEX = {e.keyword: i for i, e in enumerate(shapes.REGISTRY)}
_KEYWORDS = tuple(e.keyword for e in shapes.REGISTRY)
_MESH_CODES = frozenset(_KIND_INDEX[k] for k in MESH_KINDS)
#: Per kind code: whether its bounds come from vertices (a mesh's, a polyhedron's).
_HAS_VERTICES = np.array([e.family != "analytic" for e in shapes.REGISTRY])
#: Per kind code, which parameter slots are the kind's own and the values of the others (ShapeKind.traced).
_OWN_PARAMETER = np.array([[k < len(e.parameters) for k in range(shapes.MAX_PARAMETERS)] for e in shapes.REGISTRY])
_FIXED_PARAMETER = np.array([[e.fixed[k] if k < len(e.fixed) else 0.0 for k in range(shapes.MAX_PARAMETERS)]
                             for e in shapes.REGISTRY])


def _traced_parameters(codes: np.ndarray, parameters: np.ndarray) -> np.ndarray:
    """The values the kinds (codes (N,)) of rows of Shape.parameters ((N, shapes.MAX_PARAMETERS)) give their
    intersections (ShapeKind.traced): each kind's own parameters where it reads them, its fixed values where
    it has those, 0 after."""
    return np.where(_OWN_PARAMETER[codes], parameters, _FIXED_PARAMETER[codes])


#: (keywords, bounds function) of the kinds whose generic bounds depend on their parameters, by function.
_PARAMETER_BOUNDS = [(tuple(e.keyword for e in shapes.REGISTRY if e.bounds == name),
                      next(e for e in shapes.REGISTRY if e.bounds == name).function("bounds"))
                     for name in dict.fromkeys(e.bounds for e in shapes.REGISTRY if e.bounds)]
#: Per kind code: whether the kind has a fixed generic box, the box's low and high corners, and the generic
#: size (Primitive.generic_size) of such a kind.
_HAS_BOX = np.array([e.keyword in _BOX_CORNERS for e in shapes.REGISTRY])
_BOX_LO = np.array([_BOX_CORNERS[e.keyword].min(axis=0) if e.keyword in _BOX_CORNERS else np.zeros(3)
                    for e in shapes.REGISTRY])
_BOX_HI = np.array([_BOX_CORNERS[e.keyword].max(axis=0) if e.keyword in _BOX_CORNERS else np.zeros(3)
                    for e in shapes.REGISTRY])
_BOX_SIZE = np.array([float(np.max(np.abs(_BOX_CORNERS[e.keyword]))) if e.keyword in _BOX_CORNERS else 1.0
                      for e in shapes.REGISTRY])
#: Rows per batch of the table's stacked computations: their temporaries stay ~2 MB at any size (~250 bytes
#: a row; at 1 << 15 rows they were 80 bytes an instance of a scene of 10^5, at the top of its memory).
_CHUNK = 1 << 13


def row_chunks(n: int):
    """Slices of range(n), _CHUNK long."""
    return (slice(start, min(n, start + _CHUNK)) for start in range(0, n, _CHUNK))


def delete_positions(items: list, positions: Sequence[int]) -> None:
    """Delete these positions (ascending) from a list in place: a few deletions move the tail a few times, with
    no Python loop over the whole list; many make the list anew."""
    if len(positions) > 64:
        gone = set(positions)
        items[:] = [item for i, item in enumerate(items) if i not in gone]
        return
    for p in reversed(positions):
        del items[p]


def _position(index, length: int) -> int:
    """A sequence index (negative from the end) as a position in range(length), or IndexError."""
    position = operator.index(index)
    if position < 0:
        position += length
    if not 0 <= position < length:
        raise IndexError(f"index {index} out of range for {length} items")
    return position


class PrimitiveList(Sequence):
    """A compiled scene's primitives, made from its table's rows when first asked for (a scene of a million
    spheres traced by the C core never makes one) and the same object on every later access."""

    def __init__(self, table: PrimitiveTable):
        self.table = table
        self._made: dict[int, Primitive] = {}

    def __len__(self) -> int:
        return len(self.table)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        index = _position(index, len(self))
        prim = self._made.get(index)
        if prim is None:
            prim = self._made[index] = Primitive.of_row(self.table, index)
        return prim

    def __iter__(self):
        return map(self.__getitem__, range(len(self)))


class CompiledObjects(Sequence):
    """A compiled scene's top-level objects: CSGNode trees for the booleans, and for the plain shapes their
    primitive (made when first asked for).  ``primitive_index`` (objects,) is the primitive of each plain
    object, -1 for a boolean."""

    def __init__(self, primitives: PrimitiveList, primitive_index: np.ndarray, booleans: dict[int, "CSGNode"]):
        self.primitives = primitives
        self.primitive_index = primitive_index
        self.booleans = booleans
        #: tracer.batches.batches_of's grouping of these objects, once made
        self.batches = None

    def forget_batches(self) -> None:
        """The grouping made again when next asked for (an edit may have changed a primitive's kind)."""
        self.batches = None

    def __len__(self) -> int:
        return len(self.primitive_index)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        index = _position(index, len(self))
        node = self.booleans.get(index)
        return node if node is not None else self.primitives[int(self.primitive_index[index])]

    def __iter__(self):
        return map(self.__getitem__, range(len(self)))


def _compile_objects(objects: list[SceneObject], primitives: PrimitiveList, any_boolean: bool) -> CompiledObjects:
    """The top-level objects, their primitives numbered in iter_shapes order (as the table's rows)."""
    if not any_boolean:
        return CompiledObjects(primitives, np.arange(len(objects)), {})
    index = np.full(len(objects), -1, dtype=np.int64)
    booleans: dict[int, CSGNode] = {}
    counter = iter(range(len(primitives)))
    for k, obj in enumerate(objects):
        if isinstance(obj, CSG):
            booleans[k] = fold_tree(obj, lambda _: primitives[next(counter)],
                                    lambda node, left, right: CSGNode(node.op, left, right))
        else:
            index[k] = next(counter)
    return CompiledObjects(primitives, index, booleans)


def live_effects(scene: Scene) -> frozenset[str]:
    """Which effects this scene can show at all; the tracer computes nothing for the others."""
    shapes = scene.shapes()
    materials = list({id(s.material): s.material for s in shapes}.values())
    uv_textured = any(s.material.texture > 0 and s.mesh is not None and s.mesh.corner_uvs is not None
                      for s in shapes)
    return _effects(scene, {s.kind for s in shapes}, MaterialTable(materials) if materials else None,
                    any(isinstance(o, CSG) for o in scene.objects), uv_textured=uv_textured)


def uv_textured_of(table: "PrimitiveTable", texture: np.ndarray) -> bool:
    """Whether an image texture lies on a mesh with texture coordinates (``texture``: per material id): the
    live effect mesh-uv."""
    return any(mesh.corner_uvs is not None and (texture[table.material_ids[rows]] > 0).any()
               for mesh, rows in table.mesh_groups())


#: What a material can call for (material_traits' columns).
TRAITS = ("lit", "reflects", "transmits", "textured", "cook-torrance", "fresnel-reflects", "fresnel-transmits")


def material_traits(table: MaterialTable, settings, rows=slice(None)) -> np.ndarray:
    """Per material (of every row, or of ``rows``), which TRAITS it has, (M, 7) bool: lit (a diffuse or specular
    colour), reflects and transmits (above the settings' thresholds), textured, a Cook–Torrance share, and
    reflects or transmits with a Fresnel mode."""
    r, t = table.reflectivity[rows], table.transparency[rows]
    reflects, transmits = (r >= settings.min_reflectivity) & (r > 0), (t >= settings.min_transparency) & (t > 0)
    fresnel = table.fresnel[rows] != 0
    return np.stack([(table.diffuse[rows] > 0).any(axis=1) | (table.specular[rows] > 0).any(axis=1),
                     reflects, transmits, table.texture[rows] != 0, table.specular_fraction[rows] > 0,
                     fresnel & reflects, fresnel & transmits], axis=1)


def _effects(scene: Scene, kinds: set[str], table: Optional[MaterialTable], any_boolean: bool,
             used: Optional[np.ndarray] = None, uv_textured: bool = False) -> frozenset[str]:
    """live_effects from the kinds of the scene's shapes and a table of their materials (None: no shapes;
    ``used``: which of its rows count, default all); ``uv_textured``: an image texture lies on a mesh with
    texture coordinates."""
    traits = np.zeros((0, len(TRAITS)), dtype=bool) if table is None else material_traits(table, scene.settings)
    return effects_of_traits(scene, kinds, (traits if used is None else traits[used]).any(axis=0), any_boolean,
                             uv_textured)


def effects_of_traits(scene: Scene, kinds: set[str], present: np.ndarray, any_boolean: bool,
                      uv_textured: bool = False) -> frozenset[str]:
    """The live effects of a scene whose shapes are of ``kinds`` and whose materials have, together, the
    TRAITS where ``present`` (a bool per trait) is true; ``uv_textured``: an image texture lies on a mesh
    with texture coordinates (uv_textured_of)."""
    settings = scene.settings
    has = dict(zip(TRAITS, np.asarray(present, dtype=bool).tolist()))
    effects = {f"shape:{kind}" for kind in kinds}
    shining = [light for light in scene.lights if light.lights_surfaces]  # (lights switched off wholly do not)
    if shining and has["lit"]:
        effects.add("lighting")
        if any(light.cast_shadow for light in shining):
            effects.add("shadows")
        if any(light.kind != "point" for light in scene.lights):
            effects.add("physical-lights")
        if any(light.soft and light.cast_shadow for light in shining):
            effects.add("soft-shadows")
    deep = settings.max_recursion_depth > 0
    if deep and has["reflects"]:
        effects.add("reflection")
    if deep and has["transmits"]:
        effects.add("refraction")
    if any_boolean:
        effects.add("csg")
    if has["textured"]:
        effects.add("textures")
        if uv_textured:
            effects.add("mesh-uv")
    if "lighting" in effects and has["cook-torrance"]:
        effects.add("cook-torrance")
    if "shadows" in effects and settings.smooth_terminator and kinds & set(MESH_KINDS):
        effects.add("smooth-terminator")
    if ("reflection" in effects and has["fresnel-reflects"]) or ("refraction" in effects and has["fresnel-transmits"]):
        effects.add("fresnel")
    if _seen_lights_live(scene, effects):
        effects.add("seen-lights")  # (lights with an extent seen in mirrors and through glass, as Cycles' are)
    if _light_switches_live(scene, effects):
        effects.add("light-switches")
    return frozenset(effects)


def _seen_lights_live(scene: Scene, effects: set[str]) -> bool:
    """Whether a reflected ray (a mirror's, or glass's total internal reflection) may see a light with an
    extent (an area light, a sphere or spot light of some radius, a sun of some angle: Light.seen_by_rays) that
    glossy rays see, or a refracted ray one that transmission rays see.  Lights without one (SDL's, and a point
    of radius 0) are never seen: a scene of them pays nothing."""
    seen = [light for light in scene.lights if light.seen_by_rays]
    return bool((effects & {"reflection", "refraction"} and any(light.visible_glossy for light in seen))
                or ("refraction" in effects and any(light.visible_transmission for light in seen)))


def _light_switches_live(scene: Scene, effects: set[str]) -> bool:
    """Whether a light's switch that is off changes what the live effects trace (the backends then read the
    switches: a light that casts no shadow where shadows are live, one left out of the diffuse or glossy
    shading where lighting is, a light with an extent that reflected (or, where refraction is live, refracted)
    rays do not see where seen-lights is)."""
    for light in scene.lights:
        if "shadows" in effects and not light.cast_shadow:
            return True
        if "lighting" in effects and not (light.visible_diffuse and light.visible_glossy):
            return True
        if "seen-lights" in effects and light.seen_by_rays and (
                not light.visible_glossy or ("refraction" in effects and not light.visible_transmission)):
            return True
    return False


#: Built triangle meshes by content (see mesh_digest), kept while any compiled scene uses them: the same
#: .3vn in a thousand shapes, or in a scene compiled again, is built once.
_TRIANGLE_MESHES: "weakref.WeakValueDictionary[tuple, object]" = weakref.WeakValueDictionary()


def mesh_digest(mesh: MeshData) -> bytes:
    """A digest of a mesh's content: its vertices, normals and faces (what its BVH is built from).  A mesh
    given to remember_digest is hashed once (while it holds the same arrays)."""
    kept = mesh.__dict__.get(_DIGEST_ATTRIBUTE)
    if kept is not None and kept[0] == _parts(mesh):
        return kept[1]
    return _hash_mesh(mesh)


#: Where remember_digest keeps a mesh's digest, with the identity of the arrays it was computed from.
_DIGEST_ATTRIBUTE = "_content_digest"


def _parts(mesh: MeshData) -> tuple:
    return id(mesh.vertices), id(mesh.normals), id(mesh.faces)


def remember_digest(mesh: MeshData) -> MeshData:
    """Hash ``mesh`` now and keep the digest on it, for a caller that never changes the mesh's arrays in place
    afterwards (the Blender add-on's converted meshes, compiled again at every viewport update): compiling
    a scene then does not hash a million triangles again.  Returns the mesh."""
    mesh.__dict__[_DIGEST_ATTRIBUTE] = (_parts(mesh), _hash_mesh(mesh))
    return mesh


def _hash_mesh(mesh: MeshData) -> bytes:
    """The digest of a mesh's content: its vertices, normals and faces (what its BVH is built from).  Arrays
    are hashed where they lie (indices a slice at a time as int64), so a big mesh is not copied for it."""
    h = hashlib.blake2b(digest_size=20)
    for array in (mesh.vertices, mesh.normals):
        array = np.ascontiguousarray(array, dtype=np.float64)
        h.update(repr(array.shape).encode())
        h.update(array.reshape(-1))
    faces = mesh.faces
    if isinstance(faces, FaceList):
        h.update(b"packed")
        size = faces.uniform_size
        if size is not None:  # every face of one size: that size and the count say what sizes would
            h.update(f"{size}x{len(faces)}".encode())
        else:
            _hash_indices(h, faces.sizes)
        for array in (faces.vertex_index, faces.normal_index):
            _hash_indices(h, array)
    else:
        h.update(b"list")
        h.update(repr([(tuple(map(int, v)), tuple(map(int, n))) for v, n in faces]).encode())
    if mesh.corner_uvs is not None:  # (the texture coordinates are part of the built mesh)
        uvs = np.ascontiguousarray(mesh.corner_uvs, dtype=np.float64)
        h.update(b"uvs" + repr(uvs.shape).encode())
        h.update(uvs.reshape(-1))
    return h.digest()


def _hash_indices(h, array) -> None:
    """Feed an index array (or None) to the hash as int64, a million at a time."""
    if array is None:
        h.update(b"-")
        return
    array = np.asarray(array).reshape(-1)
    h.update(f"[{len(array)}]".encode())
    step = 1 << 20
    for start in range(0, len(array), step):
        h.update(np.ascontiguousarray(array[start:start + step], dtype=np.int64))


def shared_triangle_mesh(mesh: MeshData):
    """The TriangleMesh (BVH and triangle tables) of a mesh: built once per content, shared after.  The C core
    builds its BVH when it is loaded (the NumPy builder's tree, in a fraction of the time)."""
    from .intersect import mesh as mesh_module  # deferred: loaded by the first mesh, not by import tracer

    key = (mesh_digest(mesh), mesh_module.BOX_PADDING)  # (the one build constant a test may change)
    built = _TRIANGLE_MESHES.get(key)
    if built is None:
        problem = mesh.coordinate_problem()  # (the readers check; a mesh made in a program may not be)
        if problem is not None:
            raise SceneError(f"{mesh.origin or 'mesh'}: {problem}")
        built = mesh_module.TriangleMesh(mesh, builder=c_bvh_builder())
        _TRIANGLE_MESHES[key] = built
    return built


class MeshBound:
    """What bounds every instance of one mesh, from its vertices once: their generic box (``lo``, ``hi``,
    exact), a sphere round them (``center``, the box's; ``radius``, rounded outward) and ``generic_size`` (the
    largest |coordinate|, 1 without vertices).  An instance's world box (:meth:`world_box`) is where both
    carried to the world overlap: the box's image is tight for an axis-aligned instance, the sphere's for a
    rotated round one."""

    def __init__(self, vertices: np.ndarray):
        vertices = np.asarray(vertices, dtype=np.float64).reshape(-1, 3)
        self.generic_size = float(np.max(np.abs(vertices))) if vertices.size else 1.0
        if not len(vertices):  # (no surface: bounded as a point at the origin)
            vertices = np.zeros((1, 3))
        self.lo, self.hi = vertices.min(axis=0), vertices.max(axis=0)
        self.center = 0.5 * (self.lo + self.hi)
        offsets = vertices - self.center
        # (computed norms are within a few roundings of the true ones: 8 cover them, and the step up)
        radius = float(np.sqrt(np.max(np.einsum("ij,ij->i", offsets, offsets)))) * (1 + _BOUND_SLACK)
        self.radius = float(np.nextafter(radius, np.inf))

    def world_box(self, linear: np.ndarray, translation: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(lo, hi), each (k, 3): world boxes of the instances under ``linear`` (k, 3, 3) and ``translation``
        (k, 3) that hold every vertex carried there in exact arithmetic.  Each bound is computed in floating
        point and then widened by that computation's rounding (at most gamma_4 of the sum of its terms'
        magnitudes, Higham's bound for a dot product of four terms) and a last step outward."""
        at_lo, at_hi = linear * self.lo, linear * self.hi  # [i, r, j] = linear[i, r, j] * corner j
        low, high = np.minimum(at_lo, at_hi), np.maximum(at_lo, at_hi)
        size = np.maximum(np.abs(at_lo), np.abs(at_hi)).sum(axis=2) + np.abs(translation)
        slack = size * _BOUND_SLACK
        box_lo = low.sum(axis=2) + translation - slack
        box_hi = high.sum(axis=2) + translation + slack
        at_center = linear * self.center
        center = at_center.sum(axis=2) + translation
        # (a ball of radius R carried by the linear part reaches R * |row r| along world axis r)
        reach = self.radius * np.sqrt(np.einsum("irj,irj->ir", linear, linear))
        reach = (reach + (np.abs(at_center).sum(axis=2) + np.abs(translation)) * _BOUND_SLACK) * (1 + _BOUND_SLACK)
        lo = np.maximum(box_lo, center - reach)
        hi = np.minimum(box_hi, center + reach)
        return np.nextafter(lo, -np.inf), np.nextafter(hi, np.inf)


#: Relative slack that covers the roundings of a bound's computation (gamma_8: twice the roundings there are).
_BOUND_SLACK = numerics.gamma(8)
#: Each built mesh's MeshBound, while the mesh is kept.
_MESH_BOUNDS: "weakref.WeakKeyDictionary[object, MeshBound]" = weakref.WeakKeyDictionary()


def mesh_bound(mesh: MeshData, built=None) -> MeshBound:
    """The MeshBound of a mesh, made once per built mesh (``built``, its shared TriangleMesh, which stands for
    its content), or anew when it is not built."""
    if built is None:
        return MeshBound(mesh.vertices)
    bound = _MESH_BOUNDS.get(built)
    if bound is None:
        bound = _MESH_BOUNDS[built] = MeshBound(mesh.vertices)
    return bound


def c_bvh_builder():
    """tracer.native.build_mesh_bvh when the C core is loaded, else None (TriangleMesh builds in NumPy)."""
    try:
        # deferred: the C core is loaded (in a checkout: compiled) by the first mesh or render that wants it,
        # not by importing the tracer
        from . import native
    except ImportError:  # no C core in this installation
        return None
    return native.build_mesh_bvh if native.load_error is None else None


def content_key(scene: Scene) -> tuple:
    """Everything compile_scene reads from a scene, in a form that compares quickly (see _content)."""
    return _content(scene)[0]


@dataclass
class _Columns:
    """What _content gathers from a scene's shapes (in iter_shapes order) on its way, for _compile: from a
    list of objects, per-shape tuples; from a ShapeTable not yet made into Shapes, its arrays (``table``)."""

    nodes: list  # what the key's ids stand for, kept alive with it: every node (or the table's columns)
    shapes: Sequence[Shape]  # a list, or a _RowShapes that makes a table's rows into Shapes when asked
    any_boolean: bool
    matrices: Optional[np.ndarray]  # (N, 4, 4) (see _stacked_matrices), or a table's (N, 12) affines
    kinds: tuple[str, ...] = ()
    materials: tuple[Material, ...] = ()
    parameters: tuple[tuple[float, ...], ...] = ()
    table: Optional[ShapeColumns] = None

    def arrays(self) -> tuple[np.ndarray, np.ndarray, list[Material], np.ndarray]:
        """(kind codes, material ids, the materials by id, parameter rows) of the shapes."""
        table = self.table
        if table is not None:
            ids, materials = table.material_ids, table.materials
            used = np.bincount(ids, minlength=len(materials)) > 0
            if not used.all():  # (only the materials in use, as from a list: they decide the live effects)
                ids = (np.cumsum(used) - 1)[ids].astype(np.int32)
                materials = (materials.used(used) if isinstance(materials, MaterialRows) else
                             [m for m, kept in zip(materials, used.tolist()) if kept])
            return table.kinds, ids, materials, table.parameters
        n = len(self.kinds)
        material_ids, materials = _material_ids(self.materials)
        return (np.fromiter(map(_KIND_INDEX.__getitem__, self.kinds), dtype=np.int16, count=n), material_ids,
                materials, parameter_rows(self.parameters))


class _RowShapes(Sequence):
    """A ShapeTable's rows as Shapes, each made when first asked for (ShapeColumns.shape) and the same object
    after: what a compiled table's Primitives (the NumPy path's) are made of."""

    def __init__(self, columns: ShapeColumns):
        self.columns = columns
        self._made: dict[int, Shape] = {}

    def __len__(self) -> int:
        return len(self.columns)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        index = _position(index, len(self))
        shape = self._made.get(index)
        if shape is None:
            shape = self._made[index] = self.columns.shape(index)
        return shape

    def mesh_of(self, index: int) -> Optional[MeshData]:
        """The mesh row ``index`` holds (its own, its kind's built-in mesh, or None), without making its Shape."""
        return self.columns.mesh_of(index)


def _walk(objects: list[SceneObject]) -> tuple[list, list[Shape], list[tuple]]:
    """(nodes, shapes, structure) of the objects, depth first, left to right, without recursion."""
    if not any(issubclass(t, CSG) for t in set(map(type, objects))):  # no boolean: the objects are the shapes
        shapes = list(objects)
        return shapes, shapes, []
    nodes, shapes, structure = [], [], []
    todo = list(reversed(objects))
    while todo:
        node = todo.pop()
        nodes.append(node)
        if isinstance(node, CSG):
            structure.append((node.op, id(node.left), id(node.right)))
            todo += (node.right, node.left)
        else:
            shapes.append(node)
    return nodes, shapes, structure


def _content(scene: Scene) -> tuple[tuple, _Columns]:
    """Everything compile_scene reads from a scene, in a form that compares quickly: two scenes (or one
    scene at two times) with equal keys compile to the same thing.

    Objects are compared by identity *and* by what compile_scene reads from them (kind, material, taper,
    matrix, mesh content; a boolean's operation and operands), so replacing, reordering or editing any of
    them, even a matrix changed in place, gives another key.  Pixmap files count with their size and
    modification time.  The key holds no scene object but materials (compared by value): ids stay
    meaningful because the cached entry keeps the objects alive (see compile_scene).  Returns (key, columns):
    the columns keep the nodes alive and hold what _compile needs."""
    table = scene.objects.columns if isinstance(scene.objects, ShapeTable) else None
    if table is not None:
        return _table_content(scene, table)
    nodes, shapes, structure = _walk(scene.objects)
    stack = _stacked_matrices(shapes)
    matrices = hashlib.blake2b(digest_size=20)
    if stack is not None:
        matrices.update(stack)  # (the array's own bytes, without a copy)
    else:  # (a matrix that is not a float64 4x4: compiling will say which)
        matrices.update(repr([np.asarray(s.matrix).tolist() for s in shapes]).encode())
    mesh_list = list(map(attrgetter("mesh"), shapes))
    meshes = dict(zip(map(id, mesh_list), mesh_list))
    meshes.pop(id(None), None)
    columns = _Columns(nodes, shapes, bool(structure), stack,
                       *(tuple(map(attrgetter(name), shapes)) for name in ("kind", "material", "parameters")))
    key = (_ids_digest(nodes), tuple(structure), columns.kinds, columns.materials, columns.parameters,
           _ids_digest(mesh_list), tuple((k, mesh_digest(m)) for k, m in meshes.items()),
           matrices.digest()) + _scene_wide_key(scene)
    return key, columns


def _table_content(scene: Scene, table: ShapeColumns) -> tuple[tuple, _Columns]:
    """_content of a scene whose objects are a ShapeTable not yet made into Shapes: the identity of its
    columns (arrays nobody can change: see ShapeTable) and its materials by value, without a Python object
    per shape and without hashing its arrays.  (Once the table is made into Shapes, _content reads those:
    another key, and a new compile from them.)"""
    shapes = _RowShapes(table)
    meshes = {id(mesh): mesh for mesh in map(shapes.mesh_of, _builtin_mesh_rows(table))}
    meshes.update((id(mesh), mesh) for mesh in table.meshes)
    key = ("table", id(table), table.materials,
           tuple((k, mesh_digest(m)) for k, m in meshes.items())) + _scene_wide_key(scene)
    return key, _Columns([table], shapes, False, table.affines, table=table)


def _builtin_mesh_rows(table: ShapeColumns) -> list[int]:
    """One row of each kind present in the table that holds a built-in mesh (polyhedra, the teapot)."""
    codes = [code for code, e in enumerate(shapes.REGISTRY) if e.builtin_mesh]
    present = np.isin(table.kinds, codes)
    if not present.any():
        return []
    _, first = np.unique(table.kinds[present], return_index=True)
    return np.flatnonzero(present)[first].tolist()


def _scene_wide_key(scene: Scene) -> tuple:
    """The part of _content's key that is not about the shapes: lights, camera, settings, the pixmap files
    (with their sizes and modification times), the tolerances."""
    pixmaps = []
    for number, path in sorted(scene.pixmaps.items()):
        try:
            stat = os.stat(path)
            pixmaps.append((number, str(path), stat.st_size, stat.st_mtime_ns))
        except (OSError, ValueError):  # (a missing file, a name with a NUL: compiling reports it)
            pixmaps.append((number, str(path), None, None))
    return tuple(scene.lights), scene.camera, astuple(scene.settings), tuple(pixmaps), numerics.TOLERANCES


def _ids_digest(objects: list) -> bytes:
    """A digest of the objects' ids, in order (20 bytes, where a tuple of the ids takes 40 per object)."""
    ids = np.fromiter(map(id, objects), dtype=np.uint64, count=len(objects))
    return hashlib.blake2b(ids, digest_size=20).digest()


def compile_scene(scene: Scene) -> CompiledScene:
    """The scene ready to trace.  Compiled once: the result is kept on the scene with its content_key, and
    returned again for as long as the scene's content has not changed."""
    with one_blas_thread(), collector_paused():
        key, columns = _content(scene)
        holder = getattr(scene, _CACHE_ATTRIBUTE, None)
        cached = holder.entry if isinstance(holder, _CompiledHolder) else None
        if cached is not None and cached[0] == key:
            return cached[1]
        compiled = _compile(scene, columns)
    # (the nodes are kept so that the ids in the key cannot be reused by new objects while it is cached)
    setattr(scene, _CACHE_ATTRIBUTE, _CompiledHolder((key, compiled, columns.nodes)))
    return compiled


#: Where compile_scene keeps its result on the Scene (not a dataclass field: replace() of a scene does not
#: carry it, and it never takes part in comparisons).
_CACHE_ATTRIBUTE = "_compiled_cache"


class _CompiledHolder:
    """compile_scene's entry on a scene, left behind when the scene is copied or pickled: a copy compiles
    anew, and a pickled scene (sent to a Dask worker) must not drag the C core's pointers along."""

    __slots__ = ("entry",)

    def __init__(self, entry=None):
        self.entry = entry

    def __reduce__(self):
        return _CompiledHolder, ()


def _material_ids(materials: tuple[Material, ...]) -> tuple[np.ndarray, list[Material]]:
    """Per shape, the id of its material, and the distinct material objects in id order (ids in order of
    first use).  Shapes share an id when they share the material object (as the shapes read from one SDL
    state do); two equal materials of their own get two ids, which changes no colour, and spares hashing
    every material by value, which took longer than the rest of compiling a scene of 100,000 spheres."""
    n = len(materials)
    if n == 0:
        return np.zeros(0, dtype=np.int32), []
    # (the objects' addresses sorted, not a dict of them: a million shapes in a fifth of the time)
    _, first, which = np.unique(np.fromiter(map(id, materials), dtype=np.uint64, count=n), return_index=True,
                                return_inverse=True)
    order = np.argsort(first)
    number = np.empty(len(order), dtype=np.int32)
    number[order] = np.arange(len(order), dtype=np.int32)
    return number[which], list(map(materials.__getitem__, first[order].tolist()))


def _has_instance_rows(columns: _Columns, kind: np.ndarray) -> bool:
    """Whether the shapes are a ShapeTable of single-precision matrices with mesh rows (InstancedTable)."""
    table = columns.table
    return (table is not None and table.affines.dtype == np.float32
            and bool(np.isin(kind, list(_MESH_CODES)).any()))


def _compile(scene: Scene, columns: Optional[_Columns] = None) -> CompiledScene:
    """Compile ``scene`` (``columns``: what compile_scene's content key gathered, when the caller has it).

    Every primitive's numbers (inverse, rounding, bounds) are computed at once, as arrays
    (PrimitiveTable): a scene of 100,000 spheres would otherwise spend its compile time in a million
    small NumPy calls."""
    if columns is None:
        columns = _content(scene)[1]
    shapes = columns.shapes
    kind, material_ids, materials, parameters = columns.arrays()
    table = (InstancedTable(shapes, kind, parameters, material_ids) if _has_instance_rows(columns, kind) else
             PrimitiveTable(shapes, kind, parameters, columns.matrices, material_ids))
    primitives = PrimitiveList(table)
    objects = _compile_objects(scene.objects, primitives, columns.any_boolean)
    material_table = MaterialTable(materials or [Material()])
    kinds = {_KEYWORDS[code] for code in np.unique(kind).tolist()}
    effects = _effects(scene, kinds, material_table if len(shapes) else None, columns.any_boolean,
                       uv_textured=uv_textured_of(table, material_table.texture))
    textures = None
    if "textures" in effects:
        # deferred: the textures (and the noise tables made as they load) wait for the first textured scene
        from .textures import TextureSet
        textures = TextureSet(scene, primitives)
    lights = LightTable.of(scene.lights)
    return CompiledScene(
        scene=scene, objects=objects, primitives=primitives, materials=material_table,
        light_positions=lights.position, light_colors=lights.color, lights=lights,
        effects=effects, textures=textures, tolerances=table.tolerances, table=table)
