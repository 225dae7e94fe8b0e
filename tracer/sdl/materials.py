"""SDL's material keywords and the Material fields they set: the Python reader, the C reader's glue
(tracer.sdl.fastread) and the writer agree on them through these tables."""
from __future__ import annotations

#: Material keywords taking r g b, and the Material field each sets.
COLOR_MATERIAL = {"ambient": "ambient", "diffuse": "diffuse", "specular": "specular", "emissive": "emissive"}
#: Material keywords taking one number, and the Material field each sets.
FLOAT_MATERIAL = {"specularExponent": "specular_exponent", "reflectivity": "reflectivity",
                  "transparency": "transparency", "speedOfLight": "speed_of_light",
                  "specularFraction": "specular_fraction", "surfaceRoughness": "surface_roughness"}
#: The most numbers ``parameters`` may give (as in the book's material record).
MAX_PARAMETERS = 10
