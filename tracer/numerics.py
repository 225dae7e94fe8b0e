"""Tolerances, in one place, and the rounding-error bounds they scale.

Everything is float64.  No tolerance here is a distance: each hit carries a bound on the rounding error of
its ray parameter t, derived from the computation that produced it (as pbrt-v4 does with its gamma(n)
bounds, see docs/tracer.md, "Rounding error").  From that bound

* a secondary ray starts off the surface by the bound on its hit point's error, along the normal;
* a hit counts as "after t_min" only when its whole error interval is (so a ray never finds again the
  surface it leaves);
* CSG merges two children's hits into one event only where their error intervals overlap.

The multipliers below are counts of machine epsilons with room to spare; a measurement (tracer.accuracy)
may vary them through :data:`TOLERANCES`, which compile_scene reads into the compiled scene, and the C core
receives the same value with the scene.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

#: The unit roundoff of float64, 2^-53: a correctly rounded operation is off by at most this, relatively.
UNIT_ROUNDOFF = np.finfo(float).eps / 2.0


def gamma(n: float) -> float:
    """Higham's gamma_n = n u / (1 - n u): the relative error bound of n chained roundings."""
    return n * UNIT_ROUNDOFF / (1.0 - n * UNIT_ROUNDOFF)


@dataclass(frozen=True)
class Tolerances:
    """Every tolerance of the tracer, handed to the C core with the scene (tracer.native.flatten)."""

    #: gamma(hit_ulps) bounds the rounding of a hit point in the shape's generic frame, relative to the
    #: coordinates involved: the affine map of the ray (3 products and sums per coordinate), moving its
    #: origin to the point nearest the centre (2 more) and the root itself (a sqrt, a few products).
    hit_ulps: float = 16.0
    #: gamma(offset_ulps) bounds the rounding of the world hit point o + t d and of the offset origin.
    offset_ulps: float = 4.0
    #: Torus roots: a quartic value within residual_ulps machine epsilons of its terms' absolute sum is 0.
    torus_residual_ulps: float = 16.0
    #: Newton steps that polish each torus root.
    torus_newton_steps: int = 4
    #: The square's rim, relative: a crossing this close outside still counts, so that edges do not leak.
    square_edge: float = 1e-12


#: The tolerances compile_scene gives the scenes it compiles.
TOLERANCES = Tolerances()


def generic_time_error(t: np.ndarray, raw_scale: np.ndarray, origin: np.ndarray, direction: np.ndarray,
                       normal: np.ndarray, size: float, rounding: float) -> np.ndarray:
    """Bound on the rounding error of hit times (N, K) found in a shape's generic frame.

    ``raw_scale`` (N,) is ``max_i sum_j |inverse_ij| |o_j|`` plus the translation's size: the magnitude of
    the transformed origin before cancellation; ``origin`` (N, 3) and ``direction`` (N, 3) are the generic
    ray the shape solved (origin at the line's point nearest the centre), ``normal`` (N, K, 3) the generic
    normals; ``size`` is the generic shape's extent and ``rounding`` the error of its hit points in units of
    the coordinates involved (gamma of the hit ulps plus the inverse matrix's own rounding).

    A point error E across the line moves a crossing at angle phi to the normal by E / cos(phi) along it;
    near tangency (cos(phi) < sqrt(E)) the move is at most about sqrt(E) on a unit-curvature surface.
    """
    speed = np.linalg.norm(direction, axis=1)
    reach = np.abs(np.where(np.isfinite(t), t, 0.0)) * np.max(np.abs(direction), axis=1)[:, None]
    scale = raw_scale[:, None] + np.max(np.abs(origin), axis=1)[:, None] + reach + size
    error = rounding * scale / size
    n_len = np.linalg.norm(normal, axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        cosine = np.abs(np.einsum("nkj,nj->nk", normal, direction)) / (n_len * speed[:, None])
        cosine = np.where(np.isfinite(cosine), cosine, 0.0)
        return size * error / (speed[:, None] * np.maximum(cosine, np.sqrt(error)))


def offset_distance(t: np.ndarray, t_error: np.ndarray, origins: np.ndarray, directions: np.ndarray,
                    tolerances: Tolerances) -> np.ndarray:
    """How far (N,) a secondary ray starts from a hit, along the unit normal: the hit point's error bound.

    The point o + t d is off the surface by at most the time error times |d| and by its own rounding;
    the offset origin's rounding is covered by the same gamma term.
    """
    speed = np.linalg.norm(directions, axis=1)
    rounding = gamma(tolerances.offset_ulps) * (np.max(np.abs(origins), axis=1)
                                                + np.abs(t) * np.max(np.abs(directions), axis=1))
    return t_error * speed + rounding
