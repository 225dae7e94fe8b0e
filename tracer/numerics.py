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
    """``matrix`` (4 x 4, the last row 0 0 0 1; or (..., 4, 4), one per point) applied to (..., 3) points, each coordinate summed left to
    right as the C core's affine_point: a matrix product goes through BLAS, whose kernels group the terms
    their own way and may fuse a product into a sum.  Where the result decides a hit (a generic ray's origin
    9e15 from the shape, a ray through an edge shared by two faces), both backends must round alike."""
    return np.stack([points[..., 0] * matrix[..., i, 0] + points[..., 1] * matrix[..., i, 1]
                     + points[..., 2] * matrix[..., i, 2] + matrix[..., i, 3] for i in range(3)], axis=-1)


def linear_vectors(matrix: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """The 3 x 3 part of ``matrix`` (one, or one per vector) applied to (..., 3) vectors, as affine_points (the
    C core's affine_vector)."""
    return np.stack([vectors[..., 0] * matrix[..., i, 0] + vectors[..., 1] * matrix[..., i, 1]
                     + vectors[..., 2] * matrix[..., i, 2] for i in range(3)], axis=-1)


#: Vectors whose squared length might leave the normal range are scaled by a power of two first (norm3).
_SQUARE_LO, _SQUARE_HI = 2.0 ** -900, 2.0 ** 900
#: A shadow feeler longer than this (max |component|) is scaled to one of at most this length (feeler_to).
FEELER_REACH = 2.0 ** 64


def lines_near_spheres(center, radius, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
    """Which lines pass within ``radius`` of ``center`` (all of them for an infinite radius).  Broadcasts:
    lines (N, 1, 3) and spheres (P, 3), (P,) give (N, P) (tracer.batches)."""
    if np.ndim(radius) == 0 and not np.isfinite(radius):
        return np.ones(origins.shape[0], dtype=bool)
    to_center = center - origins
    dd = dot3(directions, directions)
    with np.errstate(invalid="ignore", divide="ignore"):
        along = dot3(to_center, directions) / dd
    perp = to_center - along[..., None] * directions
    return dot3(perp, perp) <= radius * radius


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


def feeler_to(starts: np.ndarray, targets: np.ndarray,
              lengths: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Shadow feelers from ``starts`` (N, 3) to ``targets``: directions and the parameter t_max (N,) at which
    each reaches its target.  Normally the direction is ``target - start`` and t_max 1; a feeler whose
    largest component exceeds FEELER_REACH is scaled by a power of two (exactly, so t_max is that power), so
    that no length, dot product or hit time along it overflows (a light at 1e300).  ``lengths``, where the
    caller knows them (the distances to the targets from the hit points the feelers start near), spare the
    look at the components below FEELER_REACH (the C core's feeler_to_known)."""
    directions = targets - starts
    t_max = np.ones(len(starts))
    if lengths is not None and not (lengths > FEELER_REACH).any():
        return directions, t_max
    largest = max_abs3(directions)
    far = (largest > FEELER_REACH) & np.isfinite(largest)
    if lengths is not None:
        far &= lengths > FEELER_REACH
    if far.any():
        _, exponent = np.frexp(np.where(far, largest, 1.0))
        directions = np.where(far[:, None], np.ldexp(directions, -exponent[:, None]), directions)
        t_max = np.ldexp(t_max, np.where(far, exponent, 0))
    return directions, t_max


def max_abs3(v: np.ndarray) -> np.ndarray:
    """max |v_i| over the last axis (of length 3): as np.max(np.abs(v), axis=-1), with two ufunc calls instead
    of a reduction (a third of the time on the tracer's (N, 3) arrays)."""
    a = np.abs(v)
    return np.maximum(np.maximum(a[..., 0], a[..., 1]), a[..., 2])


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


def crossing_shift(delta: np.ndarray, slope: np.ndarray, bend: np.ndarray) -> np.ndarray:
    """How far (in t) a crossing of a line with a surface G = 0 can move when G along the line is off by
    ``delta``, where the line crosses at rate ``slope`` (|dG/dt|) and G bends by ``bend`` (|d^2G/dt^2|): the
    root of slope s + bend s^2 / 2 = delta nearest 0, 2 delta / (slope + sqrt(slope^2 - 2 bend delta)), is at
    most delta slope / (slope^2 - bend delta) (as 1 - x <= sqrt(1 - x): no square root), which is delta /
    slope on a flat face and at most 2 delta / slope; where the pair of roots may be a double one it is at
    most sqrt(2 delta / bend).

    No curvature is assumed (the first bound took unit curvature near tangency: a flat face at grazing
    incidence exceeded it by 10^6, a cone near its apex by 10^5).  (Its callers ignore floating-point
    warnings: a zero slope or bend divides by zero where the other form is taken.)"""
    squared = slope * slope
    shift = delta * slope / (squared - bend * delta)
    double = ~(squared > 2.0 * bend * delta)  # (few: only near tangency)
    if double.any():
        shift[double] = np.sqrt(2.0 * delta[double] / np.broadcast_to(bend, delta.shape)[double])
    shift[~(delta > 0.0)] = 0.0
    return shift


def point_errors(t: np.ndarray, raw_scale: np.ndarray, origin: np.ndarray, direction: np.ndarray, size: float,
                 rounding: float) -> np.ndarray:
    """Bound (N, K) on how far the generic points of hits at times t (N, K) lie off the exact generic line,
    relative to the shape's ``size``: E = rounding / size * S, where S is the size of the coordinates involved.

    ``raw_scale`` (N,) bounds the transformed origin's size before cancellation (``|inverse| max|o|`` plus
    the translation's size); ``origin`` (N, 3) and ``direction`` (N, 3) are the generic ray the shape solved
    (origin at the line's point nearest the centre); ``rounding`` is the error of the generic line in units
    of the coordinates involved (gamma of the hit ulps plus the inverse matrix's own rounding)."""
    reach = np.abs(np.where(np.isfinite(t), t, 0.0)) * max_abs3(direction)[:, None]
    # (summed in the C core's order: with a 1e30 vertex the size dominates and the order moves the last bit)
    scale = raw_scale[:, None] + max_abs3(origin)[:, None] + size + reach
    return rounding / size * scale


def time_errors(error: np.ndarray, hits, direction: np.ndarray, size: float, nn: np.ndarray,
                length: np.ndarray) -> np.ndarray:
    """Bound (N, K) on the rounding of hit times beyond the shape's own root error, from their point errors E
    (point_errors) and the shape's ``hits`` (generic normals, of squared length ``nn`` and length ``length``,
    and their bend, tracer.intersect.hits).

    G along the line is off by |n| size E (the line's error across the surface), and its crossing moves by
    crossing_shift of that; a zero normal counts as grazing.  (numeric.h's time_error_of; the caller ignores
    floating-point warnings.)"""
    along = np.abs(dot3(hits.normal, direction[:, None, :]))
    bound = crossing_shift(length * (size * error), along, np.abs(hits.bend))
    grazing = ~(nn > 0.0) & np.isfinite(hits.t)
    if grazing.any():
        dd = np.broadcast_to(dot3(direction, direction)[:, None], nn.shape)
        bound[grazing] = size * np.sqrt(error[grazing] / dd[grazing])
    return bound


def normal_to_world(normal: np.ndarray, normal_matrix: np.ndarray) -> np.ndarray:
    """Generic normals (..., 3) through the inverse-transpose, n M^-1 with M^-1's linear part
    ``normal_matrix`` (3 x 3, or one per ray: (N, 1, 3, 3) for normals (N, K, 3)), summed as the C core's
    normal_to_world."""
    return (normal[..., 0:1] * normal_matrix[..., 0, :] + normal[..., 1:2] * normal_matrix[..., 1, :]
            + normal[..., 2:3] * normal_matrix[..., 2, :])


def world_offsets(gap: np.ndarray, normal: np.ndarray, world: np.ndarray) -> np.ndarray:
    """How far (N, K) along the unit world normal the world hit point can be from the surface: a generic
    distance ``gap`` (the point's own distance from the surface plus the line's error) along the gradient
    ``normal`` (N, K, 3) maps to the world along its world normal ``world`` by |n| / |world| (exactly for a
    plane; the C core's world_unit_normal; the caller ignores floating-point warnings)."""
    return gap * (norm3(normal) / norm3(world))


def offset_distance(offset: np.ndarray, t: np.ndarray, origins: np.ndarray, directions: np.ndarray,
                    tolerances: Tolerances) -> np.ndarray:
    """How far (N,) a secondary ray starts from a hit, along the unit normal: the hit's ``offset`` (its
    point's distance from the surface, bounded by the scene: HitArrays.offset) plus the rounding of the
    world point o + t d and of the offset origin.
    """
    rounding = gamma(tolerances.offset_ulps) * (max_abs3(origins) + np.abs(t) * max_abs3(directions))
    return offset + rounding
