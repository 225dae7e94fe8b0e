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
tracer/native/shade.h and tracer.raytree.mirror_share: one rule, the same arithmetic).  A ray over the budget is not
traced: counted as skipped for "budget", which the command line reports in one warning.  No tree of
materials whose reflectivity and transparency add up to at most 1 meets it at the default cutoff (such a tree
has fewer than 2,200 rays worth tracing at any depth).

Each skipped ray is counted per reason (``RayCounts.skipped()``, ``--stats``).  What a compiled scene allows
to be skipped (which lights a closed object seals off, which materials take no light) is worked out in
:mod:`tracer.skippable`; this module holds the switches, which both backends and the C contract share.
"""
from __future__ import annotations

from dataclasses import dataclass

from . import shapes

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
