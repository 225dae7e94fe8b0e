"""The ray trees of a batch of rays, traced breadth first (the NumPy path's recursion, tracer.trace).

Each generation of the trees -- the mirror and transmitted rays of every ray of the generation before, of
every pixel at once -- is one batch (``Tracer.shade_batch``), so a tree costs a batch per level, not one per
node: glass that reflects and transmits doubles the nodes at every level, and a batch per node was ~3.5 rays.
The colours are then added up from the leaves, each node's in the recursion's order (its own colour, plus
its reflectivity times the mirror ray's colour, plus its transparency times the transmitted ray's), so the
images are the recursion's bit for bit, and the C core's (shade.h, which recurses).

The ray budget (tracer.savings) is the one rule that is not breadth first: the recursion lets a transmitted
ray go only if its mirror sibling's whole subtree left room for it (take_ray in shade.h).  So every node
carries bounds on its budget (how many rays its descendants may trace) and on how many they do trace; a ray is
traced as soon as even the lower bound admits it, and a ray the bounds leave in doubt waits until the subtrees
before it are complete and the bounds exact.  Only rays the recursion traces are ever traced (the counts are
the same too); the bounds only decide how soon.  A tree whose budget is never short -- every tree of an
energy-conserving material -- is traced a generation per batch; a tree the budget cuts takes a few more.
"""
from __future__ import annotations

from dataclasses import dataclass, fields

import numpy as np

#: Most rays one call of ``shade_batch`` traces (a generation of a deep tree can be large: bounded memory per
#: call, and a cancel is heard between calls).
CHUNK = 8192
#: Most rays the trees of one batch may hold (~550 bytes each, ~290 MB): a batch whose trees grow past it is
#: traced again in parts (TooManyRays, Tracer.shade), so deep glass over a whole tile does not take all memory.
MAX_RAYS = 1 << 19
MIRROR, THROUGH = 0, 1  # the two children of a node, in the recursion's order


@dataclass
class Shaded:
    """A batch of shaded rays: each one's own colour and, where it hit below the depth limit (``secondary``),
    the children it asks for (slot MIRROR: the mirror ray; THROUGH: the transmitted ray, or under total
    internal reflection the mirror ray again, ``bounce``) with their weights, where they start and go, and
    the media they travel in; ``krc`` and ``kt`` weigh the children's colours."""

    color: np.ndarray  # (N, 3)
    secondary: np.ndarray  # (N,) bool
    want: np.ndarray  # (N, 2) bool: the child passes the cutoff
    weight: np.ndarray  # (N, 2)
    krc: np.ndarray  # (N, 3) the mirror ray's colour weight
    kt: np.ndarray  # (N,)
    shared: np.ndarray  # (N,) bool: the transmitted colour is the mirror ray's (tracer.savings.shared_tir)
    start: np.ndarray  # (N, 2, 3)
    direction: np.ndarray  # (N, 2, 3)
    bounce: np.ndarray  # (N,) bool
    media: object  # tracer.trace.Media of the ray (the mirror ray's too)
    through_media: object  # the transmitted ray's

    @classmethod
    def empty(cls, background: np.ndarray, media) -> "Shaded":
        n = media.depth.shape[0]
        return cls(color=np.broadcast_to(background, (n, 3)).copy(), secondary=np.zeros(n, bool),
                   want=np.zeros((n, 2), bool), weight=np.zeros((n, 2)), krc=np.zeros((n, 3)), kt=np.zeros(n),
                   shared=np.zeros(n, bool), start=np.zeros((n, 2, 3)), direction=np.zeros((n, 2, 3)),
                   bounce=np.zeros(n, bool), media=media, through_media=media)


def _join_media(parts: list):
    first = parts[0]
    return type(first)(*(np.concatenate([getattr(p, f.name) for p in parts]) for f in fields(first)))


def _rows(shaded: Shaded, rows) -> Shaded:
    return Shaded(**{f.name: (getattr(shaded, f.name).subset(rows) if f.name.endswith("media")
                              else getattr(shaded, f.name)[rows]) for f in fields(Shaded)})


def _join(parts: list[Shaded]) -> Shaded:
    if len(parts) == 1:
        return parts[0]
    out = {}
    for f in fields(Shaded):
        values = [getattr(p, f.name) for p in parts]
        out[f.name] = _join_media(values) if f.name.endswith("media") else np.concatenate(values)
    return Shaded(**out)


class _Generation:
    """The traced rays of one level of the trees: what ``shade_batch`` found, the parent of each (an index
    into the level above), its children (indices into the level below, -1: not traced), and the bounds."""

    def __init__(self, shaded: Shaded, parent: np.ndarray, slot: np.ndarray, budget_lo: np.ndarray,
                 budget_hi: np.ndarray):
        self.rays, self.parent, self.slot = shaded, parent, slot  # slot: which child of its parent
        n = parent.shape[0]
        self.child = np.full((n, 2), -1, dtype=np.int64)
        self.budget_lo, self.budget_hi = budget_lo, budget_hi  # bounds on the rays its descendants may trace
        self.used_lo, self.used_hi = np.zeros(n, np.int64), np.maximum(budget_hi, 0)  # ... and on those they do
        self.sure = np.zeros((n, 2), bool)  # the child is within the budget (traced when wanted)
        self.maybe = np.zeros((n, 2), bool)  # the child may be within the budget
        self.slot_lo = np.zeros((n, 2), np.int64)  # bounds on the children's budgets
        self.slot_hi = np.full((n, 2), np.iinfo(np.int64).max)
        self.closed = np.zeros(n, bool)  # every bound of the row exact and both children decided: never changes
        w = shaded.weight
        self.both = shaded.want[:, MIRROR] & shaded.want[:, THROUGH] & (w[:, THROUGH] >= 0)
        with np.errstate(invalid="ignore", divide="ignore"):
            ratio = w[:, MIRROR] / (w[:, MIRROR] + w[:, THROUGH])
        self.ratio = np.where((ratio >= 0.0) & (ratio <= 1.0), ratio, 0.5)  # (weights of 0 or infinity: even)

    def __len__(self) -> int:
        return self.parent.shape[0]

    def extend(self, more: "_Generation") -> None:
        self.rays = _join([self.rays, more.rays])
        for name in ("parent", "slot", "child", "budget_lo", "budget_hi", "used_lo", "used_hi", "sure", "maybe",
                     "slot_lo", "slot_hi", "closed", "both", "ratio"):
            setattr(self, name, np.concatenate([getattr(self, name), getattr(more, name)]))


def subtree_rays(levels_left: int) -> int:
    """The most rays below a ray with ``levels_left`` levels under it (two children each: 2 + 4 + ...)."""
    return (1 << (levels_left + 1)) - 2 if levels_left < 62 else np.iinfo(np.int64).max


def mirror_share(budget: np.ndarray, both: np.ndarray, ratio: np.ndarray, chain: int) -> np.ndarray:
    """The budget a mirror ray's subtree gets from a parent with ``budget`` (rays its descendants may trace;
    take_ray in shade.h): everything but the mirror ray itself, or, when the transmitted ray is wanted too
    (``both``), a part of what is left after both rays in proportion to the mirror ray's weight, but at least a
    chain of ``chain`` rays.  Never falls as ``budget`` grows (the bounds below rely on it)."""
    by_weight = np.floor((budget - 2).astype(np.float64) * ratio).astype(np.int64)
    share = np.where(both, np.maximum(by_weight, np.minimum(budget - 2, chain)), budget - 1)
    return np.maximum(share, 0)


class TooManyRays(Exception):
    """The trees of a batch hold more than MAX_RAYS rays (the caller traces it in parts)."""


class RayTrees:
    """The trees of a batch of rays at ``level`` (camera rays: 0), each with ``budget`` secondary rays, down to
    ``depth`` (traced_depth); ``tracer`` shades the batches and counts the rays."""

    def __init__(self, tracer, level: int, depth: int, budget: int):
        self.tracer, self.level, self.depth, self.budget = tracer, level, depth, budget
        self.generations: list[_Generation] = []
        #: Batches given to shade_batch (a test holds the count to the depth, not to the number of nodes).
        self.batches = 0

    def trace(self, origins: np.ndarray, directions: np.ndarray, media, weight: np.ndarray) -> np.ndarray:
        """The colours of the rays: their trees traced, then added up."""
        n = origins.shape[0]
        self.batches += 1
        first = self.tracer.shade_batch(origins, directions, self.level, media, weight)
        full = np.full(n, self.budget, dtype=np.int64)
        self.generations = [_Generation(first, np.full(n, -1, dtype=np.int64), np.zeros(n, np.int64), full,
                                        full.copy())]
        self.dirty = [True]  # per level: a bound it reads changed since it was last narrowed
        self.narrowed = 0  # bounds that narrowed (they only narrow)
        while True:
            settled_before = self._settle()
            if self._grow():
                continue
            if not self._undecided():
                break
            if self._settle() == settled_before:  # (every level narrowed again: the bounds become exact in the end)
                self.dirty = [True] * len(self.generations)
                if self._settle() == settled_before:  # (cannot happen: exact bounds decide every ray)
                    raise RuntimeError("ray tree: the budget bounds stopped narrowing")
        self._count_budget_skips()
        colors = self._colors()
        self.generations, self.dirty = [], []  # (the trees can be large: not held past the batch)
        return colors

    # -- the bounds ----------------------------------------------------------------------------------------

    def _settle(self) -> int:
        """Narrow every bound once (from the leaves up, then from the roots down); returns a number that
        changes whenever a bound does (they only narrow)."""
        for order in (reversed(range(len(self.generations))), range(len(self.generations))):
            for g in order:
                if self.dirty[g]:
                    self._narrow(g)
        return self.narrowed

    def _used(self, g: int, rows: np.ndarray, slot: int, budget_hi: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Bounds on the rays the subtrees below the ``slot`` children of the rows ``rows`` of level ``g`` trace
        (a child not yet traced: anything up to its budget, and up to a full tree to the depth limit)."""
        child = self.generations[g].child[rows, slot]
        full = subtree_rays(max(self.depth - (self.level + g + 1), 0))
        lo, hi = np.zeros(child.shape[0], np.int64), np.minimum(budget_hi, full)
        traced = np.nonzero(child >= 0)[0]
        if traced.size:
            below = self.generations[g + 1]
            lo[traced], hi[traced] = below.used_lo[child[traced]], below.used_hi[child[traced]]
        return lo, hi

    def _narrow(self, g: int) -> None:
        """The recursion's budget rule (take_ray) on bounds, for the rows of level ``g`` not closed: from the
        bounds on each node's budget and on what its children's subtrees use, which children are surely / maybe
        within the budget, the bounds on their budgets (handed down to traced children) and on what the node's
        descendants use."""
        gen = self.generations[g]
        self.dirty[g] = False
        rows = np.nonzero(~gen.closed)[0]
        if rows.size == 0:
            return
        lo, hi, both, ratio = gen.budget_lo[rows], gen.budget_hi[rows], gen.both[rows], gen.ratio[rows]
        want = gen.rays.want[rows]
        chain = self.depth - (self.level + g)
        mirror_lo, mirror_hi = mirror_share(lo, both, ratio, chain), mirror_share(hi, both, ratio, chain)
        mirror_sure, mirror_maybe = want[:, MIRROR] & (lo > 0), want[:, MIRROR] & (hi > 0)
        sub_lo, sub_hi = self._used(g, rows, MIRROR, mirror_hi)
        took_lo = np.where(mirror_sure, 1 + sub_lo, 0)  # rays the mirror child and its subtree take
        took_hi = np.where(mirror_maybe, 1 + sub_hi, 0)
        left_lo, left_hi = lo - took_hi, hi - took_lo  # what the transmitted ray finds left
        through_sure, through_maybe = want[:, THROUGH] & (left_lo > 0), want[:, THROUGH] & (left_hi > 0)
        through_lo, through_hi = np.maximum(left_lo - 1, 0), np.maximum(left_hi - 1, 0)
        sub_lo, sub_hi = self._used(g, rows, THROUGH, through_hi)
        used_lo = np.maximum(gen.used_lo[rows], took_lo + np.where(through_sure, 1 + sub_lo, 0))
        used_hi = np.minimum(took_hi + np.where(through_maybe, 1 + sub_hi, 0), np.maximum(hi, 0))
        used_hi = np.minimum(np.minimum(used_hi, subtree_rays(max(chain, 0))), gen.used_hi[rows])
        changed = int(np.count_nonzero(used_lo != gen.used_lo[rows]) + np.count_nonzero(used_hi != gen.used_hi[rows]))
        if changed and g > 0:
            self.dirty[g - 1] = True
        self.narrowed += changed
        gen.used_lo[rows], gen.used_hi[rows] = used_lo, used_hi
        exact = (lo == hi) & (used_lo == used_hi)
        for slot, sure, maybe, slot_lo, slot_hi in ((MIRROR, mirror_sure, mirror_maybe, mirror_lo, mirror_hi),
                                                    (THROUGH, through_sure, through_maybe, through_lo, through_hi)):
            sure = sure | gen.sure[rows, slot]
            gen.sure[rows, slot], gen.maybe[rows, slot] = sure, maybe | sure
            slot_lo = np.maximum(gen.slot_lo[rows, slot], slot_lo)
            slot_hi = np.minimum(gen.slot_hi[rows, slot], slot_hi)
            gen.slot_lo[rows, slot], gen.slot_hi[rows, slot] = slot_lo, slot_hi
            traced = gen.child[rows, slot] >= 0
            exact &= ~want[:, slot] | (traced & (slot_lo == slot_hi)) | ~(maybe | sure)
        gen.closed[rows] = exact
        if g + 1 < len(self.generations):
            self._hand_down(gen, self.generations[g + 1], g + 1)

    def _hand_down(self, gen: _Generation, below: _Generation, g: int) -> None:
        """The traced children (level ``g``) not closed take their parents' bounds on their budgets."""
        rows = np.nonzero(~below.closed)[0]
        parent, slot = below.parent[rows], below.slot[rows]
        lo = np.maximum(below.budget_lo[rows], gen.slot_lo[parent, slot])
        hi = np.minimum(below.budget_hi[rows], gen.slot_hi[parent, slot])
        changed = int(np.count_nonzero(lo != below.budget_lo[rows]) + np.count_nonzero(hi != below.budget_hi[rows]))
        if changed:
            self.dirty[g] = True
            self.narrowed += changed
            below.budget_lo[rows], below.budget_hi[rows] = lo, hi

    def _undecided(self) -> bool:
        return any(bool((gen.maybe & ~gen.sure & gen.rays.want).any()) for gen in self.generations)

    # -- tracing -------------------------------------------------------------------------------------------

    def _grow(self) -> bool:
        """Trace every wanted child that is surely within the budget and not traced yet, of every level, as one
        batch (CHUNK rays at most per call); returns whether any was."""
        parts = []  # (level index, parents, slots), mirror children first
        for g, gen in enumerate(self.generations):
            ready = gen.sure & gen.rays.want & (gen.child < 0)
            mirror, through = np.nonzero(ready[:, MIRROR])[0], np.nonzero(ready[:, THROUGH])[0]
            if mirror.size + through.size:
                parts.append((g, np.concatenate([mirror, through]),
                              np.concatenate([np.full(mirror.size, MIRROR), np.full(through.size, THROUGH)])))
        if not parts:
            return False
        held = sum(len(gen) for gen in self.generations) + sum(parent.size for _, parent, _ in parts)
        if held > MAX_RAYS and len(self.generations[0]) > 1:  # (one tree is traced whatever its size)
            raise TooManyRays
        counts = self.tracer.counts
        for g, parent, slot in parts:
            rays = self.generations[g].rays
            bounce = rays.bounce[parent[slot == THROUGH]]
            counts.reflection += int(np.count_nonzero(slot == MIRROR)) + int(np.count_nonzero(bounce))
            counts.refraction += int(np.count_nonzero(~bounce))
        shaded = self._shade([self.generations[g].rays for g, _, _ in parts], parts)
        begin = 0
        for g, parent, slot in parts:
            self._add(g, parent, slot, _rows(shaded, slice(begin, begin + parent.size)))
            begin += parent.size
        return True

    def _shade(self, rays: list[Shaded], parts) -> Shaded:
        """The children ``parts`` of the levels, shaded: one batch, CHUNK rays a call."""
        start = np.concatenate([r.start[parent, slot] for r, (_, parent, slot) in zip(rays, parts)])
        direction = np.concatenate([r.direction[parent, slot] for r, (_, parent, slot) in zip(rays, parts)])
        weight = np.concatenate([r.weight[parent, slot] for r, (_, parent, slot) in zip(rays, parts)])
        level = np.concatenate([np.full(parent.size, self.level + g + 1) for g, parent, _ in parts])
        # (a transmitted ray, not the mirror ray that total internal reflection sends in its place)
        refracted = np.concatenate([(slot == THROUGH) & ~r.bounce[parent]
                                    for r, (_, parent, slot) in zip(rays, parts)])
        media = _join_media([m for r, (_, parent, slot) in zip(rays, parts)
                             for m in (r.media.subset(parent[slot == MIRROR]),
                                       r.through_media.subset(parent[slot == THROUGH]))])
        out = []
        for begin in range(0, level.size, CHUNK):
            rows = slice(begin, begin + CHUNK)
            self.batches += 1
            out.append(self.tracer.shade_batch(start[rows], direction[rows], level[rows], media.subset(rows),
                                               weight[rows], refracted[rows]))
        return _join(out)

    def _add(self, g: int, parent: np.ndarray, slot: np.ndarray, shaded: Shaded) -> None:
        """Level g + 1 grows by the ``slot`` children of the rays ``parent`` of level g."""
        gen = self.generations[g]
        new = _Generation(shaded, parent, slot, gen.slot_lo[parent, slot].copy(), gen.slot_hi[parent, slot].copy())
        if g + 1 == len(self.generations):
            self.generations.append(new)
            self.dirty.append(True)
        else:
            below = self.generations[g + 1]
            gen.child[parent, slot] = len(below) + np.arange(parent.size)
            below.extend(new)
            self.dirty[g + 1] = True
            return
        gen.child[parent, slot] = np.arange(parent.size)

    # -- the results ---------------------------------------------------------------------------------------

    def _count_budget_skips(self) -> None:
        for gen in self.generations:
            self.tracer.counts.skipped_budget += int(np.count_nonzero(gen.rays.want & ~gen.maybe))

    def _colors(self) -> np.ndarray:
        """Each node's colour from the leaves up, as the recursion adds them: its own, then its reflectivity
        times the mirror ray's colour, then its transparency times the transmitted ray's (under total internal
        reflection traced once, the mirror ray's; a child not traced adds 0)."""
        below = np.zeros((0, 3))
        for gen in reversed(self.generations):
            rays = gen.rays
            color = rays.color.copy()
            rows = np.nonzero(rays.secondary)[0]
            if rows.size:
                mirrored, through = np.zeros((rows.size, 3)), np.zeros((rows.size, 3))
                child = gen.child[rows]
                has = child[:, MIRROR] >= 0
                mirrored[has] = below[child[has, MIRROR]]
                shared = rays.shared[rows]
                through[shared] = mirrored[shared]
                has = child[:, THROUGH] >= 0
                through[has] = below[child[has, THROUGH]]
                color[rows] += rays.krc[rows] * mirrored
                color[rows] += rays.kt[rows, None] * through
            below = color
        return below
