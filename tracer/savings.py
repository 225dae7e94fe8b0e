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

Each skipped ray is counted per reason (``RayCounts.skipped()``, ``--stats``).  What a compiled scene allows
to be skipped (which lights a closed object seals off, which materials take no light) is worked out in
:mod:`tracer.skippable`; this module holds the switches, which both backends and the C contract share.
"""
from __future__ import annotations

from dataclasses import dataclass

from . import shapes

#: Why a ray was not traced, in the order of RayCounts' skipped_* fields and the C core's counters.
SKIP_REASONS = ("cutoff", "inside_shadow", "shared_tir", "dark_material")
#: The on/off switches, in the bit order of RaySavings.flags() (the C core's SAVE_* bits).
SWITCHES = ("inside_shadows", "shared_tir", "dark_materials")
DEFAULT_CUTOFF = 1.0 / 512.0
#: Shapes that bound a solid (every ray into one comes out again): not the square (a sheet) nor meshes
#: (which may be open).  The plane is the half-space below it.  (ShapeKind.closed)
CLOSED_KINDS = frozenset(e.keyword for e in shapes.REGISTRY if e.closed)


@dataclass(frozen=True)
class RaySavings:
    cutoff: float = DEFAULT_CUTOFF
    inside_shadows: bool = True
    shared_tir: bool = True
    dark_materials: bool = True

    @classmethod
    def none(cls) -> "RaySavings":
        """Trace every ray, as the lecture's recursion does (for measuring what the savings change)."""
        return cls(cutoff=0.0, inside_shadows=False, shared_tir=False, dark_materials=False)

    def flags(self) -> int:
        """The switches that are on, as bits in the order of SWITCHES (for the C core)."""
        return sum(1 << k for k, name in enumerate(SWITCHES) if getattr(self, name))
