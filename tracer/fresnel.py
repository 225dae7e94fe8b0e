"""How much of the light a mirror or glass surface reflects, for the Material.fresnel modes of Blender scenes
(docs/tracer.md, "Materials for Blender scenes"): Schlick's approximation for tinted metals and the exact
Fresnel equations for dielectrics.  tracer/native/shade.h computes the same numbers in the same order."""
from __future__ import annotations

import numpy as np

from .model import FRESNEL_MODES

CONSTANT, METAL, DIELECTRIC = (FRESNEL_MODES.index(mode) for mode in ("constant", "metal", "dielectric"))


def schlick(cos1: np.ndarray, tint: np.ndarray) -> np.ndarray:
    """(N, 3) reflectance F = F0 + (1 - F0)(1 - cos)^5 for cosines (N,) of the angle of incidence and F0 =
    ``tint`` (N, 3)."""
    m = 1.0 - cos1
    m2 = m * m
    m5 = (m2 * m2 * m)[:, None]
    return tint + (1.0 - tint) * m5


def dielectric(cos1: np.ndarray, ratio: np.ndarray) -> np.ndarray:
    """(N,) unpolarised reflectance of a smooth interface for cosines of the angle of incidence and ratios
    ``ratio`` = c2 / c1 = n1 / n2 of the speeds of light on the far and near side; 1 past the critical angle
    (total internal reflection)."""
    cos2_squared = 1.0 - ratio * ratio * (1.0 - cos1 * cos1)
    total_internal = cos2_squared < 0.0
    cos2 = np.sqrt(np.maximum(cos2_squared, 0.0))
    a = ratio * cos1
    b = ratio * cos2
    with np.errstate(divide="ignore", invalid="ignore"):
        rs = (a - cos2) / (a + cos2)
        rp = (cos1 - b) / (cos1 + b)
        return np.where(total_internal, 1.0, 0.5 * (rs * rs + rp * rp))
