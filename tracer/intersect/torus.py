"""Ray against the generic torus: ring radius 1 about the z axis, tube radius 0.2.

The torus is the quartic ``(|p|^2 + R^2 - r^2)^2 = 4 R^2 (x^2 + y^2)``.  Quartic formulas in closed
form (Ferrari) lose many digits for nearly double roots, so we:

1. skip rays that miss the bounding sphere of radius R + r (most rays);
2. write the quartic in the arc length ``s`` from the point of the line closest to the centre (the
   caller already moved the origin there), so coefficients are O(1) however far away the eye is;
3. take the eigenvalues of its companion matrix (backward stable; NumPy batches them);
4. keep the real ones and polish each with Newton steps on the quartic itself.  A pair of roots counts
   only where the quartic's sign between them is proven, beyond the rounding bound of evaluating it, to be
   the one the pair implies: negative inside the tube between an entry and its exit, positive between an
   exit and the next entry (else the two chords are one).  A complex pair is a near-double root: it counts,
   as two roots, only where the quartic's extremum next to it is provably below zero.  So a line tangent
   to the tube within rounding has no touching pair, on either backend.  The bound,
   ``Tolerances.torus_residual_ulps`` machine epsilons (the coefficients take up to 6 operations each and
   Horner's rule 8 more) times the quartic's terms taken in absolute value, scales with
   the coefficients, so the test is as tight at 1e-8 as at 1e8.
"""
from __future__ import annotations

import numpy as np

from ..model import TORUS_TUBE_RADIUS
from ..numerics import TOLERANCES, Tolerances
from .hits import HitArrays

RING_RADIUS = 1.0
EPSILON = np.finfo(float).eps


def quartic_coefficients(origin: np.ndarray, unit_dir: np.ndarray, tube: float = TORUS_TUBE_RADIUS):
    """Coefficients (c3, c2, c1, c0) of the monic quartic in s for the line origin + s * unit_dir."""
    R2 = RING_RADIUS * RING_RADIUS
    ox, oy, oz = origin[:, 0], origin[:, 1], origin[:, 2]
    dx, dy = unit_dir[:, 0], unit_dir[:, 1]
    f = np.einsum("ij,ij->i", origin, unit_dir)
    e = ox * ox + oy * oy + oz * oz + R2 - tube * tube
    c3 = 4.0 * f
    c2 = 4.0 * f * f + 2.0 * e - 4.0 * R2 * (dx * dx + dy * dy)
    c1 = 4.0 * e * f - 8.0 * R2 * (ox * dx + oy * dy)
    c0 = e * e - 4.0 * R2 * (ox * ox + oy * oy)
    return c3, c2, c1, c0


def coefficient_magnitudes(origin: np.ndarray, unit_dir: np.ndarray, tube: float = TORUS_TUBE_RADIUS):
    """The coefficients of :func:`quartic_coefficients` with every term taken in absolute value."""
    R2 = RING_RADIUS * RING_RADIUS
    ox, oy, oz = origin[:, 0], origin[:, 1], origin[:, 2]
    dx, dy = unit_dir[:, 0], unit_dir[:, 1]
    f = np.abs(np.einsum("ij,ij->i", origin, unit_dir))
    e = ox * ox + oy * oy + oz * oz + R2 + tube * tube
    m3 = 4.0 * f
    m2 = 4.0 * f * f + 2.0 * e + 4.0 * R2 * (dx * dx + dy * dy)
    m1 = 4.0 * e * f + 8.0 * R2 * (np.abs(ox * dx) + np.abs(oy * dy))
    m0 = e * e + 4.0 * R2 * (ox * ox + oy * oy)
    return m3, m2, m1, m0


def quartic_at(s: np.ndarray, coeffs) -> np.ndarray:
    c3, c2, c1, c0 = coeffs
    return (((s + c3) * s + c2) * s + c1) * s + c0


def residual_bound(s: np.ndarray, magnitudes, ulps: float) -> np.ndarray:
    """How far from zero a computed quartic value at s can be when the exact one is zero."""
    a = np.abs(s)
    return ulps * EPSILON * quartic_at(a, magnitudes)


def _minimum_near(s: np.ndarray, coeffs, steps: int) -> np.ndarray:
    """Newton steps on the quartic's derivative from s: the local extremum a complex pair sits over."""
    c3, c2, c1, c0 = coeffs
    for _ in range(steps):
        d1 = ((4.0 * s + 3.0 * c3) * s + 2.0 * c2) * s + c1
        d2 = (12.0 * s + 6.0 * c3) * s + 2.0 * c2
        with np.errstate(divide="ignore", invalid="ignore"):
            candidate = s - d1 / d2
        s = np.where(np.isfinite(candidate) & (d2 > 0.0), candidate, s)
    return s


def _polish(s: np.ndarray, coeffs, steps: int) -> np.ndarray:
    """Newton steps on the monic quartic, each kept only where it reduces the residual."""
    c3, c2, c1, c0 = (c[:, None] for c in coeffs)
    for _ in range(steps):
        p = (((s + c3) * s + c2) * s + c1) * s + c0
        dp = ((4.0 * s + 3.0 * c3) * s + 2.0 * c2) * s + c1
        with np.errstate(divide="ignore", invalid="ignore"):
            candidate = s - p / dp
        p_new = (((candidate + c3) * candidate + c2) * candidate + c1) * candidate + c0
        better = np.isfinite(candidate) & (np.abs(p_new) < np.abs(p))
        s = np.where(better, candidate, s)
    return s


def _accepted_roots(roots: np.ndarray, coeffs, magnitudes, tol: Tolerances) -> np.ndarray:
    """Sorted real roots (M, 4) from the companion eigenvalues, +inf in unused slots (see module doc)."""
    col = [c[:, None] for c in coeffs]
    mag = [m[:, None] for m in magnitudes]
    ulps, steps = tol.torus_residual_ulps, tol.torus_newton_steps
    real = roots.imag == 0.0
    # A complex pair: both members start Newton from the same real part, so they find the same extremum.
    centre = _minimum_near(roots.real.copy(), col, steps)
    depth = quartic_at(centre, col)
    curvature = (12.0 * centre + 6.0 * col[0]) * centre + 2.0 * col[1]
    # Only a proven pair of real roots (p at the extremum below minus the bound) that the eigenvalues took for
    # a complex one, split by no more than twice the imaginary part (p'' / 2 (2 im)^2 = 2 p'' im^2); not a
    # deep minimum, which is one between two real roots that Newton can wander to from a far complex pair.
    # (Pairs far from the real axis are not searched: Tolerances.torus_pair_shortcut.)
    near_double = (~real & (np.abs(roots.imag) <= tol.torus_pair_shortcut * (1.0 + np.abs(roots.real)))
                   & (depth < -residual_bound(centre, mag, ulps)) & (-depth <= 2.0 * curvature * roots.imag * roots.imag)
                   & (curvature > 0.0))
    with np.errstate(invalid="ignore", divide="ignore"):
        half = np.sqrt(np.maximum(-depth, 0.0) / (0.5 * curvature))
    split = np.where(roots.imag > 0.0, centre - half, centre + half)
    s = _polish(np.where(real, roots.real, np.where(near_double, split, 0.0)), coeffs, steps)
    s = np.where(real | near_double, s, np.inf)
    s.sort(axis=1)
    # Between an entry and its exit the quartic is negative (inside the tube), between an exit and the
    # next entry positive: a pair for which that is not proven beyond rounding is no crossing at all.
    finite = np.isfinite(s)
    for first, second, inside in ((0, 1, True), (2, 3, True), (1, 2, False)):
        both = finite[:, first] & finite[:, second]
        mid = 0.5 * (np.where(both, s[:, first], 0.0) + np.where(both, s[:, second], 0.0))
        value = quartic_at(mid[:, None], col)[:, 0]
        bound = residual_bound(mid[:, None], mag, ulps)[:, 0]
        wrong = both & (~(value < -bound) if inside else ~(value > bound))
        s[wrong, first] = np.inf
        s[wrong, second] = np.inf
        finite = np.isfinite(s)
    s.sort(axis=1)
    return s


def torus_value(points: np.ndarray, tube: float = TORUS_TUBE_RADIUS) -> np.ndarray:
    """The torus function (|p|^2 + R^2 - r^2)^2 - 4 R^2 (x^2 + y^2) at (..., 3) points (shapes.h's sums)."""
    x, y, z = points[..., 0], points[..., 1], points[..., 2]
    k = x * x + y * y + z * z + RING_RADIUS * RING_RADIUS - tube * tube
    return k * k - 4.0 * RING_RADIUS * RING_RADIUS * (x * x + y * y)


def torus_normal(points: np.ndarray, tube: float = TORUS_TUBE_RADIUS) -> np.ndarray:
    """Outward gradient of the torus function at (..., 3) points."""
    r2 = np.sum(points * points, axis=-1, keepdims=True)
    k = r2 + RING_RADIUS ** 2 - tube * tube
    grad = 4.0 * points * k
    grad[..., :2] -= 8.0 * RING_RADIUS ** 2 * points[..., :2]
    return grad


def intersect_torus(origin: np.ndarray, direction: np.ndarray, tol: Tolerances = TOLERANCES) -> HitArrays:
    """All hits of the lines origin + t * direction with the generic torus (K = 4 slots)."""
    n = origin.shape[0]
    hits = HitArrays.empty(n, 4)
    speed = np.linalg.norm(direction, axis=1)
    moving = speed > 0.0
    unit = np.where(moving[:, None], direction / np.where(moving, speed, 1.0)[:, None], 0.0)
    # Bounding sphere test, in s (arc length) from the given origin.
    bound = RING_RADIUS + TORUS_TUBE_RADIUS
    b = np.einsum("ij,ij->i", origin, unit)
    closest = origin - b[:, None] * unit
    candidates = moving & (np.einsum("ij,ij->i", closest, closest) <= bound * bound)
    idx = np.nonzero(candidates)[0]
    if idx.size == 0:
        return hits
    # Re-centre each line on its point closest to the torus centre: coefficients stay O(1).
    shift = -b[idx]
    o = closest[idx]
    u = unit[idx]
    coeffs = quartic_coefficients(o, u)
    companion = np.zeros((idx.size, 4, 4))
    companion[:, 0, :] = -np.stack(coeffs, axis=1)
    companion[:, 1, 0] = companion[:, 2, 1] = companion[:, 3, 2] = 1.0
    roots = np.linalg.eigvals(companion)
    magnitudes = coefficient_magnitudes(o, u)
    s = _accepted_roots(roots, coeffs, magnitudes, tol)
    points = o[:, None, :] + np.where(np.isfinite(s), s, 0.0)[..., None] * u[:, None, :]
    normal = torus_normal(points)
    t = np.where(np.isfinite(s), (s + shift[:, None]) / speed[idx, None], np.inf)
    hits.t[idx] = t
    hits.normal[idx] = np.where(np.isfinite(t)[..., None], normal, 0.0)
    # Every line starts outside the (bounded) torus and roots come in conjugate pairs, so the sorted
    # hits alternate in, out, in, out; parity is exact even where a grazing hit's normal is ambiguous.
    hits.entering[idx] = np.isfinite(t) & (np.arange(4) % 2 == 0)
    hits.part[idx] = np.where(np.isfinite(t), 0, -1)
    hits.error[idx] = np.where(np.isfinite(t), root_error(s, coeffs, magnitudes, tol) / speed[idx, None], 0.0)
    # G is the quartic itself (the normal its gradient): it bends by speed^2 times its curvature in s
    x = np.where(np.isfinite(s), s, 0.0)
    curvature = np.abs((12.0 * x + 6.0 * coeffs[0][:, None]) * x + 2.0 * coeffs[1][:, None])
    hits.bend = np.zeros_like(hits.t)
    hits.bend[idx] = np.where(np.isfinite(t), curvature * speed[idx, None] * speed[idx, None], 0.0)
    hits.offset[idx] = np.where(np.isfinite(t), np.abs(torus_value(points)), 0.0)
    return hits


def root_error(s: np.ndarray, coeffs, magnitudes, tol: Tolerances) -> np.ndarray:
    """How far (M, 4) roots s can be from the exact ones: the residual bound over the slope, or, near a
    double root where the slope vanishes, over the curvature (|p| ~ p''/2 delta^2)."""
    col = [c[:, None] for c in coeffs]
    x = np.where(np.isfinite(s), s, 0.0)
    bound = residual_bound(x, [m[:, None] for m in magnitudes], tol.torus_residual_ulps)
    slope = np.abs(((4.0 * x + 3.0 * col[0]) * x + 2.0 * col[1]) * x + col[2])
    curvature = np.abs((12.0 * x + 6.0 * col[0]) * x + 2.0 * col[1])
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.fmin(bound / slope, np.sqrt(2.0 * bound / curvature))
