"""Scene model -> what the tracer runs: primitives with inverse matrices, CSG trees, material and light
tables, and the set of *live effects*.

Deciding here, once per scene, which effects exist (shadows, reflection, refraction, CSG, each shape
kind, textures) is what lets the tracer do no work at all for the others: the shading code branches on
``CompiledScene.effects`` once per batch, never per ray.
"""
from __future__ import annotations

import hashlib
import os
import weakref
from dataclasses import astuple, dataclass, field
from functools import cached_property
from operator import attrgetter
from typing import Callable, Optional, Union

import numpy as np

from . import numerics, shapes
from .bulk import collector_paused, one_blas_thread
from .errors import TracerError
from .intersect import analytic
from .intersect.csg import combine, sheet_to_pairs
from .intersect.hits import HitArrays
from .intersect.torus import intersect_torus
from .model import (CSG, POLYHEDRON_KINDS, FaceList, Material, MeshData, Scene, SceneObject, Shape,
                    TORUS_TUBE_RADIUS, iter_shapes)
from .transforms import transform_points


def lines_near_sphere(center, radius: float, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Which lines pass within ``radius`` of ``center`` (all of them for an infinite radius)."""
    if not np.isfinite(radius):
        return np.ones(origins.shape[0], dtype=bool)
    to_center = center - origins
    dd = numerics.dot3(directions, directions)
    with np.errstate(invalid="ignore", divide="ignore"):
        along = numerics.dot3(to_center, directions) / dd
    perp = to_center - along[:, None] * directions
    return numerics.dot3(perp, perp) <= radius * radius


#: Closed analytic shapes whose normals must agree with their entering flags (ShapeKind.normals_agree).
SOLID_ANALYTIC_KINDS = tuple(e.keyword for e in shapes.REGISTRY if e.family == "analytic" and e.normals_agree)


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
_DISC_BOX = np.array([[x, y] for x in (-1, 1) for y in (-1, 1)], dtype=float)
#: The corners of each registered kind's generic box.
_BOX_CORNERS = {e.keyword: np.asarray(e.box[0]) + _CORNERS * np.asarray(e.box[1])
                for e in shapes.REGISTRY if e.box is not None}
for _constant in (_CORNERS, _DISC_BOX, *_BOX_CORNERS.values()):
    _constant.setflags(write=False)


def _analytic_generic_points(shape: Shape) -> Optional[np.ndarray]:
    """Points whose hull holds a closed-form shape's generic solid (8 of them), or None for the plane,
    polyhedra and meshes."""
    kind = shape.kind
    if kind in _BOX_CORNERS:
        return _BOX_CORNERS[kind]
    if kind in ("taperedCylinder", "cylinder", "cone"):
        top = max(shape.small_radius, 0.0)
        # Corners of the squares that bound the two discs: the frustum lies inside their hull.
        return np.concatenate([np.c_[_DISC_BOX, np.zeros(4)], np.c_[_DISC_BOX * top, np.ones(4)]])
    return None


def _sphere_around(world: np.ndarray):
    """Bounding sphere (centre, radius) of the (K, 3) world points' box, padded by 1e-9 relatively."""
    lo, hi = world.min(axis=0), world.max(axis=0)
    center = 0.5 * (lo + hi)
    return center, float(np.linalg.norm(hi - lo) * 0.5) * (1 + 1e-9)


def _stacked_matrices(shapes: list[Shape]) -> Optional[np.ndarray]:
    """The shapes' matrices as one (N, 4, 4) array, or None if any is not a float64 4x4 array."""
    matrices = [s.matrix for s in shapes]
    if not all(isinstance(m, np.ndarray) and m.dtype == np.float64 and m.shape == (4, 4) for m in matrices):
        return None
    return np.stack(matrices) if matrices else np.zeros((0, 4, 4))


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


def _batched_bounds(shapes: list[Shape], stack: np.ndarray) -> list[Optional[tuple]]:
    """Bounding spheres of the closed-form shapes (None for the others), their corners carried to the world
    by one stacked matrix product: what transform_points and _sphere_around compute, to rounding in the
    last place (which the radius's 1e-9 padding covers)."""
    out: list[Optional[tuple]] = [None] * len(shapes)
    # Shapes whose generic points are one shared constant go in one group per constant (no per-shape copy
    # of the points); the others (tapered cylinders) in one group of their own points.
    groups: dict[int, tuple[np.ndarray, list[int]]] = {}
    varied_rows, varied_points = [], []
    for i, s in enumerate(shapes):
        pts = _BOX_CORNERS.get(s.kind)
        if pts is not None:
            groups.setdefault(id(pts), (pts, []))[1].append(i)
            continue
        pts = _analytic_generic_points(s)
        if pts is not None:
            varied_rows.append(i)
            varied_points.append(pts)
    batches = list(groups.values())
    if varied_rows:
        batches.append((np.stack(varied_points), varied_rows))
    for pts, rows in batches:
        m = stack[rows]
        world = pts @ m[:, :3, :3].transpose(0, 2, 1) + m[:, None, :3, 3]
        lo, hi = world.min(axis=1), world.max(axis=1)
        centers = list(0.5 * (lo + hi))
        extent = hi - lo
        radius = (np.sqrt(np.einsum("ij,ij->i", extent, extent)) * 0.5 * (1 + 1e-9)).tolist()
        for i, center, r in zip(rows, centers, radius):
            out[i] = (center, r)
    return out


#: Primitive.generic_size of the kinds where it is a constant (compile_scene stores it for them).
_FIXED_GENERIC_SIZE = {"sphere": 1.0, "cube": 1.0, "square": 1.0, "plane": 1.0, "torus": 1.0 + TORUS_TUBE_RADIUS}


class Primitive:
    """One shape, ready to intersect world rays.

    ``inverse`` and ``bounds`` (centre, radius), when given, are what _checked_inverse and the bounding
    sphere would compute: compile_scene computes them for all shapes at once."""

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
        entry = shapes.KINDS[shape.kind]
        self.thin = entry.thin
        self.bounded = entry.bounded
        self._intersect = entry.function("intersect") if entry.intersect else None
        self._normals_agree = entry.normals_agree
        self.tolerances = numerics.TOLERANCES
        #: numerics.inverse_rounding of the matrix (compile_scene fills it for all shapes at once)
        self.inverse_error: Optional[float] = None
        self._mesh = None
        self._planes = None
        if shape.kind in POLYHEDRON_KINDS:
            from .geometry.polyhedra import face_planes
            self._planes = face_planes(shape.kind)
        elif shape.kind in ("teapot", "mesh"):
            # Instances of one mesh (the same MeshData) share one BVH, and so do meshes of the same content.
            cache = {} if mesh_cache is None else mesh_cache
            key = id(shape.mesh)
            if key not in cache:
                cache[key] = (shape.mesh, shared_triangle_mesh(shape.mesh))
            self._mesh = cache[key][1]
        self.center, self.radius = self._world_bounding_sphere() if bounds is None else bounds

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
        """The generic shape's extent (its hit points' coordinates are of this size)."""
        if self.kind == "torus":
            return 1.0 + TORUS_TUBE_RADIUS
        pts = self._generic_points() if self.kind not in ("sphere", "cube", "square", "plane") else None
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

    def time_errors(self, origins, o_generic, d_generic, hits: HitArrays) -> np.ndarray:
        """Bounds on the rounding of ``hits.t`` (generic normals still) for world rays from ``origins``."""
        linear, translation = self.inverse_norms
        raw_scale = linear * np.max(np.abs(origins), axis=1) + translation
        # (plus the shape's own root error, where it has one: the torus)
        return hits.error + numerics.generic_time_error(hits.t, raw_scale, o_generic, d_generic, hits.normal,
                                                        self.generic_size, self.rounding)

    def world_corners(self) -> Optional[np.ndarray]:
        pts = self._generic_points()
        return None if pts is None else transform_points(self.matrix, pts)

    def generic_hits(self, o: np.ndarray, d: np.ndarray) -> HitArrays:
        if self._intersect is not None:
            return self._intersect(o, d)
        kind = self.kind
        if kind == "square":
            return analytic.intersect_square(o, d, self.tolerances.square_edge)
        if kind == "plane":
            return analytic.intersect_plane(o, d)
        if kind in ("taperedCylinder", "cylinder", "cone"):
            return analytic.intersect_tapered_cylinder(o, d, self.shape.small_radius)
        if kind == "torus":
            return intersect_torus(o, d, self.tolerances)
        if self._planes is not None:
            return analytic.intersect_convex_polyhedron(o, d, *self._planes)
        return self._mesh.all_hits(o, d)

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> HitArrays:
        """All hits along the whole world lines, world normals, ``shape`` = this primitive's index."""
        n = origins.shape[0]
        candidates = self.may_hit(origins, directions)
        idx = np.nonzero(candidates)[0]
        o, d = self.to_generic(origins[idx], directions[idx])
        # Move each generic origin to the line's point nearest the generic centre: every shape's
        # equation then has O(1) coefficients, however far away the ray started.
        with np.errstate(invalid="ignore", divide="ignore"):
            shift = -numerics.dot3(o, d) / numerics.dot3(d, d)
        shift = np.where(np.isfinite(shift), shift, 0.0)
        centred = o + shift[:, None] * d
        local = self.generic_hits(centred, d)
        if self._normals_agree:
            analytic.agree_with_crossing(local, d)
        local.t = local.t + shift[:, None]
        local.error = self.time_errors(origins[idx], centred, d, local)
        local.normal = local.normal @ self.normal_matrix
        local.shape[np.isfinite(local.t)] = self.index
        if self.thin:
            local = sheet_to_pairs(local)
        if idx.size == n:
            return local
        full = HitArrays.empty(n, local.slots)
        for name in ("t", "entering", "normal", "part", "uv", "shape", "inside_at_start", "error"):
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
            local.error = self.time_errors(origins[idx], o, d, local)
            local.normal = local.normal @ self.normal_matrix
            local.shape[np.isfinite(local.t)] = self.index
            for name in ("t", "entering", "normal", "part", "uv", "shape", "error"):
                getattr(out, name)[idx] = getattr(local, name)
        return out

    def occludes(self, origins, directions, t_min, t_max) -> np.ndarray:
        """Whether anything of this shape lies on each ray between t_min and t_max (shadow feelers)."""
        if self._mesh is None:
            return np.isfinite(self.first_hit(origins, directions, t_min, t_max).t[:, 0])
        blocked = np.zeros(origins.shape[0], dtype=bool)
        idx = np.nonzero(self.may_hit(origins, directions))[0]
        if idx.size:
            o, d = self.to_generic(origins[idx], directions[idx])
            blocked[idx] = self._mesh.any_hit(o, d, t_min[idx], t_max[idx])
        return blocked

    def to_generic(self, origins, directions):
        return transform_points(self.inverse, origins), directions @ self.inverse[:3, :3].T

    def may_hit(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        """Rays whose line passes within the bounding sphere (all rays for unbounded shapes)."""
        return lines_near_sphere(self.center, self.radius, origins, directions)


class CSGNode:
    def __init__(self, op: str, left: "Node", right: "Node"):
        self.op = op
        self.left = left
        self.right = right
        self.thin = False
        self.bounded = left.bounded and (op != "union" or right.bounded)
        self.center, self.radius = self._bound()

    def _bound(self):
        if self.op == "union":
            if not self.bounded:
                return None, np.inf
            lo = np.minimum(self.left.center - self.left.radius, self.right.center - self.right.radius)
            hi = np.maximum(self.left.center + self.left.radius, self.right.center + self.right.radius)
            return 0.5 * (lo + hi), float(np.linalg.norm(hi - lo) * 0.5)
        if self.op == "intersection" and not self.left.bounded:
            return self.right.center, self.right.radius
        return self.left.center, self.left.radius

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
        return lines_near_sphere(self.center, self.radius, origins, directions)

    def intersect(self, origins: np.ndarray, directions: np.ndarray) -> HitArrays:
        return fold_tree(self, lambda prim: prim.intersect(origins, directions),
                         lambda node, left, right: combine(node.op, left, right))


    def first_hit(self, origins, directions, t_min, t_max) -> HitArrays:
        return first_after(self.intersect(origins, directions), t_min, t_max)

    def occludes(self, origins, directions, t_min, t_max) -> np.ndarray:
        return np.isfinite(self.first_hit(origins, directions, t_min, t_max).t[:, 0])


Node = Union[Primitive, CSGNode]


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


@dataclass
class MaterialTable:
    """Materials as arrays indexed by material id (so shading gathers per ray)."""

    materials: list[Material]
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

    def __post_init__(self) -> None:
        m = self.materials
        self.ambient = np.array([x.ambient for x in m], dtype=float).reshape(-1, 3)
        self.diffuse = np.array([x.diffuse for x in m], dtype=float).reshape(-1, 3)
        self.specular = np.array([x.specular for x in m], dtype=float).reshape(-1, 3)
        self.emissive = np.array([x.emissive for x in m], dtype=float).reshape(-1, 3)
        self.specular_exponent = np.array([x.specular_exponent for x in m], dtype=float)
        self.specular_fraction = np.array([x.specular_fraction for x in m], dtype=float)
        self.surface_roughness = np.array([x.surface_roughness for x in m], dtype=float)
        self.reflectivity = np.array([x.reflectivity for x in m], dtype=float)
        self.transparency = np.array([x.transparency for x in m], dtype=float)
        self.speed_of_light = np.array([x.speed_of_light for x in m], dtype=float)


@dataclass
class CompiledScene:
    scene: Scene
    objects: list[Node]
    primitives: list[Primitive]
    materials: MaterialTable
    light_positions: np.ndarray  # (L, 3)
    light_colors: np.ndarray  # (L, 3)
    effects: frozenset[str]
    textures: Optional[object] = None  # tracer.textures.TextureSet when the scene uses textures
    tolerances: numerics.Tolerances = field(default_factory=lambda: numerics.TOLERANCES)

    @property
    def settings(self):
        return self.scene.settings


def _compile_object(obj: SceneObject, primitives: list[Primitive], material_ids: dict, mesh_cache: dict,
                    inverses: Optional[np.ndarray] = None, bounds: Optional[list] = None) -> Node:
    def leaf(shape: Shape) -> Primitive:
        mat_id = material_ids.setdefault(shape.material, len(material_ids))
        index = len(primitives)
        prim = Primitive(shape, index, mat_id, mesh_cache, inverse=None if inverses is None else inverses[index],
                         bounds=None if bounds is None else bounds[index])
        primitives.append(prim)
        return prim

    return fold_tree(obj, leaf, lambda node, left, right: CSGNode(node.op, left, right))


def live_effects(scene: Scene) -> frozenset[str]:
    """Which effects this scene can show at all; the tracer computes nothing for the others."""
    settings = scene.settings
    shapes = scene.shapes()
    materials = [s.material for s in shapes]
    effects = {f"shape:{s.kind}" for s in shapes}
    lit = any(any(c > 0 for c in m.diffuse + m.specular) for m in materials)
    if scene.lights and lit:
        effects.add("lighting")
        effects.add("shadows")
    deep = settings.max_recursion_depth > 0
    if deep and any(m.reflectivity >= settings.min_reflectivity and m.reflectivity > 0 for m in materials):
        effects.add("reflection")
    if deep and any(m.transparency >= settings.min_transparency and m.transparency > 0 for m in materials):
        effects.add("refraction")
    if any(isinstance(o, CSG) for o in scene.objects):
        effects.add("csg")
    if any(m.texture != 0 for m in materials):
        effects.add("textures")
    if "lighting" in effects and any(m.specular_fraction > 0 for m in materials):
        effects.add("cook-torrance")
    return frozenset(effects)


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
    h = hashlib.blake2b(digest_size=20)
    for array in (mesh.vertices, mesh.normals):
        array = np.ascontiguousarray(array, dtype=np.float64)
        h.update(repr(array.shape).encode())
        h.update(array.tobytes())
    faces = mesh.faces
    if isinstance(faces, FaceList):
        h.update(b"packed")
        for array in (faces.sizes, faces.vertex_index, faces.normal_index):
            h.update(b"-" if array is None else np.ascontiguousarray(array, dtype=np.int64).tobytes())
    else:
        h.update(b"list")
        h.update(repr([(tuple(map(int, v)), tuple(map(int, n))) for v, n in faces]).encode())
    return h.digest()


def shared_triangle_mesh(mesh: MeshData):
    """The TriangleMesh (BVH and triangle tables) of a mesh: built once per content, shared after."""
    from .intersect import mesh as mesh_module

    key = (mesh_digest(mesh), mesh_module.BOX_PADDING)  # (the one build constant a test may change)
    built = _TRIANGLE_MESHES.get(key)
    if built is None:
        built = mesh_module.TriangleMesh(mesh)
        _TRIANGLE_MESHES[key] = built
    return built


def content_key(scene: Scene) -> tuple:
    """Everything compile_scene reads from a scene, in a form that compares quickly (see _content)."""
    return _content(scene)[0]


def _content(scene: Scene) -> tuple:
    """Everything compile_scene reads from a scene, in a form that compares quickly: two scenes (or one
    scene at two times) with equal keys compile to the same thing.

    Objects are compared by identity *and* by what compile_scene reads from them (kind, material, taper,
    matrix, mesh content; a boolean's operation and operands), so replacing, reordering or editing any of
    them, even a matrix changed in place, gives another key.  Pixmap files count with their size and
    modification time.  The key holds no object: ids stay meaningful because the cached entry keeps the
    objects alive (see compile_scene).  Returns (key, nodes, shapes, matrices): the nodes to keep alive, and
    the shapes in iter_shapes order with their stacked matrices, for _compile."""
    nodes, shapes, structure = [], [], []
    todo = list(reversed(scene.objects))
    while todo:
        node = todo.pop()
        nodes.append(node)
        if isinstance(node, CSG):
            structure.append((node.op, id(node.left), id(node.right)))
            todo += (node.right, node.left)
        else:
            shapes.append(node)
    stack = _stacked_matrices(shapes)
    matrices = hashlib.blake2b(digest_size=20)
    if stack is not None:
        matrices.update(stack.tobytes())
    else:  # (a matrix that is not a float64 4x4: compiling will say which)
        matrices.update(repr([np.asarray(s.matrix).tolist() for s in shapes]).encode())
    meshes = {id(s.mesh): s.mesh for s in shapes if s.mesh is not None}
    pixmaps = []
    for number, path in sorted(scene.pixmaps.items()):
        try:
            stat = os.stat(path)
            pixmaps.append((number, str(path), stat.st_size, stat.st_mtime_ns))
        except (OSError, ValueError):  # (a missing file, a name with a NUL: compiling reports it)
            pixmaps.append((number, str(path), None, None))
    fields = (tuple(map(attrgetter(name), shapes)) for name in ("kind", "material", "tapered_radius"))
    return (tuple(map(id, nodes)), tuple(structure), *fields, tuple(id(s.mesh) for s in shapes),
            tuple((k, mesh_digest(m)) for k, m in meshes.items()),
            matrices.digest(), tuple(scene.lights), scene.camera, astuple(scene.settings), tuple(pixmaps),
            numerics.TOLERANCES), \
        nodes, shapes, stack


def compile_scene(scene: Scene) -> CompiledScene:
    """The scene ready to trace.  Compiled once: the result is kept on the scene with its content_key, and
    returned again for as long as the scene's content has not changed."""
    with one_blas_thread(), collector_paused():
        key, nodes, shapes, stack = _content(scene)
        holder = getattr(scene, _CACHE_ATTRIBUTE, None)
        cached = holder.entry if isinstance(holder, _CompiledHolder) else None
        if cached is not None and cached[0] == key:
            return cached[1]
        compiled = _compile(scene, shapes, stack)
    # (the nodes are kept so that the ids in the key cannot be reused by new objects while it is cached)
    setattr(scene, _CACHE_ATTRIBUTE, _CompiledHolder((key, compiled, nodes)))
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


def _compile(scene: Scene, shapes: Optional[list[Shape]] = None, stack: Optional[np.ndarray] = None) -> CompiledScene:
    """Compile ``scene``; ``shapes`` (in iter_shapes order) and their ``stack`` of matrices may be passed
    in when the caller has them already (compile_scene's content key does)."""
    primitives: list[Primitive] = []
    material_ids: dict[Material, int] = {}
    mesh_cache: dict = {}
    # Inverses and bounding spheres for all shapes at once (iter_shapes visits them in the order
    # _compile_object numbers them): a scene of 10,000 spheres would otherwise spend most of its compile time
    # in 10,000 small NumPy calls of each kind.
    if shapes is None:
        shapes = [s for obj in scene.objects for s in iter_shapes(obj)]
        stack = _stacked_matrices(shapes)
    inverses = _batched_inverses(stack)
    # Only with every matrix checked (finite, affine, invertible): otherwise the shapes are compiled one by
    # one as before, and the first bad one raises.
    bounds = _batched_bounds(shapes, stack) if inverses is not None else None
    objects = [_compile_object(obj, primitives, material_ids, mesh_cache, inverses, bounds) for obj in scene.objects]
    if inverses is not None and primitives:
        errors = numerics.inverse_rounding(inverses, stack)
        for prim, error in zip(primitives, errors.tolist()):
            prim.inverse_error = error
            size = _FIXED_GENERIC_SIZE.get(prim.kind)
            if size is not None:  # (what generic_size gives these kinds, without its cached property's lock)
                prim.__dict__["generic_size"] = size
    table = MaterialTable(list(material_ids) or [Material()])
    lights = scene.lights
    effects = live_effects(scene)
    textures = None
    if "textures" in effects:
        from .textures import TextureSet
        textures = TextureSet(scene, primitives)
    return CompiledScene(
        scene=scene, objects=objects, primitives=primitives, materials=table,
        light_positions=np.array([l.position for l in lights], dtype=float).reshape(-1, 3),
        light_colors=np.array([l.color for l in lights], dtype=float).reshape(-1, 3),
        effects=effects, textures=textures)
