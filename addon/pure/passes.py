"""Render passes besides Combined: what the ray through each pixel's centre hits first.

* Depth (Blender's Z pass): distance from the camera's plane along its view axis; 1e10 where nothing is hit.
* Normal: the surface's unit normal there, in world space, pointing out of the object.
* DiffCol (the Diffuse Color pass, the compositor Denoise node's Albedo): the material's diffuse colour
  times its texture colour there.
* Position: the point hit, in world space.
* Mist: 0 at the world's mist start, 1 at start + depth and beyond (and where nothing is hit), with the
  mist's falloff, from the camera's distance to the hit.

Hits come from the backend that shades the Combined pass (the C core's first-hit query; the NumPy path
for the part of a textured primitive, which the texture lookup needs), so the passes agree with the image.
"""
from __future__ import annotations

import numpy as np

from ..tracer.trace import first_hits

#: Blender's pass name -> (ViewLayer switch, channel ids, socket type).
PASSES = {
    "Depth": ("use_pass_z", "Z", "VALUE"),
    "Normal": ("use_pass_normal", "XYZ", "VECTOR"),
    "DiffCol": ("use_pass_diffuse_color", "RGB", "COLOR"),
    "Position": ("use_pass_position", "XYZ", "VECTOR"),
    "Mist": ("use_pass_mist", "Z", "VALUE"),
}
#: Depth of a pixel that shows the background (Blender's own engines write this).
NO_DEPTH = 1.0e10


def enabled(view_layer) -> list[str]:
    """The passes this view layer asks for, in PASSES order."""
    return [name for name, (switch, _, _) in PASSES.items() if getattr(view_layer, switch, False)]


def mist_factor(distance: np.ndarray, start: float, depth: float, falloff: str) -> np.ndarray:
    """Blender's mist: 0 before ``start``, 1 from ``start + depth``, shaped by ``falloff`` in between."""
    x = np.clip((distance - start) / max(depth, 1e-12), 0.0, 1.0)
    if falloff == "QUADRATIC":
        return x * x
    if falloff == "INVERSE_QUADRATIC":
        return np.sqrt(x)
    return x


def _first_hits(tracer, compiled, origins, directions):
    """t (inf on a miss), unit normals and primitive indices, from the backend that shaded the image."""
    if hasattr(tracer, "first_hits"):
        hits = tracer.first_hits(origins, directions)
        return hits["t"], hits["normal"], hits["shape"]
    hits = first_hits(compiled, origins, directions)
    return hits.t, hits.normal, hits.shape


def _albedo(compiled, shape, points, origins, directions, hit) -> np.ndarray:
    out = np.zeros((len(shape), 3))
    primitives = compiled.primitives
    out[hit] = [primitives[s].shape.material.diffuse for s in shape[hit]]
    if compiled.textures is None:
        return out
    textured = hit & np.array([s >= 0 and primitives[s].shape.material.texture != 0 for s in shape])
    if textured.any():
        # the part of the surface hit (side or cap, face of a polyhedron) decides the texture coordinates
        found = first_hits(compiled, origins[textured], directions[textured])
        out[textured] *= compiled.textures.colors(found.shape, points[textured], found.part)
    return out


def compute(names, tracer, compiled, origins, directions, eye, forward, mist=None) -> dict:
    """``{name: (N, channels) float32}`` for the rays ``origins + t directions`` of the pixel centres.
    ``eye`` and unit ``forward``: the camera's position and view axis; ``mist``: (start, depth, falloff)."""
    t, normal, shape = _first_hits(tracer, compiled, origins, directions)
    hit = np.isfinite(t)
    points = origins + np.where(hit, t, 0.0)[:, None] * directions
    out = {}
    for name in names:
        if name == "Depth":
            value = np.where(hit, (points - eye) @ forward, NO_DEPTH)[:, None]
        elif name == "Normal":
            value = np.where(hit[:, None], normal, 0.0)
        elif name == "DiffCol":
            value = _albedo(compiled, shape, points, origins, directions, hit)
        elif name == "Position":
            value = np.where(hit[:, None], points, 0.0)
        elif name == "Mist":
            start, depth, falloff = mist if mist is not None else (5.0, 25.0, "QUADRATIC")
            distance = np.linalg.norm(points - eye, axis=1)
            value = np.where(hit, mist_factor(distance, start, depth, falloff), 1.0)[:, None]
        else:
            raise ValueError(f"unknown pass {name}")
        out[name] = np.asarray(value, dtype=np.float32)
    return out
