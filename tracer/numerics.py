"""Tolerances, in one place, and why they have the size they have.

Everything is float64.  Errors in a computed hit point grow with the size of the coordinates involved
(a few ulps of |P|), not with the size of the objects, so every tolerance here is *relative to the
magnitude of the coordinates*: a fixed 1e-5 is far too small at 1e6 and far too big at 1e-6.
"""
from __future__ import annotations

import numpy as np

#: Relative size of "the same place": ~10^6 ulps, far above the rounding of a hit computation, far below
#: any feature a scene can show at that magnitude.
RELATIVE_EPSILON = 1e-9


def position_tolerance(points: np.ndarray) -> np.ndarray:
    """Distance under which two world points at (N, 3) ``points`` are the same place: (N,)."""
    return RELATIVE_EPSILON * (1.0 + np.max(np.abs(points), axis=-1))


def time_tolerance(origins: np.ndarray, directions: np.ndarray, t: np.ndarray) -> np.ndarray:
    """The ray-parameter tolerance matching :func:`position_tolerance` at times ``t`` (N, K) on rays (N, 3).

    ``|P| <= |O| + |t| |D|`` bounds the coordinates involved without computing P.
    """
    speed = np.linalg.norm(directions, axis=-1)
    scale = 1.0 + np.max(np.abs(origins), axis=-1)
    with np.errstate(invalid="ignore", divide="ignore"):
        tol = RELATIVE_EPSILON * (scale[:, None] / speed[:, None] + np.abs(np.where(np.isfinite(t), t, 0.0)))
    return tol
