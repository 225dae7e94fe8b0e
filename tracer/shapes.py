"""The shape registry: one entry per generic shape kind, read by everything that treats kinds differently.

An entry says what a kind is called in SDL, which C core kind traces it, how big its generic form is, which
functions intersect, texture-map and tessellate it, and how it behaves (closed, a thin sheet, unbounded).
compile.py, the C contract (native/contract.py, which generates the C dispatch tables in contract.h),
flatten.py, textures/mapping.py, the SDL parser, the USD writer and reader and the Blender add-on read it,
so adding a shape is one entry here plus its intersection code (docs/contributing.md, "Adding a shape").

Functions are named as ``"tracer.module:function"`` and imported when first used: this module imports
nothing of the tracer, so the scene model (and the add-on, which vendors the package under another name)
can read it without import cycles.
"""
from __future__ import annotations

import functools
import importlib
from dataclasses import dataclass
from typing import Callable, Optional

#: Tube radius of the generic torus (its ring radius is 1), as the book draws it.
TORUS_TUBE_RADIUS = 0.2

Vec3 = tuple[float, float, float]


@dataclass(frozen=True)
class ShapeKind:
    """One generic shape kind.

    ``family`` is "analytic" (a closed-form surface), "polyhedron" (a built-in convex polyhedron) or "mesh".
    ``box`` is the generic bounding box (centre, half extents) when it does not depend on a parameter.
    The function fields name ``"tracer.module:function"``:

    * ``intersect(origins, directions) -> HitArrays``: every crossing of the whole generic line (NumPy);
    * ``uv(points, parts) -> (u, v, wrap_u, wrap_v)``: the texture mapping (NumPy);
    * ``tessellate() -> MeshData``: polygons for USD and Blender, for kinds that have no parameter.

    ``c_intersect`` and ``c_uv`` name the C functions (``int f(const double *o, const double *d, Hit *out)``
    and ``void f(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u, int *wrap_v)``)
    that contract.h's generated dispatch tables call for the kind.  Kinds without them (parameters,
    tolerances) are dispatched by hand in compile.py, core.c and texture.h.
    """

    keyword: str
    c_kind: str
    family: str = "analytic"
    box: Optional[tuple[Vec3, Vec3]] = None
    #: A closed solid whose normals must agree with its entering flags (the square is a sheet, meshes keep
    #: their triangles' orientation, the plane's normal and flag come from one sign).
    normals_agree: bool = True
    #: Bounds a solid (every ray into it comes out again); the plane bounds the half-space below it.
    closed: bool = True
    #: A sheet with no inside: each crossing is an enter/exit pair.
    thin: bool = False
    bounded: bool = True
    intersect: Optional[str] = None
    uv: Optional[str] = None
    tessellate: Optional[str] = None
    c_intersect: Optional[str] = None
    c_uv: Optional[str] = None
    #: Offered in the Blender add-on's Add menu (a mesh needs a file).
    addable: bool = True
    #: Not in the book's SDL (docs/sdl.md, "SDL extensions"): the bundled scenes, which keep to the book,
    #: need not use it; its own test renders it instead.
    extension: bool = False

    def function(self, field: str) -> Callable:
        """The Python function a field names, imported from this tracer package (whatever it is called)."""
        return _resolve(getattr(self, field))


@functools.cache
def _resolve(reference: str) -> Callable:
    module, name = reference.split(":")
    package = __package__ or "tracer"
    return getattr(importlib.import_module(package + module[len("tracer"):]), name)


#: The mapping of a wall about z by angle and height with its discs as squares (the tapered cylinders').
WALL_AND_DISCS_UV = "tracer.textures.mapping:wall_and_discs_uv"
_UNIT = ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
_TORUS_OUTER = 1.0 + TORUS_TUBE_RADIUS


def _polyhedron(keyword: str) -> ShapeKind:
    return ShapeKind(keyword, "POLYHEDRON", family="polyhedron")


def _tapered(keyword: str) -> ShapeKind:
    # Its box and mesh depend on the top radius: compile.py, flatten.py and the tessellators handle it.
    return ShapeKind(keyword, "TAPERED", uv=WALL_AND_DISCS_UV, c_uv="wall_and_discs_uv")


#: Every kind, in the order of SDL's documentation; C kind codes follow the first appearance of each c_kind.
REGISTRY: tuple[ShapeKind, ...] = (
    ShapeKind("sphere", "SPHERE", box=_UNIT, intersect="tracer.intersect.analytic:intersect_sphere",
              c_intersect="hits_sphere"),
    ShapeKind("cube", "CUBE", box=_UNIT, intersect="tracer.intersect.analytic:intersect_cube",
              c_intersect="hits_cube"),
    ShapeKind("square", "SQUARE", box=((0.0, 0.0, 0.0), (1.0, 1.0, 0.0)), normals_agree=False, closed=False,
              thin=True, tessellate="tracer.geometry.tessellate:square_mesh"),
    ShapeKind("plane", "PLANE", normals_agree=False, bounded=False),
    _tapered("taperedCylinder"),
    _tapered("cylinder"),
    _tapered("cone"),
    ShapeKind("torus", "TORUS", box=((0.0, 0.0, 0.0), (_TORUS_OUTER, _TORUS_OUTER, TORUS_TUBE_RADIUS)),
              tessellate="tracer.geometry.tessellate:torus_mesh"),
    *(_polyhedron(k) for k in ("tetrahedron", "octahedron", "dodecahedron", "icosahedron", "buckyball", "diamond")),
    ShapeKind("teapot", "MESH", family="mesh", normals_agree=False, closed=False),
    ShapeKind("mesh", "MESH", family="mesh", normals_agree=False, closed=False, addable=False),
    # SDL extensions (append new kinds here: C kind codes follow this order).
    ShapeKind("paraboloid", "PARABOLOID", box=((0.0, 0.0, 0.5), (1.0, 1.0, 0.5)),
              intersect="tracer.intersect.paraboloid:intersect_paraboloid", c_intersect="hits_paraboloid",
              uv=WALL_AND_DISCS_UV, c_uv="wall_and_discs_uv",
              tessellate="tracer.intersect.paraboloid:paraboloid_mesh", extension=True),
)

#: SDL keyword -> entry.
KINDS: dict[str, ShapeKind] = {entry.keyword: entry for entry in REGISTRY}


def keywords(family: Optional[str] = None) -> tuple[str, ...]:
    """The SDL keywords of every kind, or of one family, in registry order."""
    return tuple(e.keyword for e in REGISTRY if family is None or e.family == family)


def c_kinds() -> tuple[tuple[str, tuple[str, ...]], ...]:
    """The C core's kinds in code order, each with the SDL keywords it traces."""
    grouped: dict[str, list[str]] = {}
    for entry in REGISTRY:
        grouped.setdefault(entry.c_kind, []).append(entry.keyword)
    return tuple((c_kind, tuple(words)) for c_kind, words in grouped.items())


assert len(KINDS) == len(REGISTRY), "two registry entries share a keyword"
