"""The numerically stable quadratic, vectorised.

We solve ``A t^2 + 2 B t + C = 0`` (note the half coefficient B, as in the lecture).  The textbook
formula ``(-B ± sqrt(B^2 - AC)) / A`` loses digits when ``B^2 >> AC``; computing
``q = -(B + sign(B) sqrt(disc))`` and taking ``q / A`` and ``C / q`` never subtracts nearly equal numbers.
The same form also covers ``A = 0`` (a linear equation): ``q / A`` becomes infinite and ``C / q`` is the
one root.
"""
from __future__ import annotations

import numpy as np


def solve_quadratic(a: np.ndarray, b: np.ndarray, c: np.ndarray, disc: np.ndarray | None = None):
    """Roots ``(t_lo, t_hi, real)`` of ``a t^2 + 2 b t + c = 0`` per element.

    ``disc`` may be passed when the caller can compute ``b^2 - a c`` more accurately than the naive
    difference.  Where there are no real roots both times are NaN and ``real`` is False.  A tangent
    (zero discriminant) gives the double root twice.  Roots at infinity (a = 0) come back as ±inf.
    """
    if disc is None:
        disc = b * b - a * c
    real = disc >= 0.0
    with np.errstate(divide="ignore", invalid="ignore"):
        root = np.sqrt(np.where(real, disc, 0.0))
        q = -(b + np.where(b >= 0.0, root, -root))
        t1 = q / a
        t2 = c / q
        # q = 0 only when b = 0 and disc = 0, i.e. a*c = 0: a double root at -b/a = 0 (or no equation).
        zero_q = q == 0.0
        t1 = np.where(zero_q, np.where(c == 0.0, 0.0, np.nan), t1)
        t2 = np.where(zero_q, t1, t2)
    lo = np.where(real, np.fmin(t1, t2), np.nan)
    hi = np.where(real, np.fmax(t1, t2), np.nan)
    # fmin/fmax ignore a NaN partner; a lone NaN (0/0 from a = b = c = 0) means "no equation".
    return lo, hi, real & ~(np.isnan(lo) & np.isnan(hi))
