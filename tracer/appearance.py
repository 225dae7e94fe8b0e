"""SDL materials in a physically based renderer's terms: the approximations that other tools show
(UsdPreviewSurface in tracer.usd, Blender's Principled BSDF in the add-on).  The tracer never uses them."""
from __future__ import annotations

import math


def display_roughness(material) -> float:
    """A [0, 1] roughness for an SDL material (a tracer Material or anything with its field names): the
    Cook-Torrance roughness where that model is in use (specularFraction > 0), otherwise the Beckmann
    roughness whose highlight matches the Phong exponent n, sqrt(2 / (n + 2))."""
    if material.specular_fraction > 0:
        return min(1.0, max(0.0, material.surface_roughness))
    return min(1.0, math.sqrt(2.0 / (max(material.specular_exponent, 0.0) + 2.0)))
