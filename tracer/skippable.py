"""What a compiled scene lets the tracers skip (tracer.savings has the switches): materials that take nothing
from a light (no shadow feelers for them), and lights that a closed object seals off from its inside (no
feeler from inside it towards them).  Both backends use these tables.
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from . import shapes
from .compile import CompiledScene, fold_tree
from .lights import POINT, SPHERE, SPOT
from .savings import CLOSED_KINDS

#: Per kind code (the index in the shape registry): whether the kind is closed.
_CLOSED_CODES = np.array([e.keyword in CLOSED_KINDS for e in shapes.REGISTRY])
#: A direction for the point-in-solid test that no bundled shape's faces are parallel to.
_PROBE_DIRECTION = np.array([[0.5773, 0.5779, 0.5768]])


def light_takers(compiled: CompiledScene) -> tuple[np.ndarray, np.ndarray]:
    """Per material: whether it takes a light's diffuse term (some diffuse colour), and its highlight (some
    specular colour, or a Cook-Torrance share)."""
    mats = compiled.materials
    glossy = (mats.specular != 0).any(axis=1)
    if "cook-torrance" in compiled.effects:  # Schlick's Fresnel is not zero where the specular colour is
        glossy |= mats.specular_fraction != 0
    return (mats.diffuse != 0).any(axis=1), glossy


def dark_materials(compiled: CompiledScene) -> np.ndarray:
    """Per material: takes nothing from a light (zero diffuse, zero specular, no Cook-Torrance share)."""
    diffuse, glossy = light_takers(compiled)
    return ~diffuse & ~glossy


def _closed(node) -> bool:
    return fold_tree(node, lambda prim: prim.kind in CLOSED_KINDS, lambda _, left, right: left and right)


def _contains(node, point: np.ndarray) -> bool | None:
    """Whether ``point`` is inside the solid; None when it lies on (or too near) the surface to say."""
    hits = node.intersect(point[None, :], _PROBE_DIRECTION)
    t = hits.t[0]
    finite = np.isfinite(t)
    if np.any(np.abs(t[finite]) < 1e-9 * (1.0 + np.max(np.abs(point)))):
        return None
    before = np.nonzero(finite & (t < 0.0))[0]
    if before.size == 0:
        return bool(hits.inside_at_start[0])
    return bool(hits.entering[0, before[-1]])


def sealed_lights(compiled: CompiledScene, objects: Optional[np.ndarray] = None) -> np.ndarray:
    """(objects, lights) bool: a feeler from inside the object towards the light is certainly blocked
    (the object is a closed solid and the light outside it).  Only objects with some transparent material
    are examined: rays get inside solids through them.  Of every top-level object, or of the positions
    ``objects`` (in that order: tracer.edit's rows of the objects an edit changed)."""
    n_lights = len(compiled.light_positions)
    compiled_objects = compiled.objects
    chosen = np.arange(len(compiled_objects)) if objects is None else np.asarray(objects, dtype=np.int64)
    sealed = np.zeros((len(chosen), n_lights), dtype=bool)
    transparent = compiled.materials.transparency > 0
    # The plain shapes sifted all at once (a scene of 100,000 opaque spheres has none to examine), the
    # booleans one by one.
    table = compiled.table
    index = compiled_objects.primitive_index[chosen]
    plain = np.flatnonzero(index >= 0)
    rows = index[plain]
    closed = _CLOSED_CODES[table.kind[rows]]
    candidates = plain[transparent[table.material_ids[rows]] & closed].tolist()
    booleans = compiled_objects.booleans
    for j in np.flatnonzero(index < 0).tolist():
        obj = booleans[int(chosen[j])]
        if any(transparent[p.material_id] for p in obj.leaves()) and _closed(obj):
            candidates.append(j)
    # Only lights that are one point can be said to be outside (a sun, an area light or a sphere of some
    # radius sends feelers to points that may lie inside).
    points = [light for light in range(n_lights) if compiled.lights.kind[light] in (POINT, SPHERE, SPOT)
              and (compiled.lights.kind[light] == POINT or compiled.lights.param[light, 0] == 0.0)]
    for j in sorted(candidates):
        obj = compiled_objects[int(chosen[j])]
        for light in points:
            sealed[j, light] = _contains(obj, compiled.light_positions[light]) is False
    return sealed


def sealed_table(compiled: CompiledScene) -> np.ndarray:
    """sealed_lights of a compiled scene, computed once and kept on it (tracer.edit keeps it up to date, as a
    new array after each edit that changes it: a kept copy elsewhere is then seen to be stale)."""
    kept = compiled.__dict__.get(_SEALED_ATTRIBUTE)
    if kept is None:
        kept = compiled.__dict__[_SEALED_ATTRIBUTE] = sealed_lights(compiled)
    return kept


#: Where sealed_table keeps its table on the compiled scene.
_SEALED_ATTRIBUTE = "_sealed_lights"
