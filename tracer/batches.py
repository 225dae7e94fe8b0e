"""Many top-level primitives of one kind traced at once (the NumPy path).

The reference path asks each top-level object for its hits in turn, and each ask costs some thirty NumPy
calls whatever the number of rays: a scene of 2,048 spheres took 88 s for a 32 x 24 image the C core draws in
0.05 s.  Primitives of one kind with the same traced parameters differ only in their numbers (matrix, bounds),
so a batch of them is traced over the (ray, primitive) pairs whose line passes the primitive's bounding sphere,
by one Primitive whose numbers are per pair (Primitive.of_rows): the arithmetic of each primitive's own, so
the same bits.  tracer.trace merges what a batch finds with the other objects' hits by the rules it applies
to each object (the nearest hit; a tie to the object first in the scene; a feeler blocked by any).

Meshes and booleans are traced one by one, as are kinds with fewer than BATCH_MIN primitives.  (A layer
below tracer.compile, whose Primitive and PrimitiveTable it is handed: hence their names in quotes.)
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterator, Optional

import numpy as np

from . import numerics, shapes
from .intersect.hits import HitArrays
from .model import MESH_KINDS

#: Fewer primitives of one kind than this are traced one by one (pairing rays with a batch has its own cost).
BATCH_MIN = 8
#: (ray, primitive) pairs culled or traced at a time: bounds the temporaries (some 200 bytes a pair).
PAIRS_AT_ONCE = 1 << 15
#: The most members asked at a time for shadow feelers (PrimitiveBatch.blocked).
MOST_BLOCKERS_AT_ONCE = 64
#: The most (ray, leaf) rows of a boolean's batched leaves held at once (LeafHits): some 100 bytes each.
LEAF_ROWS = 1 << 18
_MESH_CODES = [code for code, entry in enumerate(shapes.REGISTRY) if entry.keyword in MESH_KINDS]


@dataclass(frozen=True)
class PrimitiveBatch:
    """Top-level objects ``objects`` (their indices in the scene, ascending): plain primitives of one kind with
    the same traced parameters, whose table rows are ``rows``."""

    objects: np.ndarray
    rows: np.ndarray
    table: "PrimitiveTable"

    def pairs(self, origins: np.ndarray, directions: np.ndarray, rays: np.ndarray,
              members: slice = slice(None)) -> Iterator[tuple[np.ndarray, np.ndarray]]:
        """(ray, member) index pairs, a chunk at a time: the rays ``rays`` whose line passes the bounding sphere
        of a member in ``members`` (every such member, for an unbounded kind), ray-major."""
        table, chosen = self.table, np.arange(len(self.rows))[members]
        spheres = table.numbers_of(self.rows[chosen], ("spheres",))["spheres"]
        centers, radii = spheres[:, :3], spheres[:, 3]
        bounded = bool(np.isfinite(radii[0]))  # (one kind: all bounded or none)
        step = max(1, PAIRS_AT_ONCE // chosen.size)
        for start in range(0, rays.size, step):
            chunk = rays[start:start + step]
            if bounded:
                near = numerics.lines_near_spheres(centers, radii, origins[chunk][:, None], directions[chunk][:, None])
            else:
                near = np.ones((chunk.size, chosen.size), dtype=bool)
            at, member = np.nonzero(near)
            for first in range(0, at.size, PAIRS_AT_ONCE):
                part = slice(first, first + PAIRS_AT_ONCE)
                yield chunk[at[part]], chosen[member[part]]

    def members(self, member: np.ndarray) -> "Primitive":
        """The members ``member`` as one Primitive with numbers per pair."""
        return self.table.primitives_of_rows(self.rows[member])

    def first_hits(self, origins, directions, t_min, t_max, rays: np.ndarray,
                   before: Optional[np.ndarray] = None) -> Iterator[tuple[np.ndarray, np.ndarray, HitArrays]]:
        """For each chunk of pairs: (ray, object, hits) of the pairs that have a first hit t_min < t < t_max
        (K = 1, as Primitive.first_hit gives it); ``before`` (per ray): only objects before that index."""
        for ray, member in self.pairs(origins, directions, rays):
            if before is not None:
                earlier = self.objects[member] < before[ray]
                ray, member = ray[earlier], member[earlier]
            if ray.size == 0:
                continue
            hits = self.members(member).first_hit(origins[ray], directions[ray], t_min[ray], t_max[ray])
            found = np.isfinite(hits.t[:, 0])
            if found.any():
                yield ray[found], self.objects[member[found]], hits.subset(found)

    def blocked(self, origins, directions, t_max, rays: np.ndarray) -> np.ndarray:
        """Which of the rays ``rays`` (feelers) some member blocks (Primitive.occludes): the members asked in
        blocks of 1, 2, 4, ... (at most MOST_BLOCKERS_AT_ONCE), each block for the feelers still open: the first
        blockers often block them all (a floor under the whole scene)."""
        blocked = np.zeros(origins.shape[0], dtype=bool)
        first, size = 0, 1
        while first < len(self.rows):
            open_rays = rays[~blocked[rays]]
            if open_rays.size == 0:
                break
            block = slice(first, first + size)
            first, size = first + size, min(2 * size, MOST_BLOCKERS_AT_ONCE)
            for ray, member in self.pairs(origins, directions, open_rays, block):
                open_pairs = ~blocked[ray]
                ray, member = ray[open_pairs], member[open_pairs]
                if ray.size:
                    hit = self.members(member).occludes(origins[ray], directions[ray], np.zeros(ray.size),
                                                        t_max[ray])
                    blocked[ray[hit]] = True
        return blocked[rays]


def firsts(rays: np.ndarray, *keys: np.ndarray) -> np.ndarray:
    """Positions of each ray's first entry in the order of ``keys`` (the first key the last decided, as
    np.lexsort); ``rays`` and the keys are one entry each per pair."""
    order = np.lexsort((*keys, rays))
    leads = np.ones(order.size, dtype=bool)
    leads[1:] = rays[order][1:] != rays[order][:-1]
    return order[leads]


def _groups(rows: np.ndarray, table: "PrimitiveTable") -> list[np.ndarray]:
    """Positions in ``rows`` (table rows) of the batches: BATCH_MIN or more primitives of one kind (not meshes)
    with the same traced parameters, grouped by their bits (0 and -0 apart: they may round apart)."""
    candidates = np.nonzero(~np.isin(table.kind[rows], _MESH_CODES))[0]
    if candidates.size < BATCH_MIN:
        return []
    keys = np.ascontiguousarray(np.column_stack([table.kind[rows[candidates]].astype(float),
                                                 table.parameters[rows[candidates]]]))
    _, group = np.unique(keys.view(np.dtype((np.void, keys.itemsize * keys.shape[1]))).reshape(-1),
                         return_inverse=True)
    group = group.reshape(-1)
    return [candidates[group == g] for g in np.nonzero(np.bincount(group) >= BATCH_MIN)[0]]


def batches_of(objects, table: Optional["PrimitiveTable"]) -> tuple[list[PrimitiveBatch], np.ndarray]:
    """The batches of a compiled scene's top-level objects, and the indices (ascending) of the objects asked one
    by one.  The grouping is kept on ``objects`` (a CompiledObjects) until an edit forgets it
    (CompiledObjects.forget_batches)."""
    kept = getattr(objects, "batches", None)
    if kept is not None:
        return kept
    primitive_index = getattr(objects, "primitive_index", None)
    batches: list[PrimitiveBatch] = []
    alone = np.ones(len(objects), dtype=bool)
    if table is not None and primitive_index is not None:
        plain = np.nonzero(primitive_index >= 0)[0]
        for members in _groups(primitive_index[plain], table):
            batches.append(PrimitiveBatch(plain[members], primitive_index[plain[members]], table))
            alone[plain[members]] = False
    kept = (batches, np.nonzero(alone)[0])
    if primitive_index is not None:
        objects.batches = kept
    return kept


class LeafHits:
    """The whole-line hits (Primitive.intersect) of those of a boolean's leaves that come in batches: a boolean of
    2,048 spheres asks 2,048 times otherwise.  A batch's members are intersected a block at a time, when the
    first leaf of the block is asked for (fold_tree asks left to right), into one table of rows, member after
    member; each leaf's hits (a view of its rows) are handed out once, so a block is freed as the fold goes on:
    at most LEAF_ROWS rows of a boolean's leaves are held beyond the fold's own."""

    def __init__(self, leaves: list["Primitive"], origins: np.ndarray, directions: np.ndarray):
        self.origins, self.directions = origins, directions
        self.waiting: dict[int, tuple] = {}  # id(leaf) -> (its batch, the block of members it is in)
        self.ready: dict[int, HitArrays] = {}
        table = getattr(leaves[0], "table", None) if leaves else None
        if table is None or len(leaves) < BATCH_MIN or any(getattr(leaf, "table", None) is not table
                                                          for leaf in leaves):
            return
        rows = np.array([leaf.index for leaf in leaves])
        per_block = max(BATCH_MIN, LEAF_ROWS // max(1, origins.shape[0]))
        for positions in _groups(rows, table):
            batch = PrimitiveBatch(positions, rows[positions], table)
            for first in range(0, positions.size, per_block):
                block = (batch, np.arange(first, min(first + per_block, positions.size)),
                         [id(leaves[p]) for p in positions[first:first + per_block].tolist()])
                for key in block[2]:
                    self.waiting[key] = block

    def __len__(self) -> int:
        return len(self.waiting) + len(self.ready)

    def pop(self, leaf: "Primitive") -> Optional[HitArrays]:
        """The leaf's hits (once), or None for a leaf not in a batch."""
        block = self.waiting.get(id(leaf))
        if block is not None:
            self._intersect(*block)
        return self.ready.pop(id(leaf), None)

    def _intersect(self, batch: PrimitiveBatch, members: np.ndarray, keys: list[int]) -> None:
        origins, directions = self.origins, self.directions
        n = origins.shape[0]
        nowhere = np.zeros((0, 3))
        slots = batch.members(members[:1]).intersect(nowhere, nowhere).slots  # (the kind's)
        stacked = HitArrays.empty(members.size * n, slots)
        for ray, member in batch.pairs(origins, directions, np.arange(n), slice(members[0], members[-1] + 1)):
            if ray.size:
                hits = batch.members(member).intersect(origins[ray], directions[ray])
                for name in _HIT_FIELDS:
                    getattr(stacked, name)[(member - members[0]) * n + ray] = getattr(hits, name)
        for j, key in enumerate(keys):
            del self.waiting[key]
            self.ready[key] = stacked.subset(slice(j * n, (j + 1) * n))


#: What Primitive.intersect copies into the rows of the rays it culled (the others have no hits).
_HIT_FIELDS = ("t", "entering", "normal", "part", "uv", "shape", "inside_at_start", "error", "offset")
