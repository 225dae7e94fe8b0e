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


def dot3(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Dot products over the last axis (of length 3, broadcasting), summed left to right as the C core's
    dot3 is.

    np.einsum's summation order is NumPy's choice: it groups the terms differently and can end an ulp away,
    or, under cancellation (a triangle with a vertex at 1e30), anywhere.  Where the result decides a hit,
    both backends must round alike."""
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def affine_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """``matrix`` (4 x 4, the last row 0 0 0 1) applied to (..., 3) points, each coordinate summed left to
    right as the C core's affine_point: a matrix product goes through BLAS, whose kernels group the terms
    their own way and may fuse a product into a sum.  Where the result decides a hit (a generic ray's origin
    9e15 from the shape, a ray through an edge shared by two faces), both backends must round alike."""
    return np.stack([points[..., 0] * matrix[i, 0] + points[..., 1] * matrix[i, 1] + points[..., 2] * matrix[i, 2]
                     + matrix[i, 3] for i in range(3)], axis=-1)


def linear_vectors(matrix: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """The 3 x 3 part of ``matrix`` applied to (..., 3) vectors, as affine_points (the C core's affine_vector)."""
    return np.stack([vectors[..., 0] * matrix[i, 0] + vectors[..., 1] * matrix[i, 1] + vectors[..., 2] * matrix[i, 2]
                     for i in range(3)], axis=-1)


def vectors_times(vectors: np.ndarray, matrix: np.ndarray) -> np.ndarray:
    """(..., 3) row vectors times the 3 x 3 part of ``matrix`` (v @ M), summed left to right as the C core's
    normal_to_world."""
    return np.stack([vectors[..., 0] * matrix[0, j] + vectors[..., 1] * matrix[1, j] + vectors[..., 2] * matrix[2, j]
                     for j in range(3)], axis=-1)


#: Vectors whose squared length might leave the normal range are scaled by a power of two first (norm3).
_SQUARE_LO, _SQUARE_HI = 2.0 ** -900, 2.0 ** 900
#: A shadow feeler longer than this (max |component|) is scaled to one of at most this length (feeler_to).
FEELER_REACH = 2.0 ** 64


def norm3(v: np.ndarray) -> np.ndarray:
    """Euclidean lengths over the last axis (of length 3) that cannot overflow or underflow: where |v|^2 leaves
    [2^-900, 2^900] the vector is scaled by the power of two nearest its largest component first, which
    changes no bit where it was not needed (as the C core's norm3).  A light at 1e300 has |L - P|^2 = inf."""
    with np.errstate(over="ignore", under="ignore"):
        squared = dot3(v, v)
    plain = (squared >= _SQUARE_LO) & (squared <= _SQUARE_HI)
    if plain.all():
        return np.sqrt(squared)
    largest = np.max(np.abs(v), axis=-1)
    _, exponent = np.frexp(np.where(plain | ~np.isfinite(largest), 1.0, largest))
    with np.errstate(over="ignore", under="ignore"):
        scaled = np.ldexp(v, -exponent[..., None])
        rescaled = np.ldexp(np.sqrt(dot3(scaled, scaled)), exponent)
    return np.where(plain, np.sqrt(squared), np.where(largest == 0.0, 0.0, rescaled))


def feeler_to(starts: np.ndarray, targets: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Shadow feelers from ``starts`` (N, 3) to ``targets``: directions and the parameter t_max (N,) at which
    each reaches its target.  Normally the direction is ``target - start`` and t_max 1; a feeler longer than
    FEELER_REACH is scaled by a power of two (exactly, so t_max is that power), so that no length, dot
    product or hit time along it overflows (a light at 1e300)."""
    directions = targets - starts
    largest = np.max(np.abs(directions), axis=1)
    far = (largest > FEELER_REACH) & np.isfinite(largest)
    t_max = np.ones(len(starts))
    if far.any():
        _, exponent = np.frexp(np.where(far, largest, 1.0))
        directions = np.where(far[:, None], np.ldexp(directions, -exponent[:, None]), directions)
        t_max = np.ldexp(t_max, np.where(far, exponent, 0))
    return directions, t_max


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
    #: Torus: complex root pairs further than this (relative) from the real axis are not searched for a
    #: double root (a shortcut: the quartic is ~ im^2 there, 10^8 times above its rounding bound).
    torus_pair_shortcut: float = 1e-4
    #: The square's rim, relative: a crossing this close outside still counts, so that edges do not leak.
    square_edge: float = 1e-12


#: The tolerances compile_scene gives the scenes it compiles.
TOLERANCES = Tolerances()


def inverse_rounding(inverses: np.ndarray, matrices: np.ndarray) -> np.ndarray:
    """The rounding (N,) of computed inverses (N, 4, 4) of ``matrices``, relative: the largest residual of
    inverse @ matrix - I against the products' magnitudes |inverse| @ |matrix|, elementwise.  It grows
    with the matrix's condition number (about 1e-8 at 1e8)."""
    # (matmul, not einsum: a tenth of the time for a million 4x4 products)
    residual = np.abs(inverses @ matrices - np.eye(4))
    magnitude = np.abs(inverses) @ np.abs(matrices)
    relative = np.divide(residual, magnitude, out=np.zeros_like(residual), where=magnitude > 0)
    return relative.reshape(len(relative), -1).max(axis=1) if len(relative) else np.zeros(0)


def generic_time_error(t: np.ndarray, raw_scale: np.ndarray, origin: np.ndarray, direction: np.ndarray,
                       normal: np.ndarray, size: float, rounding: float) -> np.ndarray:
    """Bound on the rounding error of hit times (N, K) found in a shape's generic frame.

    ``raw_scale`` (N,) bounds the transformed origin's size before cancellation (``|inverse| max|o|`` plus
    the translation's size); ``origin`` (N, 3) and ``direction`` (N, 3) are the generic
    ray the shape solved (origin at the line's point nearest the centre), ``normal`` (N, K, 3) the generic
    normals; ``size`` is the generic shape's extent and ``rounding`` the error of its hit points in units of
    the coordinates involved (gamma of the hit ulps plus the inverse matrix's own rounding).

    A point error E across the line moves a crossing at angle phi to the normal by E / cos(phi) along it;
    near tangency (cos(phi) < sqrt(E)) the move is at most about sqrt(E) on a unit-curvature surface.
    """
    reach = np.abs(np.where(np.isfinite(t), t, 0.0)) * np.max(np.abs(direction), axis=1)[:, None]
    # (summed in the C core's order: with a 1e30 vertex the size dominates and the order moves the last bit)
    scale = raw_scale[:, None] + np.max(np.abs(origin), axis=1)[:, None] + size + reach
    error = rounding / size * scale
    # (|d| cos phi)^2 = (n.d)^2 / |n|^2, so the bound is size E sqrt(|n|^2 / max((n.d)^2, |d|^2 E |n|^2)):
    # one square root, one division; a zero normal counts as grazing.
    along = dot3(normal, direction[:, None, :])
    nn = dot3(normal, normal)
    dd = dot3(direction, direction)[:, None]
    with np.errstate(invalid="ignore", divide="ignore"):
        crossing, grazing = along * along, dd * error * nn
        bound = size * error * np.sqrt(nn / np.where(crossing > grazing, crossing, grazing))
        return np.where(nn > 0.0, bound, size * np.sqrt(error / dd))


def offset_distance(t: np.ndarray, t_error: np.ndarray, origins: np.ndarray, directions: np.ndarray,
                    tolerances: Tolerances) -> np.ndarray:
    """How far (N,) a secondary ray starts from a hit, along the unit normal: the hit point's error bound.

    The point o + t d is off the surface by at most the time error times |d| and by its own rounding;
    the offset origin's rounding is covered by the same gamma term.
    """
    speed = np.sqrt(dot3(directions, directions))
    rounding = gamma(tolerances.offset_ulps) * (np.max(np.abs(origins), axis=1)
                                                + np.abs(t) * np.max(np.abs(directions), axis=1))
    return t_error * speed + rounding
