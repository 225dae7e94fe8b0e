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
class Parameter:
    """A number a shape kind reads after its SDL keyword.  A kind's parameters are listed in the order SDL
    writes them (their index is their SDL argument position: ``taperedCylinder s``)."""

    #: The Python name (the Blender Add operator's property): ``small_radius``.
    name: str
    #: Its name in SDL's usage text (``'taperedCylinder s'``).
    usage: str
    #: Its value in a Shape made without it.
    default: float
    #: The USD attribute that keeps it on a tessellated prim: ``sdl:smallRadius``.
    usd_attribute: str
    #: Blender's label and tooltip for it.
    label: str
    description: str
    #: What Blender's Add menu starts from.
    add_value: float


@dataclass(frozen=True)
class ShapeKind:
    """One generic shape kind.

    ``family`` is "analytic" (a closed-form surface), "polyhedron" (a built-in convex polyhedron) or "mesh".
    ``box`` is the generic bounding box (centre, half extents) when it does not depend on a parameter;
    ``bounds`` names the function that gives it when it does.  The function fields name
    ``"tracer.module:function"`` (read docs/contributing.md, "Adding a shape", for the whole protocol):

    * ``intersect(origins, directions, *values, [tolerances]) -> HitArrays``: every crossing of the whole
      generic line (NumPy).  ``values`` are the kind's parameters (:meth:`traced`), and a kind with an
      error ``budget`` is given the compiled scene's ``tracer.numerics.Tolerances`` last.  Polyhedra are given
      their face planes (normals, offsets), meshes their ``TriangleMesh``, instead of values;
    * ``bounds(values) -> points``: for (N, P) parameter rows, (N, K, 3) generic points whose hull holds the
      solid (kinds without a fixed ``box``);
    * ``uv(points, parts) -> (u, v, wrap_u, wrap_v)``: the texture mapping (NumPy);
    * ``tessellate(*values) -> MeshData``: polygons for USD and Blender.

    ``c_intersect`` and ``c_uv`` name the C functions that contract.h's generated dispatch calls for the
    kind: ``int f(const double *o, const double *d, <values>, <budget fields>, Hit *out)`` (an unbounded
    kind also reports ``int *inside``, whether the line starts inside it; polyhedra take their face planes
    and count instead of values; the mesh family's is the C core's BVH traversal) and ``void f(double x,
    double y, double z, int32_t part, double *u, double *v, int *wrap_u, int *wrap_v)``.
    """

    keyword: str
    c_kind: str
    family: str = "analytic"
    box: Optional[tuple[Vec3, Vec3]] = None
    #: The numbers SDL reads after the keyword, in order (see Parameter).
    parameters: tuple[Parameter, ...] = ()
    #: The values of its C kind's parameters for a keyword that reads none (a cylinder is a tapered
    #: cylinder of top radius 1).
    fixed: tuple[float, ...] = ()
    #: Its error budget: the tracer.numerics.Tolerances fields its intersection reads, in the order the C
    #: function takes them (after the values).
    budget: tuple[str, ...] = ()
    #: A closed solid whose normals must agree with its entering flags (the square is a sheet, meshes keep
    #: their triangles' orientation, the plane's normal and flag come from one sign).
    normals_agree: bool = True
    #: Bounds a solid (every ray into it comes out again); the plane bounds the half-space below it.
    closed: bool = True
    #: A sheet with no inside: each crossing is an enter/exit pair.
    thin: bool = False
    bounded: bool = True
    intersect: Optional[str] = None
    bounds: Optional[str] = None
    uv: Optional[str] = None
    tessellate: Optional[str] = None
    c_intersect: Optional[str] = None
    c_uv: Optional[str] = None
    #: The UsdGeom implicit prim that stands for it ("Sphere", ...); None: a Mesh of its tessellation (or of
    #: its mesh), which the USD reader reads back as the exact shape by its ``sdl:shape``.
    usd_prim: Optional[str] = None
    #: The function of the Blender add-on's ``primitives`` module that draws it (finer than ``tessellate``;
    #: given the values); None: its tessellation, or its mesh.
    blender_mesh: Optional[str] = None
    #: SDL gives it a file (``mesh file``) rather than numbers.
    file_argument: bool = False
    #: Offered in the Blender add-on's Add menu (a mesh needs a file).
    addable: bool = True
    #: Not in the book's SDL (docs/sdl.md, "SDL extensions"): the bundled scenes, which keep to the book,
    #: need not use it; its own test renders it instead.
    extension: bool = False

    def function(self, field: str) -> Callable:
        """The Python function a field names, imported from this tracer package (whatever it is called)."""
        return _resolve(getattr(self, field))

    @property
    def defaults(self) -> tuple[float, ...]:
        """The parameters of a Shape made without them."""
        return tuple(p.default for p in self.parameters)

    def traced(self, parameters: tuple[float, ...]) -> tuple[float, ...]:
        """The values its intersection, bounds and tessellation take, for a shape with these parameters."""
        return tuple(parameters) if self.parameters else self.fixed

    @property
    def usage(self) -> str:
        """What SDL's usage text shows after the keyword: its parameters, or ``file``."""
        return "file" if self.file_argument else " ".join(p.usage for p in self.parameters)

    @property
    def builtin_mesh(self) -> bool:
        """Its shapes hold the kind's own mesh (tracer.geometry.builtin_mesh): the polyhedra and the teapot."""
        return self.family != "analytic" and not self.file_argument


@functools.cache
def _resolve(reference: str) -> Callable:
    module, name = reference.split(":")
    package = __package__ or "tracer"
    return getattr(importlib.import_module(package + module[len("tracer"):]), name)


#: The mapping of a wall about z by angle and height with its discs as squares (the tapered cylinders').
WALL_AND_DISCS_UV = "tracer.textures.mapping:wall_and_discs_uv"
#: The direction from the generic centre, as on a globe (polyhedra and meshes).
DIRECTION_UV = "tracer.textures.mapping:direction_uv"
_UNIT = ((0.0, 0.0, 0.0), (1.0, 1.0, 1.0))
_TORUS_OUTER = 1.0 + TORUS_TUBE_RADIUS


def _polyhedron(keyword: str) -> ShapeKind:
    return ShapeKind(keyword, "POLYHEDRON", family="polyhedron",
                     intersect="tracer.intersect.analytic:intersect_convex_polyhedron", c_intersect="hits_polyhedron",
                     uv=DIRECTION_UV, c_uv="direction_uv")


def _mesh(keyword: str, **flags) -> ShapeKind:
    return ShapeKind(keyword, "MESH", family="mesh", normals_agree=False, closed=False,
                     intersect="tracer.intersect.mesh:intersect_mesh", c_intersect="mesh_all",
                     uv=DIRECTION_UV, c_uv="direction_uv", **flags)


def _tapered(keyword: str, parameters: tuple[Parameter, ...] = (), fixed: tuple[float, ...] = (),
             usd_prim: Optional[str] = None) -> ShapeKind:
    return ShapeKind(keyword, "TAPERED", parameters=parameters, fixed=fixed, budget=("hit_ulps",),
                     intersect="tracer.intersect.analytic:intersect_tapered_cylinder", c_intersect="hits_tapered",
                     bounds="tracer.intersect.analytic:tapered_cylinder_bounds",
                     uv=WALL_AND_DISCS_UV, c_uv="wall_and_discs_uv",
                     tessellate="tracer.geometry.tessellate:tapered_cylinder_mesh", usd_prim=usd_prim,
                     blender_mesh="tapered_cylinder")


#: taperedCylinder's one parameter: the radius of its top (its base has radius 1).
SMALL_RADIUS = Parameter("small_radius", "s", 1.0, "sdl:smallRadius", "Top Radius", "Top radius of a tapered cylinder",
                         0.5)

#: The hyperboloid's one parameter: the radius of its waist (its ends have radius 1).
WAIST = Parameter("waist", "S", 0.5, "sdl:waistRadius", "Waist Radius", "Radius of a hyperboloid's waist (z = 0)",
                  0.5)

#: Every kind, in the order of SDL's documentation; C kind codes follow the first appearance of each c_kind.
REGISTRY: tuple[ShapeKind, ...] = (
    ShapeKind("sphere", "SPHERE", box=_UNIT, intersect="tracer.intersect.analytic:intersect_sphere",
              c_intersect="hits_sphere", uv="tracer.textures.mapping:sphere_uv", c_uv="sphere_uv",
              usd_prim="Sphere", blender_mesh="sphere"),
    ShapeKind("cube", "CUBE", box=_UNIT, intersect="tracer.intersect.analytic:intersect_cube",
              c_intersect="hits_cube", uv="tracer.textures.mapping:cube_uv", c_uv="cube_uv", usd_prim="Cube",
              blender_mesh="cube"),
    ShapeKind("square", "SQUARE", box=((0.0, 0.0, 0.0), (1.0, 1.0, 0.0)), budget=("square_edge",),
              normals_agree=False, closed=False, thin=True, intersect="tracer.intersect.analytic:intersect_square",
              c_intersect="hits_square", uv="tracer.textures.mapping:square_uv", c_uv="square_uv",
              tessellate="tracer.geometry.tessellate:square_mesh", blender_mesh="square"),
    ShapeKind("plane", "PLANE", normals_agree=False, bounded=False,
              intersect="tracer.intersect.analytic:intersect_plane", c_intersect="hits_plane",
              uv="tracer.textures.mapping:plane_uv", c_uv="plane_uv", usd_prim="Plane", blender_mesh="plane"),
    _tapered("taperedCylinder", parameters=(SMALL_RADIUS,)),
    _tapered("cylinder", fixed=(1.0,), usd_prim="Cylinder"),
    _tapered("cone", fixed=(0.0,), usd_prim="Cone"),
    ShapeKind("torus", "TORUS", box=((0.0, 0.0, 0.0), (_TORUS_OUTER, _TORUS_OUTER, TORUS_TUBE_RADIUS)),
              budget=("torus_newton_steps", "torus_residual_ulps", "torus_pair_shortcut"),
              intersect="tracer.intersect.torus:intersect_torus", c_intersect="hits_torus",
              uv="tracer.textures.mapping:torus_uv", c_uv="torus_uv",
              tessellate="tracer.geometry.tessellate:torus_mesh", blender_mesh="torus"),
    *(_polyhedron(k) for k in ("tetrahedron", "octahedron", "dodecahedron", "icosahedron", "buckyball", "diamond")),
    _mesh("teapot"),
    _mesh("mesh", file_argument=True, addable=False),
    # SDL extensions (append new kinds here: C kind codes follow this order).
    ShapeKind("paraboloid", "PARABOLOID", box=((0.0, 0.0, 0.5), (1.0, 1.0, 0.5)), budget=("hit_ulps",),
              intersect="tracer.intersect.paraboloid:intersect_paraboloid", c_intersect="hits_paraboloid",
              uv=WALL_AND_DISCS_UV, c_uv="wall_and_discs_uv",
              tessellate="tracer.intersect.paraboloid:paraboloid_mesh", extension=True),
    ShapeKind("hyperboloid", "HYPERBOLOID", parameters=(WAIST,), budget=("hit_ulps",),
              intersect="tracer.intersect.hyperboloid:intersect_hyperboloid", c_intersect="hits_hyperboloid",
              bounds="tracer.intersect.hyperboloid:hyperboloid_bounds",
              uv="tracer.intersect.hyperboloid:hyperboloid_uv", c_uv="hyperboloid_uv",
              tessellate="tracer.intersect.hyperboloid:hyperboloid_mesh", extension=True),
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


#: The most parameters a kind takes (or its intersection takes): the columns of a ShapeTable's and the C
#: core's parameter rows.
MAX_PARAMETERS = max(max(len(e.parameters), len(e.fixed)) for e in REGISTRY)

assert len(KINDS) == len(REGISTRY), "two registry entries share a keyword"
