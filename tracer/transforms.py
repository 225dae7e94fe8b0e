"""4x4 affine matrices for SDL's transform statements (column vectors, angles in degrees)."""
from __future__ import annotations

import math

import numpy as np

from .errors import SceneError

_EPSILON = np.finfo(np.float64).eps


def translation(dx: float, dy: float, dz: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (dx, dy, dz)
    return m


def scaling(sx: float, sy: float, sz: float) -> np.ndarray:
    return np.diag([sx, sy, sz, 1.0]).astype(np.float64)


def rotation(angle_degrees: float, ux: float, uy: float, uz: float) -> np.ndarray:
    """Right-handed rotation about the axis (ux, uy, uz), which is normalised here (Rodrigues' formula)."""
    # The length summed left to right (np.linalg.norm's order depends on the build): the C core's SDL reader
    # (native/sdl_read.h) repeats these operations and must get the same bits.
    length = math.sqrt(ux * ux + uy * uy + uz * uz)
    if not (length > 0.0 and math.isfinite(length)):
        # The squares overflowed (an axis of 1e200) or underflowed (1e-200): the same direction, scaled by its
        # largest component first.  (Only here: a plain axis keeps the operations above, bit for bit.)
        largest = max(abs(ux), abs(uy), abs(uz))
        if not (largest > 0.0 and math.isfinite(largest)):
            raise SceneError("rotation axis must be a non-zero finite vector")
        ux, uy, uz = ux / largest, uy / largest, uz / largest
        length = math.sqrt(ux * ux + uy * uy + uz * uz)
    x, y, z = ux / length, uy / length, uz / length
    a = math.radians(angle_degrees)
    c, s = math.cos(a), math.sin(a)
    # Snap the sine and cosine of exact multiples of 90 degrees so that common rotations stay exact.
    if float(angle_degrees) % 90.0 == 0.0:
        c, s = round(c), round(s)
    k = 1.0 - c
    m = np.eye(4)
    m[:3, :3] = [[c + x * x * k, x * y * k - z * s, x * z * k + y * s],
                 [y * x * k + z * s, c + y * y * k, y * z * k - x * s],
                 [z * x * k - y * s, z * y * k + x * s, c + z * z * k]]
    return m


# The SDL reader's current transform: an affine map as 12 Python floats, the top three rows of its 4x4
# matrix, row after row (the bottom row is always 0 0 0 1).  A scene of 10^5 shapes has some 2·10^5
# transform statements; composing 4x4 NumPy arrays costs microseconds of call overhead each, the dozen
# multiplications here a fraction of that.  A product that is zero is +0.0 here (the ``+ 0.0``), as in a
# NumPy matrix product, whose sums start from +0.0: a -0.0 would only show up as "-0" when a scene is written.

Affine = tuple[float, ...]

IDENTITY_AFFINE: Affine = (1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 0.0, 1.0, 0.0)


def affine_translate(m: Affine, dx: float, dy: float, dz: float) -> Affine:
    """``m`` times translation(dx, dy, dz)."""
    a, b, c, x, d, e, f, y, g, h, i, z = m
    return (a, b, c, a * dx + b * dy + c * dz + x,
            d, e, f, d * dx + e * dy + f * dz + y,
            g, h, i, g * dx + h * dy + i * dz + z)


def affine_scale(m: Affine, sx: float, sy: float, sz: float) -> Affine:
    """``m`` times scaling(sx, sy, sz)."""
    a, b, c, x, d, e, f, y, g, h, i, z = m
    return (a * sx + 0.0, b * sy + 0.0, c * sz + 0.0, x, d * sx + 0.0, e * sy + 0.0, f * sz + 0.0, y,
            g * sx + 0.0, h * sy + 0.0, i * sz + 0.0, z)


def affine_times(m: Affine, matrix: np.ndarray) -> Affine:
    """``m`` times an affine 4x4 ``matrix`` (a rotation, say)."""
    (p, q, r, u), (s, t, v, w), (k, l, n, o), _ = matrix.tolist()
    a, b, c, x, d, e, f, y, g, h, i, z = m
    return (a * p + b * s + c * k + 0.0, a * q + b * t + c * l + 0.0, a * r + b * v + c * n + 0.0,
            a * u + b * w + c * o + x,
            d * p + e * s + f * k + 0.0, d * q + e * t + f * l + 0.0, d * r + e * v + f * n + 0.0,
            d * u + e * w + f * o + y,
            g * p + h * s + i * k + 0.0, g * q + h * t + i * l + 0.0, g * r + h * v + i * n + 0.0,
            g * u + h * w + i * o + z)


def affine_entries(m: Affine) -> tuple[float, ...]:
    """The 16 entries of the 4x4 matrix of ``m``, row after row (what np.array(...).reshape(4, 4) takes)."""
    return m + (0.0, 0.0, 0.0, 1.0)


def affine_matrix(m: Affine) -> np.ndarray:
    """The 4x4 matrix of ``m``."""
    return np.array(affine_entries(m), dtype=np.float64).reshape(4, 4)


def transform_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply an affine 4x4 to (..., 3) points."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def transform_vectors(matrix: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Apply the linear part of a 4x4 to (..., 3) directions."""
    return vectors @ matrix[:3, :3].T


def normal_matrix(matrix: np.ndarray) -> np.ndarray:
    """The 3x3 that carries generic normals to world normals: the inverse-transpose of the linear part."""
    return np.linalg.inv(matrix[:3, :3]).T


def polished_svd(linear: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A = U diag(s) Vt, accurate to a few units in the last place of the largest s.

    LAPACK's SVD can be off by dozens of units for sheared matrices (1e-12 on entries near 100), so its V
    is polished with one-sided Jacobi sweeps: rotate pairs of columns of W = A V until they are orthogonal
    to working precision; then s are the column lengths and U the normalised columns.
    """
    _, _, vt = np.linalg.svd(linear)
    v = vt.T.copy()
    w = linear @ v
    for _ in range(30):
        rotated = False
        for p, q in ((0, 1), (0, 2), (1, 2)):
            alpha, beta, gamma = w[:, p] @ w[:, p], w[:, q] @ w[:, q], w[:, p] @ w[:, q]
            if abs(gamma) <= _EPSILON * math.sqrt(alpha * beta):
                continue
            rotated = True
            zeta = (beta - alpha) / (2.0 * gamma)
            t = math.copysign(1.0, zeta) / (abs(zeta) + math.hypot(1.0, zeta))
            c = 1.0 / math.hypot(1.0, t)
            sn = c * t
            for m in (w, v):
                mp, mq = m[:, p].copy(), m[:, q].copy()
                m[:, p], m[:, q] = c * mp - sn * mq, sn * mp + c * mq
        if not rotated:
            break
    s = np.linalg.norm(w, axis=0)
    return w / s, s, v.T


def rotation_scale_rotation(linear: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``linear`` (3x3) = U diag(s) Vt with U and Vt proper rotations (determinant +1): an SVD whose
    reflections, if any, are moved into the sign of s[2].  Any affine map's linear part, shears
    included, is then rotate, scale, rotate."""
    u, s, vt = polished_svd(linear)
    if np.linalg.det(u) < 0:
        u[:, 2] *= -1
        s[2] *= -1
    if np.linalg.det(vt) < 0:
        vt[2, :] *= -1
        s[2] *= -1
    return u, s, vt
