"""Rays that cannot change the image, and the switches that skip them (both backends honour them).

* ``cutoff``: a reflected or transmitted ray whose cumulative weight (the product of the reflectivities
  and transparencies on its way from the eye) is below this is not traced; it adds nothing.  A ray that
  would bring back colour c adds weight * c, so with c <= 1 the change is below the cutoff.
* ``inside_shadows``: a surface hit from inside a closed object (its ray was inside the solid) lights its
  shadow feeler from inside that solid; when the light is outside the solid, the feeler must cross the
  surface and is blocked, so it is not cast.
* ``shared_tir``: under total internal reflection the "transmitted" ray is the mirror ray that the
  material's reflectivity already traces; it is traced once and weighted by both coefficients.
* ``dark_materials``: a material with no diffuse and no specular colour (and no Cook-Torrance part) takes
  nothing from a light, so it casts no shadow feelers.

Not a saving but a bound on work, and part of the same settings because both backends honour it the same
way: ``ray_budget``, the most reflected and transmitted rays one camera ray's tree may trace (RAY_BUDGET).
The depth limit alone does not bound a tree: two mirrors facing each other, or glass that both reflects and
transmits 95 %, double the rays at every level with weights the cutoff never stops (2^64 rays at depth 64).
The budget is shared down the tree: a ray's first child (the mirror ray), when a second is wanted too, may
give its own subtree a part of what is left in proportion to its weight, but at least a chain as long as
the levels left, and the second child gets everything left after the first's subtree (take_ray in
tracer/native/shade.h and Tracer._take_rays: one rule, the same arithmetic).  A ray over the budget is not
traced: counted as skipped for "budget", which the command line reports in one warning.  No tree of
materials whose reflectivity and transparency add up to at most 1 meets it at the default cutoff (such a tree
has fewer than 2,200 rays worth tracing at any depth).

Each skipped ray is counted per reason (``RayCounts.skipped()``, ``--stats``).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional

import numpy as np

from . import shapes
from .compile import CompiledScene, fold_tree
from .lights import POINT, SPHERE, SPOT

#: Why a ray was not traced, in the order of RayCounts' skipped_* fields and the C core's counters.
SKIP_REASONS = ("cutoff", "inside_shadow", "shared_tir", "dark_material", "budget")
#: The on/off switches, in the bit order of RaySavings.flags() (the C core's SAVE_* bits).
SWITCHES = ("inside_shadows", "shared_tir", "dark_materials")
DEFAULT_CUTOFF = 1.0 / 512.0
#: Most reflected and transmitted rays a camera ray's tree traces (see the module's note): 4,096, about twice
#: what an energy-conserving material can ask for at the default cutoff; a 32 x 24 image then traces at most
#: 3.1 million secondary rays.
RAY_BUDGET = 4096
#: Shapes that bound a solid (every ray into one comes out again): not the square (a sheet) nor meshes
#: (which may be open).  The plane is the half-space below it.  (ShapeKind.closed)
CLOSED_KINDS = frozenset(e.keyword for e in shapes.REGISTRY if e.closed)
#: Per kind code (the index in the shape registry): whether the kind is closed.
_CLOSED_CODES = np.array([e.keyword in CLOSED_KINDS for e in shapes.REGISTRY])
#: A direction for the point-in-solid test that no bundled shape's faces are parallel to.
_PROBE_DIRECTION = np.array([[0.5773, 0.5779, 0.5768]])


@dataclass(frozen=True)
class RaySavings:
    cutoff: float = DEFAULT_CUTOFF
    inside_shadows: bool = True
    shared_tir: bool = True
    dark_materials: bool = True
    ray_budget: int = RAY_BUDGET

    @classmethod
    def none(cls) -> "RaySavings":
        """Trace every ray, as the lecture's recursion does (for measuring what the savings change), up to
        the ray budget (which only bounds the work)."""
        return cls(cutoff=0.0, inside_shadows=False, shared_tir=False, dark_materials=False)

    def flags(self) -> int:
        """The switches that are on, as bits in the order of SWITCHES (for the C core)."""
        return sum(1 << k for k, name in enumerate(SWITCHES) if getattr(self, name))


def dark_materials(compiled: CompiledScene) -> np.ndarray:
    """Per material: takes nothing from a light (zero diffuse, zero specular, no Cook-Torrance share)."""
    mats = compiled.materials
    dark = ~(mats.diffuse != 0).any(axis=1) & ~(mats.specular != 0).any(axis=1)
    if "cook-torrance" in compiled.effects:  # Schlick's Fresnel is not zero where the specular colour is
        dark &= mats.specular_fraction == 0
    return dark


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
