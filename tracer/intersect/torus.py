"""Ray against the generic torus: ring radius 1 about the z axis, tube radius 0.2.

The torus is the quartic ``(|p|^2 + R^2 - r^2)^2 = 4 R^2 (x^2 + y^2)``.  Quartic formulas in closed
form (Ferrari) lose many digits for nearly double roots, so we:

1. skip rays that miss the bounding sphere of radius R + r (most rays);
2. write the quartic in the arc length ``s`` from the point of the line closest to the centre (the
   caller already moved the origin there), so coefficients are O(1) however far away the eye is;
3. take the eigenvalues of its companion matrix (backward stable; NumPy batches them);
4. keep the (nearly) real ones and polish each with Newton steps on the quartic itself.
"""
from __future__ import annotations

import numpy as np

from ..model import TORUS_TUBE_RADIUS
from .hits import HitArrays

RING_RADIUS = 1.0
# Eigenvalues of a double root split into a complex pair of size ~sqrt(machine eps) ~ 1e-8; anything
# within this of the real axis is treated as a (grazing) real root.
IMAG_TOLERANCE = 1e-6
NEWTON_STEPS = 4


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


def _polish(s: np.ndarray, coeffs) -> np.ndarray:
    """Newton steps on the monic quartic, each kept only where it reduces the residual."""
    c3, c2, c1, c0 = (c[:, None] for c in coeffs)
    for _ in range(NEWTON_STEPS):
        p = (((s + c3) * s + c2) * s + c1) * s + c0
        dp = ((4.0 * s + 3.0 * c3) * s + 2.0 * c2) * s + c1
        with np.errstate(divide="ignore", invalid="ignore"):
            candidate = s - p / dp
        p_new = (((candidate + c3) * candidate + c2) * candidate + c1) * candidate + c0
        better = np.isfinite(candidate) & (np.abs(p_new) < np.abs(p))
        s = np.where(better, candidate, s)
    return s


def torus_normal(points: np.ndarray, tube: float = TORUS_TUBE_RADIUS) -> np.ndarray:
    """Outward gradient of the torus function at (..., 3) points."""
    r2 = np.sum(points * points, axis=-1, keepdims=True)
    k = r2 + RING_RADIUS ** 2 - tube * tube
    grad = 4.0 * points * k
    grad[..., :2] -= 8.0 * RING_RADIUS ** 2 * points[..., :2]
    return grad


def intersect_torus(origin: np.ndarray, direction: np.ndarray) -> HitArrays:
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
    real = np.abs(roots.imag) <= IMAG_TOLERANCE * (1.0 + np.abs(roots.real))
    s = _polish(np.where(real, roots.real, 0.0), coeffs)
    s = np.where(real, s, np.inf)
    s.sort(axis=1)
    points = o[:, None, :] + np.where(np.isfinite(s), s, 0.0)[..., None] * u[:, None, :]
    normal = torus_normal(points)
    t = np.where(np.isfinite(s), (s + shift[:, None]) / speed[idx, None], np.inf)
    hits.t[idx] = t
    hits.normal[idx] = np.where(np.isfinite(t)[..., None], normal, 0.0)
    # Every line starts outside the (bounded) torus and roots come in conjugate pairs, so the sorted
    # hits alternate in, out, in, out; parity is exact even where a grazing hit's normal is ambiguous.
    hits.entering[idx] = np.isfinite(t) & (np.arange(4) % 2 == 0)
    hits.part[idx] = np.where(np.isfinite(t), 0, -1)
    return hits
