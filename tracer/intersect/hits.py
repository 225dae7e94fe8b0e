"""The one shape every intersection routine returns: all hits of a batch of rays with one solid.

Rays are ``origin + t * direction`` with arrays of shape (N, 3).  Hit lists cover the *whole line*
(t from -inf to +inf), so that CSG can tell from the hit sequence alone whether a ray starts inside a
solid; callers drop the hits they do not want (t <= t_min) afterwards.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np


@dataclass
class HitArrays:
    """Hits of N rays with one solid, K slots per ray, sorted by t; unused slots have t = +inf.

    * ``t`` (N, K): ray parameter of each hit, in the units of the direction given.
    * ``entering`` (N, K): the ray goes from outside to inside the solid there.
    * ``normal`` (N, K, 3): the surface normal there, pointing out of the solid, not necessarily unit.
    * ``part`` (N, K) int32: which face / triangle / surface of the shape (-1 for none).
    * ``uv`` (N, K, 2): surface coordinates (barycentrics for triangles; texture coordinates later).
    * ``inside_at_start`` (N,): the ray is inside the solid at t = -inf (only unbounded solids, e.g. the
      plane's half-space, can say True).
    * ``shape`` (N, K) int32: which primitive of the compiled scene was hit (-1 for none); shape routines
      leave it -1 and the scene fills it in.
    * ``error`` (N, K): a bound on the rounding error of ``t`` (tracer.numerics); shape routines put their
      own root's error there (the torus's, or 0) and the scene adds the rest.
    * ``bend`` (N, K): from a shape routine to the error bound (not carried by ``take`` and the others):
      with the normal the gradient of the shape's function G on the surface, G's second derivative along the
      generic direction; None (what ``empty`` makes) for flat faces.
    * ``offset`` (N, K): shape routines: the residual of the computed hit point, |G| to first order (so
      that |G| / |n| is its distance from the surface), where the root carries more rounding than the point
      error (tapered walls, the torus, the paraboloid's and hyperboloid's walls; a flat face's point and the
      sphere's are off by no more than the line's error: 0); the scene turns it into how far a secondary ray
      starts from the hit along the unit world normal (before the world rounding,
      tracer.numerics.offset_distance).
    """

    t: np.ndarray
    entering: np.ndarray
    normal: np.ndarray
    part: np.ndarray
    uv: np.ndarray
    inside_at_start: np.ndarray
    shape: Optional[np.ndarray] = None
    error: Optional[np.ndarray] = None
    bend: Optional[np.ndarray] = None
    offset: Optional[np.ndarray] = None

    def __post_init__(self) -> None:
        if self.shape is None:
            self.shape = np.full(self.t.shape, -1, dtype=np.int32)
        for name in ("error", "offset"):
            if getattr(self, name) is None:
                setattr(self, name, np.zeros(self.t.shape))

    @property
    def count(self) -> int:
        return self.t.shape[0]

    @property
    def slots(self) -> int:
        return self.t.shape[1]

    @classmethod
    def empty(cls, n: int, k: int = 0) -> "HitArrays":
        return cls(t=np.full((n, k), np.inf),
                   entering=np.zeros((n, k), dtype=bool),
                   normal=np.zeros((n, k, 3)),
                   part=np.full((n, k), -1, dtype=np.int32),
                   uv=np.zeros((n, k, 2)),
                   inside_at_start=np.zeros(n, dtype=bool))

    def sorted(self) -> "HitArrays":
        """The same hits with each row sorted by t (stable, so equal times keep their order)."""
        order = np.argsort(self.t, axis=1, kind="stable")
        return self.take(order)

    def take(self, order: np.ndarray) -> "HitArrays":
        """Reorder/select slots per row: ``order`` is (N, K') of slot indices."""
        rows = np.arange(self.count)[:, None]
        return HitArrays(t=self.t[rows, order], entering=self.entering[rows, order],
                         normal=self.normal[rows, order], part=self.part[rows, order],
                         uv=self.uv[rows, order], inside_at_start=self.inside_at_start.copy(),
                         shape=self.shape[rows, order], error=self.error[rows, order], offset=self.offset[rows, order])

    def subset(self, rows: np.ndarray) -> "HitArrays":
        """Only some rays (a boolean mask or index array over N)."""
        return HitArrays(t=self.t[rows], entering=self.entering[rows], normal=self.normal[rows],
                         part=self.part[rows], uv=self.uv[rows], inside_at_start=self.inside_at_start[rows],
                         shape=self.shape[rows], error=self.error[rows], offset=self.offset[rows])

    def trimmed(self) -> "HitArrays":
        """Drop trailing slots that no ray uses."""
        used = np.isfinite(self.t).any(axis=0)
        k = int(used.nonzero()[0].max()) + 1 if used.any() else 0
        return self.take(np.broadcast_to(np.arange(k), (self.count, k)))


def concatenate(a: HitArrays, b: HitArrays) -> HitArrays:
    """Slots of a then slots of b, per ray (not sorted)."""
    return HitArrays(t=np.concatenate([a.t, b.t], axis=1),
                     entering=np.concatenate([a.entering, b.entering], axis=1),
                     normal=np.concatenate([a.normal, b.normal], axis=1),
                     part=np.concatenate([a.part, b.part], axis=1),
                     uv=np.concatenate([a.uv, b.uv], axis=1),
                     inside_at_start=a.inside_at_start | b.inside_at_start,
                     shape=np.concatenate([a.shape, b.shape], axis=1),
                     error=np.concatenate([a.error, b.error], axis=1),
                     offset=np.concatenate([a.offset, b.offset], axis=1))
