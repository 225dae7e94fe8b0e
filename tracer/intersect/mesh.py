"""Rays against triangle meshes: a bounding volume hierarchy built and traversed in NumPy.

The BVH is kept in flat arrays (see :class:`TriangleMesh`) so that the C core can later walk the very
same arrays.  The NumPy traversal is *packet*-style: a Python stack holds ``(node, active rays)`` pairs,
every node is visited at most once per call, with the subset of rays whose slab test passed, and a
leaf tests all its rays against all its triangles at once (a vectorised Möller–Trumbore).  The Python
overhead is therefore per node, not per ray, which is what makes coherent batches fast.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..errors import SceneError
from ..model import MeshData
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


@dataclass(frozen=True)
class MeshArrays:
    """A :class:`TriangleMesh`'s BVH and per-triangle tables, as the C core walks them (views, no copies).

    Named as their SceneDesc fields (tracer/native/contract.py).  Leaf order (row i is triangle
    ``tri_order[i]``): ``tri_p0``, ``tri_e1``, ``tri_e2``, ``tri_flip``, ``tri_edge_scale`` (|e1| |e2|),
    ``tri_radius`` (largest vertex norm), ``tri_slack1`` (|e2| + radius), ``tri_slack2`` (|e1| + radius),
    ``tri_welded`` (vertex ids after welding equal positions).  Original order: ``tri_geometric`` (unit
    geometric normals), ``tri_corners`` (three unit corner normals each), ``tri_has_normals``."""

    node_lo: np.ndarray
    node_hi: np.ndarray
    node_left: np.ndarray
    node_right: np.ndarray
    node_first: np.ndarray
    node_count: np.ndarray
    node_axis: np.ndarray
    tri_order: np.ndarray
    tri_p0: np.ndarray
    tri_e1: np.ndarray
    tri_e2: np.ndarray
    tri_flip: np.ndarray
    tri_edge_scale: np.ndarray
    tri_radius: np.ndarray
    tri_slack1: np.ndarray
    tri_slack2: np.ndarray
    tri_welded: np.ndarray
    tri_geometric: np.ndarray
    tri_corners: np.ndarray
    tri_has_normals: np.ndarray
    extent: float


class TriangleMesh:
    """A triangle mesh in generic coordinates with a BVH, answering all-hits, closest-hit and any-hit.

    Triangles are ``MeshData.triangles()`` (fan triangulation of the faces); ``part`` in the hits is the
    index into that list and ``uv`` holds the barycentrics (b1, b2) of the hit, so the hit point is
    ``(1 - b1 - b2) P0 + b1 P1 + b2 P2``.

    Orientation: the *geometric normal* of a triangle is its winding normal (P1 - P0) x (P2 - P0),
    flipped when the triangle's vertex normals, averaged, point against it (meshes without normals keep
    the winding).  A hit is *entering* when ``direction . geometric normal < 0``.  The reported normal is
    the shading normal: the barycentric interpolation of the (unit) vertex normals, or the geometric
    normal where the triangle has none, where the interpolation is degenerate or where it falls on the
    inner side of the geometric normal.  All reported normals are unit length.

    Shared edges and vertices: the barycentric test is inclusive with a slack the size of the rounding
    (see ROUNDING_FACTOR), and all-hits merges hits of one ray with the same entering sign at the same
    time (see DEDUPE_RELATIVE), so a ray through an edge or vertex crosses the surface once.

    BVH: binned surface-area heuristic (``bins`` buckets along the longest axis of the centroids),
    split until a node holds at most ``leaf_size`` triangles.  Layout (M nodes, node 0 is the root,
    each inner node's children are allocated together so ``node_right == node_left + 1``; all arrays
    are C-contiguous):

    * ``node_lo``, ``node_hi`` (M, 3) float64: the node's box (padded by a tiny fraction of the mesh size).
    * ``node_left``, ``node_right`` (M,) int64: children of an inner node, -1 for a leaf.
    * ``node_first`` (M,) int64, ``node_count`` (M,) int64: a leaf's triangles are
      ``tri_order[node_first : node_first + node_count]``; inner nodes have count 0 (first -1).
    * ``node_axis`` (M,) int8: the axis an inner node was split along (left holds the smaller
      centroids), used to visit the nearer child first; -1 for leaves.
    * ``tri_order`` (T,) int64: triangle indices (into ``MeshData.triangles()``) in leaf order.

    Per-triangle data in *leaf order* (row i belongs to triangle ``tri_order[i]``), so that a leaf's
    triangles are one contiguous slice: ``tri_p0`` (T, 3), ``tri_e1``, ``tri_e2`` (T, 3) = P1 - P0,
    P2 - P0, and ``tri_flip`` (T,) bool, the triangles whose geometric normal is minus the winding normal.
    """

    def __init__(self, mesh: MeshData, leaf_size: int = 8, bins: int = 16) -> None:
        tri_v, tri_n = mesh.triangles()
        vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(mesh.normals, dtype=np.float64).reshape(-1, 3)
        if tri_v.size and (tri_v.min() < 0 or tri_v.max() >= len(vertices)):
            raise SceneError(f"mesh {mesh.origin!r}: a face uses a vertex index out of range")
        if (tri_n >= len(normals)).any():
            raise SceneError(f"mesh {mesh.origin!r}: a face uses a normal index out of range")
        self.triangle_count = len(tri_v)

        # One corner at a time ((T, 3) arrays, not one (T, 3, 3) gather), and each temporary dropped as soon
        # as it is used: for a million triangles every (T, 3) array is 24 MB.
        corners = [vertices[tri_v[:, k]] for k in range(3)]
        p0 = corners[0]
        e1 = corners[1] - p0
        e2 = corners[2] - p0
        winding = np.cross(e1, e2)

        # Unit vertex normals per corner; triangles with any missing normal have none at all.
        has_normals = (tri_n >= 0).all(axis=1) if len(normals) else np.zeros(len(tri_v), dtype=bool)
        if has_normals.all() and len(tri_v):
            corner_normals = normals[tri_n]  # (T, 3, 3), made unit in place
            _normalise_rows(corner_normals)
        else:
            corner_normals = np.zeros((len(tri_v), 3, 3))
            if has_normals.any():
                raw = normals[tri_n[has_normals]]
                _normalise_rows(raw)
                corner_normals[has_normals] = raw
                del raw
        del tri_n
        # Orientation: flip the winding where the file's normals, averaged, disagree with it.
        flip = np.einsum("ij,ij->i", corner_normals.sum(axis=1), winding) < 0
        geometric = np.where(flip[:, None], -winding, winding)
        del winding
        length = np.linalg.norm(geometric, axis=1, keepdims=True)
        geometric = np.divide(geometric, length, out=np.zeros_like(geometric), where=length > 0)
        del length

        # Kept in the original (MeshData.triangles()) order, for the hits' normals.
        self._geometric_normal = geometric
        self._corner_normals = corner_normals
        self._has_normals = has_normals

        # The mesh's size gives absolute scales for box padding and hit deduplication.
        if len(tri_v):
            self.bounds = np.stack([np.min([c.min(axis=0) for c in corners], axis=0),
                                    np.max([c.max(axis=0) for c in corners], axis=0)])
        else:
            self.bounds = np.zeros((2, 3))
        self.extent = float(np.max(self.bounds[1] - self.bounds[0], initial=0.0)) or 1.0
        self._magnitude = float(np.max(np.abs(self.bounds), initial=0.0))

        # Boxes and centroids of the triangles for the builder (the centroid is the corners' mean, summed
        # in corner order as p.mean(axis=1) sums them).
        centroid = corners[0] + corners[1]
        centroid += corners[2]
        centroid /= 3.0
        self._build_bvh(np.minimum(np.minimum(corners[0], corners[1]), corners[2]),
                        np.maximum(np.maximum(corners[0], corners[1]), corners[2]), centroid, leaf_size, bins)
        del centroid

        order = self.tri_order
        # Scales for the parallel test and the barycentric slack (see ROUNDING_FACTOR), leaf order.
        radius = np.linalg.norm(corners[0], axis=1)
        for c in corners[1:]:
            np.maximum(radius, np.linalg.norm(c, axis=1), out=radius)
        del corners
        self._radius = radius[order]
        del radius
        self.tri_p0 = p0[order]
        del p0
        self.tri_e1 = e1[order]
        del e1
        self.tri_e2 = e2[order]
        del e2
        self.tri_flip = flip[order]
        e1_length = np.linalg.norm(self.tri_e1, axis=1)
        e2_length = np.linalg.norm(self.tri_e2, axis=1)
        self._edge_scale = e1_length * e2_length
        self._slack1 = e2_length + self._radius
        self._slack2 = e1_length + self._radius
        # Vertex ids after welding equal positions, to tell which triangles touch (for deduplication).
        if len(order):
            _, welded = np.unique(vertices, axis=0, return_inverse=True)
            self._tri_welded = welded.reshape(-1)[tri_v[order]]
        else:
            self._tri_welded = np.zeros((0, 3), dtype=np.int64)

    # ------------------------------------------------------------------ BVH construction

    def _build_bvh(self, tri_lo: np.ndarray, tri_hi: np.ndarray, centroid: np.ndarray,
                   leaf_size: int, bins: int) -> None:
        """Binned-SAH BVH over the triangles' bounding boxes (split candidates from the centroids): built by
        the C core when it is there (the same tree, in a fraction of the time), else in NumPy."""
        native = _native_builder() if 2 <= bins <= 64 and leaf_size >= 1 else None
        if native is None:
            self._build_bvh_numpy(tri_lo, tri_hi, centroid, leaf_size, bins)
            return
        tree = native(tri_lo, tri_hi, centroid, leaf_size, bins)
        self._store_nodes(tree["lo"], tree["hi"], tree["left"], tree["right"], tree["first"], tree["count"],
                          tree["axis"], tree["order"])

    def _build_bvh_numpy(self, tri_lo: np.ndarray, tri_hi: np.ndarray, centroid: np.ndarray,
                         leaf_size: int, bins: int) -> None:
        """The reference builder (bvh_build.h builds the same tree)."""
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
            self._store_nodes(lo, hi, left, right, first, count, axes, order)
            return

        stack = [(new_node(), 0, t_count)]  # (node, start, end) over ``order``
        while stack:
            node, start, end = stack.pop()
            members = order[start:end]
            lo[node] = tri_lo[members].min(axis=0)
            hi[node] = tri_hi[members].max(axis=0)
            n = end - start
            split = self._choose_split(tri_lo[members], tri_hi[members], centroid[members], bins) \
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
        self._store_nodes(lo, hi, left, right, first, count, axes, order)

    @staticmethod
    def _choose_split(tri_lo: np.ndarray, tri_hi: np.ndarray, centroid: np.ndarray, bins: int):
        """(axis, mask of triangles going left) by the surface area heuristic over ``bins`` buckets.

        The axis is the longest extent of the centroids.  When all centroids coincide there is nothing
        to bin, and the range is simply halved (so leaves stay small even for duplicate triangles).
        """
        n = len(centroid)
        c_lo, c_hi = centroid.min(axis=0), centroid.max(axis=0)
        axis = int(np.argmax(c_hi - c_lo))
        width = c_hi[axis] - c_lo[axis]
        if not width > 0:
            goes_left = np.zeros(n, dtype=bool)
            goes_left[: n // 2] = True
            return axis, goes_left

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
        return axis, bucket <= best

    def _store_nodes(self, lo, hi, left, right, first, count, axes, order) -> None:
        pad = BOX_PADDING * (self.extent + self._magnitude)
        self.node_lo = np.array(lo, dtype=np.float64).reshape(-1, 3) - pad
        self.node_hi = np.array(hi, dtype=np.float64).reshape(-1, 3) + pad
        self.node_left = np.array(left, dtype=np.int64)
        self.node_right = np.array(right, dtype=np.int64)
        self.node_first = np.array(first, dtype=np.int64)
        self.node_count = np.array(count, dtype=np.int64)
        self.node_axis = np.array(axes, dtype=np.int8)
        self.tri_order = order
        self.node_first[self.node_count == 0] = -1

    @property
    def node_total(self) -> int:
        return len(self.node_count)

    def arrays(self) -> MeshArrays:
        """The tables another tracer needs to walk this mesh exactly as the queries below do."""
        return MeshArrays(
            node_lo=self.node_lo, node_hi=self.node_hi, node_left=self.node_left, node_right=self.node_right,
            node_first=self.node_first, node_count=self.node_count, node_axis=self.node_axis,
            tri_order=self.tri_order, tri_p0=self.tri_p0, tri_e1=self.tri_e1, tri_e2=self.tri_e2,
            tri_flip=self.tri_flip, tri_edge_scale=self._edge_scale, tri_radius=self._radius,
            tri_slack1=self._slack1, tri_slack2=self._slack2, tri_welded=self._tri_welded,
            tri_geometric=self._geometric_normal, tri_corners=self._corner_normals,
            tri_has_normals=self._has_normals, extent=self.extent)

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
                first = self.node_first[node]
                found.append((idx[ray_pos], first + tri_pos, t[ray_pos, tri_pos],
                              b1[ray_pos, tri_pos], b2[ray_pos, tri_pos]))

        self._traverse(rays, np.full(rays.n, -np.inf), np.full(rays.n, np.inf), on_leaf, shrink=False)
        if not found:
            return HitArrays.empty(rays.n, 0)
        ray, slot, t, b1, b2 = (np.concatenate(column) for column in zip(*found))
        entering = self._entering(rays.directions[ray], slot)
        ray, slot, t, b1, b2, entering = _dedupe_and_order(
            ray, slot, t, b1, b2, entering, rays.speed, self.extent, self._tri_welded)

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
            best_slot[winners] = self.node_first[node] + pick
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
                near, far = self.node_left[node], self.node_right[node]
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
        first = self.node_first[node]
        last = first + self.node_count[node]
        p0 = self.tri_p0[first:last]
        e1 = self.tri_e1[first:last]
        e2 = self.tri_e2[first:last]
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
            ROUNDING_FACTOR * np.finfo(float).eps * speed * (rays.magnitude[idx, None] + self._radius[first:last])
            / abs_det, BARYCENTRIC_EPSILON_MAX / np.maximum(self._slack1[first:last], self._slack2[first:last]))
        slack1 = rounding * self._slack1[first:last]
        slack2 = rounding * self._slack2[first:last]
        hit = ((abs_det > PARALLEL_EPSILON * speed * self._edge_scale[first:last])
               & (b1 >= -slack1) & (b2 >= -slack2) & (b1 + b2 <= 1.0 + slack1 + slack2) & np.isfinite(t))
        return t, b1, b2, hit

    # ------------------------------------------------------------------ hit attributes

    def _entering(self, directions: np.ndarray, slot: np.ndarray) -> np.ndarray:
        """direction . geometric normal < 0 for triangles given in leaf order."""
        winding = np.cross(self.tri_e1[slot], self.tri_e2[slot])
        facing = np.einsum("ij,ij->i", directions, winding)
        return np.where(self.tri_flip[slot], facing > 0, facing < 0)

    def _shading_normal(self, tri: np.ndarray, b1: np.ndarray, b2: np.ndarray) -> np.ndarray:
        """Unit shading normals for hits on triangles ``tri`` (original order) at barycentrics (b1, b2)."""
        geometric = self._geometric_normal[tri]
        corners = self._corner_normals[tri]
        weights = np.stack([1.0 - b1 - b2, b1, b2], axis=1)
        smooth = np.einsum("ij,ijk->ik", weights, corners)
        length = np.linalg.norm(smooth, axis=1)
        # Use the interpolation only where it is meaningful and on the outer side of the face.
        usable = self._has_normals[tri] & (length > 1e-12) & (np.einsum("ij,ij->i", smooth, geometric) > 0)
        with np.errstate(all="ignore"):
            smooth = smooth / length[:, None]
        return np.where(usable[:, None], smooth, geometric)


def _normalise_rows(vectors: np.ndarray) -> None:
    """Scale each vector (last axis) to unit length in place; vectors of length 0 become 0."""
    length = np.linalg.norm(vectors, axis=-1, keepdims=True)
    np.divide(vectors, length, out=vectors, where=length > 0)
    vectors[np.broadcast_to(~(length > 0), vectors.shape)] = 0.0


def _native_builder():
    """tracer.native.build_mesh_bvh when the C core is built, else None."""
    try:
        from .. import native
    except ImportError:
        return None
    return native.build_mesh_bvh if native.load_error is None else None


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


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis with broadcasting (np.cross is slower on small arrays)."""
    ax, ay, az = a[..., 0], a[..., 1], a[..., 2]
    bx, by, bz = b[..., 0], b[..., 1], b[..., 2]
    return np.stack([ay * bz - az * by, az * bx - ax * bz, ax * by - ay * bx], axis=-1)


def _dedupe_and_order(ray, slot, t, b1, b2, entering, speed, extent, welded):
    """Drop repeated crossings of shared edges/vertices, then sort by (ray, t) with ties alternating.

    Duplicates are hits of one ray with the same entering sign whose times differ by at most
    ``DEDUPE_RELATIVE * (|t| + extent / |d|)``, or ``DEDUPE_RELATIVE_ADJACENT`` times that when the two
    triangles share a vertex.  Sorting by (ray, sign, t) puts them next to each other even when hits of
    the other sign fall between them in time.  ``welded`` (T, 3) holds the triangles' vertex ids (leaf
    order, like ``slot``).
    """
    tol_scale = extent / np.where(speed > 0, speed, 1.0)
    order = np.lexsort((t, entering, ray))
    ray, slot, t, b1, b2, entering = ray[order], slot[order], t[order], b1[order], b2[order], entering[order]
    window = _dedupe_window(slot, t, tol_scale[ray], welded)
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
    window = _dedupe_window(slot, t, tol_scale[ray], welded)
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


def _dedupe_window(slot, t, tol_scale, welded):
    """How far apart hits i and i+1 (of a sorted list) may be and still be one place: (len - 1,)."""
    scale = np.maximum(np.abs(t[1:]), np.abs(t[:-1])) + tol_scale[1:]
    touching = (welded[slot[1:], :, None] == welded[slot[:-1], None, :]).any(axis=(1, 2))
    return np.where(touching, DEDUPE_RELATIVE_ADJACENT, DEDUPE_RELATIVE) * scale
