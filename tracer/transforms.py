"""4x4 affine matrices for SDL's transform statements (column vectors, angles in degrees)."""
from __future__ import annotations

import math

import numpy as np


def translation(dx: float, dy: float, dz: float) -> np.ndarray:
    m = np.eye(4)
    m[:3, 3] = (dx, dy, dz)
    return m


def scaling(sx: float, sy: float, sz: float) -> np.ndarray:
    return np.diag([sx, sy, sz, 1.0]).astype(np.float64)


def rotation(angle_degrees: float, ux: float, uy: float, uz: float) -> np.ndarray:
    """Right-handed rotation about the axis (ux, uy, uz), which is normalised here (Rodrigues' formula)."""
    axis = np.array([ux, uy, uz], dtype=np.float64)
    length = float(np.linalg.norm(axis))
    if length == 0.0 or not math.isfinite(length):
        raise ValueError("rotation axis must be a non-zero finite vector")
    x, y, z = axis / length
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


def transform_points(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply an affine 4x4 to (..., 3) points."""
    return points @ matrix[:3, :3].T + matrix[:3, 3]


def transform_vectors(matrix: np.ndarray, vectors: np.ndarray) -> np.ndarray:
    """Apply the linear part of a 4x4 to (..., 3) directions."""
    return vectors @ matrix[:3, :3].T


def normal_matrix(matrix: np.ndarray) -> np.ndarray:
    """The 3x3 that carries generic normals to world normals: the inverse-transpose of the linear part."""
    return np.linalg.inv(matrix[:3, :3]).T
