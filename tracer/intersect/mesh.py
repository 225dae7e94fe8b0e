"""Rays against triangle meshes: a bounding volume hierarchy built and traversed in NumPy.

A mesh is kept *vertex-indexed* (see :class:`TriangleMesh`): the file's vertex and normal arrays, three
int32 indices per triangle into each, the leaf order of the triangles, and compact BVH nodes (32 bytes,
single-precision boxes rounded outward).  Everything a hit test needs per triangle (edges, scales for the
tolerances, the geometric normal, the orientation) is computed from the vertices where it is needed, in the
same order of operations as the C core (mesh.h), which walks the very same arrays.  The NumPy traversal is
*packet*-style: a Python stack holds ``(node, active rays)`` pairs, every node is visited at most once per
call, with the subset of rays whose slab test passed, and a leaf tests all its rays against all its
triangles at once (a vectorised Möller–Trumbore).  The Python overhead is therefore per node, not per ray,
which is what makes coherent batches fast.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from ..errors import SceneError
from ..model import FaceList, MeshData
from ..numerics import dot3
from .hits import HitArrays

#: Inclusive slack on the barycentric test, so that a ray through an edge or vertex shared by two
#: triangles is never missed by both because of rounding.  It is a bound on that rounding, per ray and
#: triangle: ROUNDING_FACTOR * machine epsilon * |d| L (|e| + R) / |det|, where L = |origin| + R bounds
#: every coordinate involved and R is the triangle's largest vertex norm (the errors of s = O - P0 and
#: of the edge vectors are ~eps L and ~eps R, and the barycentrics divide by det).  Keeping the slack
#: as small as the rounding keeps the band of doubly-hit rays around an edge tiny, so that the doubles
#: it does produce lie within the deduplication window below.  The price of any slack: a line passing
#: *outside* a convex edge closer than the slack (~1e-13 of the coordinates) may keep a lone hit on one
#: of the two faces; a watertight test (Woop et al. 2013) would close that too.
ROUNDING_FACTOR = 64.0
#: ... but never more than this (near-parallel rays have a tiny det and ill-conditioned barycentrics).
BARYCENTRIC_EPSILON_MAX = 1e-10
#: A ray is parallel to a triangle's plane when |d . (e1 x e2)| <= this * |d| |e1| |e2|: there the hit
#: time is pure rounding noise, so no hit is reported (and no NaN or inf is produced).
PARALLEL_EPSILON = 1e-12
#: Two hits of one ray with the same entering sign whose times differ by at most this (relative to
#: |t|, plus the same fraction of the mesh's size in ray-parameter units) are one crossing: a shared
#: edge or vertex hit twice through the slack above, or coincident faces.
DEDUPE_RELATIVE = 1e-12
#: The same, for two triangles that share a vertex (by position): rounding in a hit time grows with
#: the coordinates and with 1/cos of the angle of incidence, so a neighbour's double can stray further
#: than 1e-12 (about 10^6 ulps: far above any rounding, far below any feature).
DEDUPE_RELATIVE_ADJACENT = 1e-9
#: Node boxes are grown by this fraction of the mesh's size (plus its distance from the origin), so
#: that rounding in the slab test can never cull a triangle that Möller–Trumbore, with its slack, hits.
BOX_PADDING = 1e-9


#: One BVH node as the C core reads it (mesh.h's MeshNode, 32 bytes): the box in single precision, rounded
#: outward from the padded double-precision box; ``offset`` is an inner node's left child (the right one is
#: ``offset + 1``) or a leaf's first slot in ``tri_order``; ``count`` is a leaf's number of triangles (0 for
#: an inner node); ``axis`` the axis an inner node was split along (-1 for a leaf).
NODE = np.dtype({"names": ["lo", "hi", "offset", "count", "axis", "pad"],
                 "formats": [("<f4", (3,)), ("<f4", (3,)), "<i4", "<u2", "i1", "u1"],
                 "offsets": [0, 12, 24, 28, 30, 31], "itemsize": 32})
#: A BVH builder that can stand in for the NumPy one (TriangleMesh's ``builder``): (vertices (V, 3), triangles'
#: vertex indices (T, 3) int32, leaf size, bins, box padding) -> (NODE records, leaf order int32).
BvhBuilder = Callable[[np.ndarray, np.ndarray, int, int, float], tuple[np.ndarray, np.ndarray]]
#: A leaf's triangle count must fit the node's 16 bits; indices and offsets are int32.
MAX_LEAF_SIZE = 2**16 - 1
MAX_INDEX = 2**31 - 1


@dataclass(frozen=True)
class MeshArrays:
    """A :class:`TriangleMesh` as the C core walks it (the mesh's own arrays, no copies).

    ``nodes`` (M,) :data:`NODE` records; ``tri_order`` (T,) int32: leaf slot -> triangle; ``tri_vertex``
    (T, 3) int32 vertex indices per triangle; ``tri_normal`` (T, 3) int32 normal indices (a triangle with any
    index below 0 has no normals), or None when no triangle has normals; ``vertices`` (V, 3) and ``normals``
    (N, 3) float64 as the mesh gives them (normals need not be unit)."""

    nodes: np.ndarray
    tri_order: np.ndarray
    tri_vertex: np.ndarray
    tri_normal: "np.ndarray | None"
    vertices: np.ndarray
    normals: np.ndarray
    extent: float
    tri_uv: "np.ndarray | None" = None


class TriangleMesh:
    """A triangle mesh in generic coordinates with a BVH, answering all-hits, closest-hit and any-hit.

    Triangles are ``MeshData.triangles()`` (fan triangulation of the faces); ``part`` in the hits is the
    index into that list and ``uv`` holds the barycentrics (b1, b2) of the hit, so the hit point is
    ``(1 - b1 - b2) P0 + b1 P1 + b2 P2``.

    Orientation: the *geometric normal* of a triangle is its winding normal (P1 - P0) x (P2 - P0),
    flipped when the triangle's unit vertex normals, summed, point against it (triangles without normals
    keep the winding).  A hit is *entering* when ``direction . geometric normal < 0``.  The reported
    normal is the shading normal: the barycentric interpolation of the (unit) vertex normals, or the
    geometric normal where the triangle has none, where the interpolation is degenerate or where it falls
    on the inner side of the geometric normal.  All reported normals are unit length.

    Shared edges and vertices: the barycentric test is inclusive with a slack the size of the rounding
    (see ROUNDING_FACTOR), and all-hits merges hits of one ray with the same entering sign at the same
    time (see DEDUPE_RELATIVE), so a ray through an edge or vertex crosses the surface once.  Two
    triangles *touch* when they share a vertex index or a vertex position.

    Memory (vertex-indexed, nothing per triangle but indices): ``vertices`` (V, 3) and ``normals`` (N, 3)
    float64 are the MeshData's own arrays; ``tri_vertex`` and ``tri_normal`` (T, 3) int32 are views of its
    FaceList when every face is a triangle (one array when the normal indices equal the vertex indices);
    ``tri_order`` (T,) int32; ``nodes`` (M,) :data:`NODE`; ``tri_uv`` (T, 6) float64, the (u, v) of each
    triangle's corners from MeshData.corner_uvs, or None.

    BVH: binned surface-area heuristic (``bins`` buckets along the longest axis of the centroids),
    split until a node holds at most ``leaf_size`` triangles.  Node 0 is the root, each inner node's
    children are allocated together; a leaf's triangles are ``tri_order[offset : offset + count]``.
    ``builder(vertices, tri_vertex, leaf_size, bins, pad) -> (nodes, tri_order)`` builds it instead of
    the NumPy builder here: it must build the very same tree (tracer.compile hands over the C core's,
    tracer.native.build_mesh_bvh, which does).
    """

    def __init__(self, mesh: MeshData, leaf_size: int = 8, bins: int = 16, builder: Optional[BvhBuilder] = None
                 ) -> None:
        if not 1 <= leaf_size <= MAX_LEAF_SIZE or bins < 2:
            raise ValueError(f"leaf_size must be in 1..{MAX_LEAF_SIZE} and bins at least 2")
        vertices, normals = _rows_of_three(mesh.vertices), _rows_of_three(mesh.normals)
        if max(len(vertices), len(normals)) > MAX_INDEX:
            raise SceneError(f"mesh {mesh.origin!r}: more than {MAX_INDEX} vertices or normals")
        tri_v, tri_n = _indexed_triangles(mesh)
        if tri_v.size and (tri_v.min() < 0 or tri_v.max() >= len(vertices)):
            raise SceneError(f"mesh {mesh.origin!r}: a face uses a vertex index out of range")
        if tri_n is not None and tri_n.size and tri_n.max() >= len(normals):
            raise SceneError(f"mesh {mesh.origin!r}: a face uses a normal index out of range")
        self.vertices, self.normals = vertices, normals
        self.tri_vertex, self.tri_normal = tri_v, tri_n
        self.triangle_count = len(tri_v)
        self.tri_uv = _triangle_uvs(mesh)

        # The mesh's size (of the vertices the triangles use) gives absolute scales for box padding and hit
        # deduplication.
        if len(tri_v):
            used = np.zeros(len(vertices), dtype=bool)
            used[tri_v.reshape(-1)] = True
            where = used[:, None]
            self.bounds = np.stack([np.min(vertices, axis=0, where=where, initial=np.inf),
                                    np.max(vertices, axis=0, where=where, initial=-np.inf)])
            del used, where
        else:
            self.bounds = np.zeros((2, 3))
        self.extent = float(np.max(self.bounds[1] - self.bounds[0], initial=0.0)) or 1.0
        self._magnitude = float(np.max(np.abs(self.bounds), initial=0.0))
        self._build_bvh(leaf_size, bins, builder)

    # ------------------------------------------------------------------ BVH construction

    def _build_bvh(self, leaf_size: int, bins: int, builder: Optional[BvhBuilder]) -> None:
        """Binned-SAH BVH over the triangles' bounding boxes (split candidates from the centroids): by
        ``builder`` when given, else in NumPy."""
        pad = BOX_PADDING * (self.extent + self._magnitude)
        if builder is not None:
            self.nodes, self.tri_order = builder(self.vertices, self.tri_vertex, leaf_size, bins, pad)
        else:
            self.nodes, self.tri_order = _build_bvh_numpy(*self._boxes_and_centroids(), leaf_size, bins, pad)
        # Column views for the NumPy traversal.
        self.node_lo, self.node_hi = self.nodes["lo"], self.nodes["hi"]
        self.node_offset, self.node_count, self.node_axis = (self.nodes["offset"], self.nodes["count"],
                                                              self.nodes["axis"])

    def _boxes_and_centroids(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(T, 3) each: the triangles' boxes, min(min(P0, P1), P2) and max(...), and centroids (P0 + P1 + P2) / 3
        summed in corner order (bvh_build.h computes the same numbers), one corner at a time, in place."""
        tri_v, vertices = self.tri_vertex, self.vertices
        corner = vertices[tri_v[:, 0]]
        tri_lo, tri_hi, centroid = corner.copy(), corner.copy(), corner
        for k in (1, 2):
            corner = vertices[tri_v[:, k]]
            np.minimum(tri_lo, corner, out=tri_lo)
            np.maximum(tri_hi, corner, out=tri_hi)
            centroid += corner
        del corner
        centroid /= 3.0
        return tri_lo, tri_hi, centroid

    @property
    def node_total(self) -> int:
        return len(self.nodes)

    def arrays(self) -> MeshArrays:
        """The tables another tracer needs to walk this mesh exactly as the queries below do."""
        return MeshArrays(nodes=self.nodes, tri_order=self.tri_order, tri_vertex=self.tri_vertex,
                          tri_normal=self.tri_normal, vertices=self.vertices, normals=self.normals,
                          extent=self.extent, tri_uv=self.tri_uv)

    def kept_arrays(self) -> list[np.ndarray]:
        """Every array this mesh keeps alive (some are the MeshData's own): what it costs in memory."""
        arrays = [self.nodes, self.tri_order, self.tri_vertex, self.vertices, self.normals]
        return arrays + [a for a in (self.tri_normal, self.tri_uv) if a is not None]

    def texture_uv(self, tri: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """The texture coordinates (u, v) at barycentrics (b1, b2) of triangles ``tri`` (the mesh has
        ``tri_uv``): its corners' interpolated (texture.h's mesh_uv)."""
        corner = self.tri_uv[tri]
        w0 = 1.0 - b1 - b2
        u = (w0 * corner[:, 0] + b1 * corner[:, 2]) + b2 * corner[:, 4]
        v = (w0 * corner[:, 1] + b1 * corner[:, 3]) + b2 * corner[:, 5]
        return u, v

    # ------------------------------------------------------------------ per-triangle values

    def _corners(self, tri: np.ndarray):
        """(P0, P1, P2) of triangles ``tri`` (original order), each (n, 3)."""
        index = self.tri_vertex[tri]
        return self.vertices[index[:, 0]], self.vertices[index[:, 1]], self.vertices[index[:, 2]]

    def _frame(self, tri: np.ndarray):
        """(P0, E1 = P1 - P0, E2 = P2 - P0) of triangles ``tri``."""
        p0, p1, p2 = self._corners(tri)
        return p0, p1 - p0, p2 - p0

    def winding_normals(self, tri: np.ndarray) -> np.ndarray:
        """The winding normals E1 x E2 (tri.shape + (3,)) of triangles ``tri`` (original order; below 0: the
        first), as the C core's mesh_winding forms them: the normal of the plane a hit's t was solved in."""
        _, e1, e2 = self._frame(np.maximum(tri, 0).ravel())
        return _cross(e1, e2).reshape(tri.shape + (3,))

    def _unit_corner_normals(self, tri: np.ndarray):
        """The three unit vertex normals of triangles ``tri`` ((n, 3) each; zero for a zero normal) and which
        triangles have normals at all (zeros for those that have not)."""
        n = len(tri)
        if self.tri_normal is None or not len(self.normals):
            zero = np.zeros((n, 3))
            return (zero, zero, zero), np.zeros(n, dtype=bool)
        index = self.tri_normal[tri]
        has = (index >= 0).all(axis=1)
        corners = []
        for k in range(3):
            v = self.normals[np.where(has, index[:, k], 0)]
            length = np.sqrt(dot3(v, v))[:, None]
            usable = has[:, None] & (length > 0)
            with np.errstate(all="ignore"):
                corners.append(np.where(usable, v / length, 0.0))
        return tuple(corners), has

    @staticmethod
    def _geometric(e1: np.ndarray, e2: np.ndarray, corners):
        """(winding normal E1 x E2, flip): flip where the unit corner normals, summed, point against it."""
        winding = _cross(e1, e2)
        summed = corners[0] + corners[1]
        summed += corners[2]
        return winding, dot3(summed, winding) < 0

    # ------------------------------------------------------------------ queries
    def all_hits(self, origins: np.ndarray, directions: np.ndarray) -> HitArrays:
        """Every crossing of each whole line ``origin + t direction`` (t from -inf to +inf), sorted by t.

        K is the largest number of hits of any ray.  Crossings of a shared edge or vertex are reported
        once per entering sign; where an enter and an exit coincide (grazing an edge), the one that
        makes the sequence alternate comes first.
        """
        rays = _Rays(origins, directions)
        found: list[tuple[np.ndarray, ...]] = []

        def on_leaf(node, idx, t, b1, b2, hit):
            ray_pos, tri_pos = np.nonzero(hit)
            if len(ray_pos):
                first = self.node_offset[node]
                found.append((idx[ray_pos], first + tri_pos, t[ray_pos, tri_pos],
                              b1[ray_pos, tri_pos], b2[ray_pos, tri_pos]))

        self._traverse(rays, np.full(rays.n, -np.inf), np.full(rays.n, np.inf), on_leaf, shrink=False)
        if not found:
            return HitArrays.empty(rays.n, 0)
        ray, slot, t, b1, b2 = (np.concatenate(column) for column in zip(*found))
        entering = self._entering(rays.directions[ray], slot)
        ray, slot, t, b1, b2, entering = _dedupe_and_order(
            ray, slot, t, b1, b2, entering, rays.speed, self.extent, self._touching)

        # Scatter the hits, now sorted by (ray, t), into (N, K) slots.
        counts = np.bincount(ray, minlength=rays.n)
        k = int(counts.max())
        column = np.arange(len(ray)) - np.repeat(np.cumsum(counts) - counts, counts)
        out = HitArrays.empty(rays.n, k)
        out.t[ray, column] = t
        out.entering[ray, column] = entering
        out.part[ray, column] = self.tri_order[slot]
        out.uv[ray, column, 0] = b1
        out.uv[ray, column, 1] = b2
        out.normal[ray, column] = self._shading_normal(self.tri_order[slot], b1, b2)
        return out

    def closest_hits(self, origins: np.ndarray, directions: np.ndarray, t_min=0.0, t_max=np.inf) -> HitArrays:
        """The first hit with ``t_min < t < t_max`` per ray (K = 1; t = inf and part = -1 for a miss)."""
        rays = _Rays(origins, directions)
        best_t = np.array(np.broadcast_to(np.asarray(t_max, dtype=np.float64), (rays.n,)))
        lower = np.array(np.broadcast_to(np.asarray(t_min, dtype=np.float64), (rays.n,)))
        best_slot = np.full(rays.n, -1, dtype=np.int64)
        best_b = np.zeros((rays.n, 2))

        def on_leaf(node, idx, t, b1, b2, hit):
            # Hits beyond the best so far (or t_max) lose the comparison below.
            candidate = np.where(hit & (t > lower[idx, None]), t, np.inf)
            pick = np.argmin(candidate, axis=1)
            rows = np.arange(len(idx))
            better = candidate[rows, pick] < best_t[idx]
            winners, pick = idx[better], pick[better]
            rows = rows[better]
            best_t[winners] = candidate[rows, pick]
            best_slot[winners] = self.node_offset[node] + pick
            best_b[winners, 0] = b1[rows, pick]
            best_b[winners, 1] = b2[rows, pick]

        self._traverse(rays, lower, best_t, on_leaf, shrink=True)
        out = HitArrays.empty(rays.n, 1)
        hit = np.flatnonzero(best_slot >= 0)
        slot = best_slot[hit]
        out.t[hit, 0] = best_t[hit]
        out.entering[hit, 0] = self._entering(rays.directions[hit], slot)
        out.part[hit, 0] = self.tri_order[slot]
        out.uv[hit, 0] = best_b[hit]
        out.normal[hit, 0] = self._shading_normal(self.tri_order[slot], best_b[hit, 0], best_b[hit, 1])
        return out

    def any_hit(self, origins: np.ndarray, directions: np.ndarray, t_min=0.0, t_max=np.inf) -> np.ndarray:
        """(N,) bool: the ray meets the mesh somewhere with ``t_min < t < t_max`` (shadow rays)."""
        rays = _Rays(origins, directions)
        upper = np.array(np.broadcast_to(np.asarray(t_max, dtype=np.float64), (rays.n,)))
        lower = np.array(np.broadcast_to(np.asarray(t_min, dtype=np.float64), (rays.n,)))
        blocked = np.zeros(rays.n, dtype=bool)

        def on_leaf(node, idx, t, b1, b2, hit):
            hit &= (t > lower[idx, None]) & (t < upper[idx, None])
            blocked[idx[hit.any(axis=1)]] = True

        self._traverse(rays, lower, upper, on_leaf, shrink=False, done=blocked)
        return blocked

    # ------------------------------------------------------------------ traversal

    def _traverse(self, rays: "_Rays", lower: np.ndarray, upper: np.ndarray, on_leaf, shrink: bool,
                  done: np.ndarray | None = None) -> None:
        """Walk the BVH with the packet of rays, calling ``on_leaf`` with each leaf's Möller–Trumbore.

        ``lower``/``upper`` (N,) bound the interval a box must overlap; ``upper`` is read afresh at every
        node, so a caller that lowers it (closest hit) prunes the rest of the walk.  With ``shrink`` the
        child nearer to most of the rays (by the sign of their summed direction along the node's split
        axis) is visited first.  Rays flagged in
        ``done`` (any-hit) are dropped from the packet as soon as they are.
        """
        if rays.n == 0 or self.node_total == 0:
            return
        stack = [(0, np.arange(rays.n))]
        with np.errstate(all="ignore"):
            while stack:
                node, idx = stack.pop()
                if done is not None:
                    idx = idx[~done[idx]]
                    if not len(idx):
                        continue
                idx = idx[self._slab(node, rays, idx, lower[idx], upper[idx])]
                if not len(idx):
                    continue
                if self.node_count[node]:
                    t, b1, b2, hit = self._leaf_hits(node, rays, idx)
                    on_leaf(node, idx, t, b1, b2, hit)
                    continue
                near = int(self.node_offset[node])
                far = near + 1
                if shrink and rays.directions[idx, self.node_axis[node]].sum() < 0:
                    near, far = far, near
                stack.append((far, idx))
                stack.append((near, idx))

    def _slab(self, node: int, rays: "_Rays", idx: np.ndarray, lower: np.ndarray, upper: np.ndarray) -> np.ndarray:
        """Which of the rays ``idx`` meet the node's box for some t in [lower, upper].

        A zero direction component gives an infinite inverse: the slab is then the whole line or
        nothing, except when the origin lies exactly on the slab's plane, where 0 * inf = NaN.  NaN
        means "no constraint from this axis" (the box is closed, so such a ray does touch the slab);
        ``fmax``/``fmin`` skip NaNs, ``maximum``/``minimum`` carry them through per axis.
        """
        o = rays.origins[idx]
        inv = rays.inverse[idx]
        t_lo = (self.node_lo[node] - o) * inv
        t_hi = (self.node_hi[node] - o) * inv
        near = np.fmax.reduce(np.minimum(t_lo, t_hi), axis=1)
        far = np.fmin.reduce(np.maximum(t_lo, t_hi), axis=1)
        near = np.fmax(near, lower)
        far = np.fmin(far, upper)
        return near <= far

    def _leaf_hits(self, node: int, rays: "_Rays", idx: np.ndarray):
        """Möller–Trumbore for rays ``idx`` x the leaf's triangles: (t, b1, b2, hit), each (n, k).

        ``t`` etc. are garbage where ``hit`` is False (parallel rays are masked, never divided by 0
        into a reported value).
        """
        first = int(self.node_offset[node])
        tri = self.tri_order[first:first + int(self.node_count[node])]
        p0, p1, p2 = self._corners(tri)
        e1, e2 = p1 - p0, p2 - p0
        # Scales for the parallel test and the barycentric slack (see ROUNDING_FACTOR): the largest vertex
        # norm and the edge lengths, as mesh.h computes them.
        radius = np.maximum(np.maximum(_length(p0), _length(p1)), _length(p2))
        e1_length, e2_length = _length(e1), _length(e2)
        slack1_scale, slack2_scale = e2_length + radius, e1_length + radius
        d = rays.directions[idx][:, None, :]  # (n, 1, 3)
        s = rays.origins[idx][:, None, :] - p0  # (n, k, 3)
        pvec = _cross(d, e2)  # (n, k, 3)
        # (dot products summed as the C core's: under cancellation einsum's order decides hits differently)
        det = dot3(e1, pvec)
        qvec = _cross(s, e1)
        inv_det = 1.0 / det
        b1 = dot3(s, pvec) * inv_det
        b2 = dot3(d, qvec) * inv_det
        t = dot3(e2, qvec) * inv_det
        speed = rays.speed[idx, None]
        abs_det = np.abs(det)
        rounding = np.minimum(
            ROUNDING_FACTOR * np.finfo(float).eps * speed * (rays.magnitude[idx, None] + radius) / abs_det,
            BARYCENTRIC_EPSILON_MAX / np.maximum(slack1_scale, slack2_scale))
        slack1 = rounding * slack1_scale
        slack2 = rounding * slack2_scale
        hit = ((abs_det > PARALLEL_EPSILON * speed * (e1_length * e2_length))
               & (b1 >= -slack1) & (b2 >= -slack2) & (b1 + b2 <= 1.0 + slack1 + slack2) & np.isfinite(t))
        return t, b1, b2, hit

    # ------------------------------------------------------------------ hit attributes

    def _entering(self, directions: np.ndarray, slot: np.ndarray) -> np.ndarray:
        """direction . geometric normal < 0 for triangles given in leaf order."""
        tri = self.tri_order[slot]
        _, e1, e2 = self._frame(tri)
        corners, _ = self._unit_corner_normals(tri)
        winding, flip = self._geometric(e1, e2, corners)
        facing = dot3(directions, winding)
        return np.where(flip, facing > 0, facing < 0)

    def geometric_normals(self, tri: np.ndarray):
        """The unit geometric normals (generic, (n, 3); zero for a degenerate triangle) of triangles ``tri``
        (original order), on the side their corner normals point to, the corner normals, and which triangles
        have corner normals (are smooth-shaded).  (mesh.h's mesh_geometric_normal)"""
        _, e1, e2 = self._frame(tri)
        corners, has_normals = self._unit_corner_normals(tri)
        winding, flip = self._geometric(e1, e2, corners)
        geometric = np.where(flip[:, None], -winding, winding)
        length = _length(geometric)[:, None]
        return np.divide(geometric, length, out=np.zeros_like(geometric), where=length > 0), corners, has_normals

    def _shading_normal(self, tri: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> np.ndarray:
        """Unit shading normals for hits on triangles ``tri`` (original order) at barycentrics (b1, b2)."""
        geometric, corners, has_normals = self.geometric_normals(tri)
        smooth = ((1.0 - b1 - b2)[:, None] * corners[0] + b1[:, None] * corners[1]) + b2[:, None] * corners[2]
        length = _length(smooth)
        # Use the interpolation only where it is meaningful and on the outer side of the face.
        usable = has_normals & (length > 1e-12) & (dot3(smooth, geometric) > 0)
        with np.errstate(all="ignore"):
            smooth = smooth / length[:, None]
        return np.where(usable[:, None], smooth, geometric)

    def smooth_lift(self, tri: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """How far (generic, (n, 3)) the points at barycentrics (b1, b2) of triangles ``tri`` move onto the
        smooth surface the vertex normals describe, and which triangles have normals (a zero move for the
        others).  The point g goes to each corner's tangent plane where it lies below it, q_i = g - min(0,
        (g - p_i) . n_i) n_i, and the moves are mixed with the barycentrics (docs/tracer.md, "Smooth shadow
        terminator"; mesh.h's mesh_smooth_lift)."""
        corners, has = self._unit_corner_normals(tri)
        p0, p1, p2 = self._corners(tri)
        w0 = (1.0 - b1 - b2)[:, None]
        w1, w2 = b1[:, None], b2[:, None]
        g = (w0 * p0 + w1 * p1) + w2 * p2
        q = [g - np.minimum(dot3(g - p, n), 0.0)[:, None] * n for p, n in zip((p0, p1, p2), corners)]
        lift = ((w0 * q[0] + w1 * q[1]) + w2 * q[2]) - g
        return np.where(has[:, None], lift, 0.0), has

    def _touching(self, slot_a: np.ndarray, slot_b: np.ndarray) -> np.ndarray:
        """Do the triangles in leaf slots ``slot_a`` and ``slot_b`` share a vertex (by index or position)?"""
        a, b = self.tri_vertex[self.tri_order[slot_a]], self.tri_vertex[self.tri_order[slot_b]]
        same = a[:, :, None] == b[:, None, :]
        same |= (self.vertices[a][:, :, None, :] == self.vertices[b][:, None, :, :]).all(axis=3)
        return same.any(axis=(1, 2))


def _build_bvh_numpy(tri_lo: np.ndarray, tri_hi: np.ndarray, centroid: np.ndarray, leaf_size: int, bins: int,
                 pad: float) -> tuple[np.ndarray, np.ndarray]:
    """The reference builder (bvh_build.h builds the same tree): (NODE records, tri_order int32)."""
    t_count = len(tri_lo)
    order = np.arange(t_count, dtype=np.int64)
    lo, hi, left, right, first, count, axes = [], [], [], [], [], [], []

    def new_node() -> int:
        for column in (lo, hi):
            column.append(None)
        for column in (left, right, first, count, axes):
            column.append(-1)
        return len(lo) - 1

    if t_count == 0:
        return _node_records(lo, hi, left, first, count, axes, pad), order.astype(np.int32)

    stack = [(new_node(), 0, t_count)]  # (node, start, end) over ``order``
    while stack:
        node, start, end = stack.pop()
        members = order[start:end]
        lo[node] = tri_lo[members].min(axis=0)
        hi[node] = tri_hi[members].max(axis=0)
        n = end - start
        split = _choose_split(tri_lo[members], tri_hi[members], centroid[members], bins) \
            if n > leaf_size else None
        if split is None:
            first[node], count[node] = start, n
            continue
        axis, goes_left = split
        # Stable partition of this node's range: left members first.
        order[start:end] = np.concatenate([members[goes_left], members[~goes_left]])
        middle = start + int(goes_left.sum())
        left_child, right_child = new_node(), new_node()
        left[node], right[node], axes[node], count[node] = left_child, right_child, axis, 0
        stack.append((right_child, middle, end))
        stack.append((left_child, start, middle))
    return _node_records(lo, hi, left, first, count, axes, pad), order.astype(np.int32)

def _choose_split(tri_lo: np.ndarray, tri_hi: np.ndarray, centroid: np.ndarray, bins: int):
    """(axis, mask of triangles going left) by the surface area heuristic over ``bins`` buckets.

    The axis is the longest extent of the centroids.  When all centroids coincide there is nothing
    to bin, and the range is simply halved (so leaves stay small even for duplicate triangles).
    """
    n = len(centroid)
    c_lo, c_hi = centroid.min(axis=0), centroid.max(axis=0)
    axis = int(np.argmax(c_hi - c_lo))
    width = c_hi[axis] - c_lo[axis]
    if not (width > 0 and np.isfinite(width) and np.isfinite(bins / width)):
        return axis, _halves(n)

    bucket = np.minimum(((centroid[:, axis] - c_lo[axis]) * (bins / width)).astype(np.int64), bins - 1)
    # Per-bucket boxes: sort by bucket, then reduce each non-empty run (bucket 0 and bins-1 are
    # never empty, the centroids' minimum and maximum are in them).
    by_bucket = np.argsort(bucket, kind="stable")
    sorted_bucket = bucket[by_bucket]
    starts = np.flatnonzero(np.r_[True, sorted_bucket[1:] != sorted_bucket[:-1]])
    present = sorted_bucket[starts]
    box_lo = np.full((bins, 3), np.inf)
    box_hi = np.full((bins, 3), -np.inf)
    box_lo[present] = np.minimum.reduceat(tri_lo[by_bucket], starts, axis=0)
    box_hi[present] = np.maximum.reduceat(tri_hi[by_bucket], starts, axis=0)
    counts = np.bincount(bucket, minlength=bins)

    def half_area(lo, hi):
        size = np.maximum(hi - lo, 0.0)  # empty prefixes have inf/-inf bounds: area 0
        size[~np.isfinite(size)] = 0.0
        return size[:, 0] * size[:, 1] + size[:, 1] * size[:, 2] + size[:, 2] * size[:, 0]

    # Candidate k splits between bucket k and k+1 (k = 0 .. bins-2).
    left_area = half_area(np.minimum.accumulate(box_lo, axis=0), np.maximum.accumulate(box_hi, axis=0))[:-1]
    right_area = half_area(np.minimum.accumulate(box_lo[::-1], axis=0),
                           np.maximum.accumulate(box_hi[::-1], axis=0))[::-1][1:]
    left_count = np.cumsum(counts)[:-1]
    right_count = n - left_count
    cost = left_area * left_count + right_area * right_count
    cost[(left_count == 0) | (right_count == 0)] = np.inf
    best = int(np.argmin(cost))
    goes_left = bucket <= best
    count = int(goes_left.sum())
    return axis, (goes_left if 0 < count < n else _halves(n))  # (an empty side would never end)


def _halves(n: int) -> np.ndarray:
    """The split of a range into its first and second half (the first half goes left)."""
    goes_left = np.zeros(n, dtype=bool)
    goes_left[: n // 2] = True
    return goes_left



def _node_records(lo, hi, left, first, count, axes, pad: float) -> np.ndarray:
    """The builder's columns as NODE records: boxes padded by ``pad``, then rounded outward to single
    precision (mesh.h's bvh_store_node does the same for the C builder)."""
    nodes = np.zeros(len(count), dtype=NODE)
    if not len(count):
        return nodes
    nodes["lo"] = _single_outward(np.array(lo, dtype=np.float64).reshape(-1, 3) - pad, down=True)
    nodes["hi"] = _single_outward(np.array(hi, dtype=np.float64).reshape(-1, 3) + pad, down=False)
    count = np.array(count, dtype=np.int64)
    nodes["offset"] = np.where(count > 0, np.array(first, dtype=np.int64), np.array(left, dtype=np.int64))
    nodes["count"] = count
    nodes["axis"] = np.array(axes, dtype=np.int8)
    return nodes


def _single_outward(x: np.ndarray, down: bool) -> np.ndarray:
    """The nearest float32 at or below (``down``) or at or above ``x``; NaN stays NaN."""
    with np.errstate(over="ignore", invalid="ignore"):
        rounded = x.astype(np.float32)
        off = rounded > x if down else rounded < x
        return np.where(off, np.nextafter(rounded, np.float32(-np.inf if down else np.inf)), rounded)

def _indexed_triangles(mesh: MeshData) -> tuple[np.ndarray, "np.ndarray | None"]:
    """(T, 3) int32 vertex indices and normal indices of ``mesh.triangles()`` (None when no triangle has
    normals).  When every face is a triangle these are views of the FaceList's own arrays (no copy), and
    one array when the normal indices are the vertex indices."""
    faces = mesh.faces
    if isinstance(faces, FaceList) and faces.all_triangles():
        tri_v = _as_int32(faces.vertex_index).reshape(-1, 3)
        if faces.normal_index is None:
            return tri_v, None
        if faces.normal_index is faces.vertex_index:
            return tri_v, tri_v
        return tri_v, _as_int32(faces.normal_index).reshape(-1, 3)
    tri_v, tri_n = mesh.triangles()
    tri_v = _as_int32(tri_v)
    if not (tri_n >= 0).any():
        return tri_v, None
    return tri_v, (tri_v if np.array_equal(tri_n, tri_v) else _as_int32(tri_n))


def _triangle_uvs(mesh: MeshData) -> "np.ndarray | None":
    """(T, 6) the corner_uvs of each triangle's corners (u0 v0 u1 v1 u2 v2), or None without corner_uvs."""
    if mesh.corner_uvs is None:
        return None
    uvs = np.asarray(mesh.corner_uvs, dtype=np.float64)
    if uvs.ndim != 2 or uvs.shape[1] != 2 or len(uvs) != mesh.corner_count():
        raise SceneError(f"mesh {mesh.origin!r}: corner_uvs has shape {uvs.shape}, not ({mesh.corner_count()}, 2)"
                         " (one (u, v) per face corner)")
    if not np.isfinite(uvs).all():
        raise SceneError(f"mesh {mesh.origin!r}: corner_uvs holds a number that is not finite")
    return np.ascontiguousarray(uvs[mesh.triangle_corners()].reshape(-1, 6))


def _rows_of_three(values) -> np.ndarray:
    """(n, 3) C-contiguous float64: the array itself when it is one already (the MeshData's vertices)."""
    values = np.ascontiguousarray(values, dtype=np.float64)
    return values if values.ndim == 2 and values.shape[1] == 3 else values.reshape(-1, 3)


def _as_int32(index: np.ndarray) -> np.ndarray:
    """Indices as a C-contiguous int32 array (the array itself when it is one).  Every negative index means
    the same (none: an error for a vertex), and any index beyond int32 is out of every mesh's range: they
    are clipped to -1 and MAX_INDEX, which the range checks then judge."""
    index = np.asarray(index)
    if index.dtype != np.int32:
        index = np.clip(index, -1, MAX_INDEX).astype(np.int32)
    return np.ascontiguousarray(index)


class _Rays:
    """A batch of rays with the per-ray values the traversal reuses."""

    def __init__(self, origins: np.ndarray, directions: np.ndarray) -> None:
        self.origins = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
        self.directions = np.ascontiguousarray(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
        if self.origins.shape != self.directions.shape:
            raise ValueError("origins and directions must both be (N, 3)")
        self.n = len(self.origins)
        with np.errstate(divide="ignore", over="ignore"):
            # +-inf for zero (or subnormal) components, the sign of the zero kept.
            self.inverse = 1.0 / self.directions
        self.speed = np.linalg.norm(self.directions, axis=1)
        self.magnitude = np.linalg.norm(self.origins, axis=1)


def _length(v: np.ndarray) -> np.ndarray:
    """Euclidean lengths over the last axis, summed as the C core's sqrt(dot3(v, v))."""
    return np.sqrt(dot3(v, v))


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis with broadcasting (np.cross is slower on small arrays)."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def _dedupe_and_order(ray, slot, t, b1, b2, entering, speed, extent, touching):
    """Drop repeated crossings of shared edges/vertices, then sort by (ray, t) with ties alternating.

    Duplicates are hits of one ray with the same entering sign whose times differ by at most
    ``DEDUPE_RELATIVE * (|t| + extent / |d|)``, or ``DEDUPE_RELATIVE_ADJACENT`` times that when the two
    triangles share a vertex.  Sorting by (ray, sign, t) puts them next to each other even when hits of
    the other sign fall between them in time.  ``touching(slot_a, slot_b)`` says which pairs of
    triangles (leaf slots) share a vertex.
    """
    tol_scale = extent / np.where(speed > 0, speed, 1.0)
    order = np.lexsort((t, entering, ray))
    ray, slot, t, b1, b2, entering = ray[order], slot[order], t[order], b1[order], b2[order], entering[order]
    window = _dedupe_window(slot, t, tol_scale[ray], touching)
    repeat = np.zeros(len(t), dtype=bool)
    repeat[1:] = (ray[1:] == ray[:-1]) & (entering[1:] == entering[:-1]) & (t[1:] - t[:-1] <= window)
    keep = ~repeat
    ray, slot, t, b1, b2, entering = ray[keep], slot[keep], t[keep], b1[keep], b2[keep], entering[keep]

    # Sort by time.  An enter and an exit at (nearly) the same time (a line touching an edge or corner)
    # go in the order that alternates with what came before: outside -> enter first, inside -> exit
    # first.  "Inside" is the net count of enters minus exits before the pair, which the pair's own
    # order does not change.
    order = np.lexsort((t, ray))
    ray, slot, t, b1, b2, entering = ray[order], slot[order], t[order], b1[order], b2[order], entering[order]
    window = _dedupe_window(slot, t, tol_scale[ray], touching)
    tie = np.zeros(len(t), dtype=bool)  # tie[i]: hits i and i+1 coincide with opposite signs
    tie[:-1] = (ray[1:] == ray[:-1]) & (entering[1:] != entering[:-1]) & (t[1:] - t[:-1] <= window)
    tie[1:] &= ~tie[:-1]  # pairs do not overlap
    i = np.flatnonzero(tie)
    if len(i):
        step = np.where(entering, 1, -1)
        before = np.cumsum(step) - step  # net enters before each hit, over all rays so far ...
        ray_start = np.searchsorted(ray, ray[i])  # ... minus those of earlier rays
        inside_before = before[i] - before[ray_start] > 0
        swap = i[entering[i] == inside_before]
        # The times stay where they are (sorted; the two differ by rounding only), the hits swap.
        for column in (slot, b1, b2, entering):
            column[swap], column[swap + 1] = column[swap + 1], column[swap].copy()
    return ray, slot, t, b1, b2, entering


def _dedupe_window(slot, t, tol_scale, touching):
    """How far apart hits i and i+1 (of a sorted list) may be and still be one place: (len - 1,)."""
    scale = np.maximum(np.abs(t[1:]), np.abs(t[:-1])) + tol_scale[1:]
    return np.where(touching(slot[1:], slot[:-1]), DEDUPE_RELATIVE_ADJACENT, DEDUPE_RELATIVE) * scale


def intersect_mesh(origins: np.ndarray, directions: np.ndarray, mesh: TriangleMesh) -> HitArrays:
    """Every crossing of the whole generic lines with ``mesh`` (the mesh kinds' registered intersection,
    tracer/shapes.py: TriangleMesh.all_hits)."""
    return mesh.all_hits(origins, directions)
