"""The scene model: plain data that SDL, Blender and USD all build.

Nothing here knows about SDL syntax or about how rays are traced.  Matrices are
4x4 float64 arrays that map a shape's *generic* coordinates to world
coordinates (column vectors: ``world = matrix @ generic``).
"""
from __future__ import annotations

from dataclasses import dataclass, field, fields
from itertools import repeat
from pathlib import Path
from collections.abc import MutableSequence, Sequence
from typing import Optional, Union

import numpy as np

from . import shapes
from .bulk import collector_paused
from .errors import SceneError
from .geometry import builtin_mesh
from .meshdata import FaceList, MeshData
from .shapes import TORUS_TUBE_RADIUS  # noqa: F401 - part of the model's vocabulary

Color = tuple[float, float, float]
Vec3 = tuple[float, float, float]

#: Generic shapes whose geometry is a closed-form surface.
ANALYTIC_KINDS = shapes.keywords("analytic")
#: Built-in convex polyhedra (the book loads these from .3vn files).
POLYHEDRON_KINDS = shapes.keywords("polyhedron")
#: Shapes made of triangles.
MESH_KINDS = shapes.keywords("mesh")
#: Kinds whose shapes hold the kind's own mesh (tracer.geometry.builtin_mesh): the polyhedra and the teapot.
BUILTIN_MESH_KINDS = tuple(e.keyword for e in shapes.REGISTRY if e.builtin_mesh)
SHAPE_KINDS = shapes.keywords()


@dataclass(frozen=True, slots=True)  # slots: one per shape, 40 bytes less each
class SourceLocation:
    """Where something came from, for messages: file (may be None for text), line and column (1-based; line 0
    for a place without lines: a USD stage's prim, whose path the file name carries)."""

    file: Optional[str]
    line: int
    column: int = 0

    def __str__(self) -> str:
        name = self.file or "<sdl>"
        if not self.line:
            return name
        return f"{name}:{self.line}:{self.column}" if self.column else f"{name}:{self.line}"


#: Texture numbers a material may hold: the material tables keep them as 32-bit integers (the C core's
#: ``mat_texture``).  Only -3..-1 and the makePixmap numbers mean something; the rest are reported as unknown
#: textures, but a number beyond these would not even fit the table.
TEXTURE_NUMBERS = range(-2**31, 2**31)


@dataclass(frozen=True, slots=True)  # slots: a scene of 10^5 shapes may hold as many materials
class Material:
    """Surface properties; SDL's defaults (see docs/sdl.md)."""

    ambient: Color = (0.1, 0.1, 0.1)
    diffuse: Color = (0.8, 0.8, 0.8)
    specular: Color = (0.0, 0.0, 0.0)
    emissive: Color = (0.0, 0.0, 0.0)
    specular_exponent: float = 1.0
    reflectivity: float = 0.0
    transparency: float = 0.0
    speed_of_light: float = 1.0
    specular_fraction: float = 0.0
    surface_roughness: float = 1.0
    texture: int = 0
    parameters: tuple[float, ...] = ()
    #: How the mirror and transmitted rays are weighted (an extension; see docs/tracer.md, "Materials for
    #: Blender scenes"): ``"constant"`` (SDL: reflectivity and transparency as given), ``"metal"`` (the mirror
    #: ray weighted by reflectivity times Schlick's Fresnel from ``fresnel_tint``, coloured) or
    #: ``"dielectric"`` (reflectivity and transparency split by the exact Fresnel reflectance of the interface,
    #: from the speeds of light on its two sides).
    fresnel: str = "constant"
    #: ``"metal"``: the reflectance at normal incidence, per channel (Schlick's F0).
    fresnel_tint: Color = (1.0, 1.0, 1.0)

    def __post_init__(self) -> None:
        if self.fresnel not in FRESNEL_MODES:
            raise SceneError(f"unknown fresnel mode {self.fresnel!r} (expected one of {', '.join(FRESNEL_MODES)})")


#: Material.fresnel's values, in the order of their codes in the material tables.
FRESNEL_MODES = ("constant", "metal", "dielectric")
#: Material fields that are not kept in MaterialRows (the C reader declines the statements that set them).
_NOT_IN_ROWS = ("texture", "parameters", "fresnel", "fresnel_tint")


def _material_slots() -> dict[str, tuple[int, int]]:
    """(first slot, width) in a MaterialRows row of each Material field but the texture and parameters."""
    slots, at = {}, 0
    for f in fields(Material):
        if f.name not in _NOT_IN_ROWS:
            width = 3 if isinstance(f.default, tuple) else 1
            slots[f.name], at = (at, width), at + width
    return slots


class MaterialRows(Sequence):
    """Materials kept as one row of numbers each (``rows``, (M, :attr:`WIDTH`) float64), as a fast reader hands
    them over: a million spheres of their own colours are a million materials, and making each a Material
    object took most of the time of reading them.  It reads as the sequence of those Materials (each made
    when first asked for, then the same object); compiling reads the columns (:meth:`column`).

    A row holds the fields in Material's order: a colour takes three slots, a number one, the texture one,
    then the count of parameters and :attr:`MAX_PARAMETERS` slots for them (unused ones 0).  The extensions
    ``fresnel`` and ``fresnel_tint`` are not kept: a row's Material has their defaults."""

    MAX_PARAMETERS = 10
    #: (first slot, width) of each colour and number field
    SLOTS: dict[str, tuple[int, int]] = _material_slots()
    TEXTURE = sum(width for _, width in SLOTS.values())
    PARAMETER_COUNT = TEXTURE + 1
    WIDTH = PARAMETER_COUNT + 1 + MAX_PARAMETERS

    def __init__(self, rows: np.ndarray):
        rows = np.array(rows, dtype=np.float64, order="C").reshape(-1, self.WIDTH)
        rows.setflags(write=False)
        self.rows = rows
        self._made: dict[int, Material] = {}

    @classmethod
    def row_of(cls, material: Material) -> np.ndarray:
        """The row of one Material (parameters beyond MAX_PARAMETERS are not kept)."""
        row = np.zeros(cls.WIDTH)
        for name, (start, width) in cls.SLOTS.items():
            row[start:start + width] = getattr(material, name)
        row[cls.TEXTURE] = material.texture
        parameters = material.parameters[:cls.MAX_PARAMETERS]
        row[cls.PARAMETER_COUNT] = len(parameters)
        row[cls.PARAMETER_COUNT + 1:cls.PARAMETER_COUNT + 1 + len(parameters)] = parameters
        return row

    def column(self, name: str) -> np.ndarray:
        """Field ``name`` of every row: (M, 3) for a colour, (M,) for a number; the texture as int64."""
        if name == "texture":
            return self.rows[:, self.TEXTURE].astype(np.int64)
        start, width = self.SLOTS[name]
        return self.rows[:, start] if width == 1 else self.rows[:, start:start + width]

    def __len__(self) -> int:
        return len(self.rows)

    def __getitem__(self, index):
        if isinstance(index, slice):
            return [self[i] for i in range(*index.indices(len(self)))]
        index = range(len(self))[index]  # (negative from the end; IndexError)
        made = self._made.get(index)
        if made is None:
            values = self.rows[index].tolist()
            kept = {name: (tuple(values[start:start + width]) if width == 3 else values[start])
                    for name, (start, width) in self.SLOTS.items()}
            count = int(values[self.PARAMETER_COUNT])
            made = self._made[index] = Material(
                **kept, texture=int(values[self.TEXTURE]),
                parameters=tuple(values[self.PARAMETER_COUNT + 1:self.PARAMETER_COUNT + 1 + count]))
        return made

    def used(self, mask: np.ndarray) -> "MaterialRows":
        """The rows where ``mask`` is true, as a table of their own."""
        return MaterialRows(self.rows[mask])

    def __eq__(self, other) -> bool:
        if isinstance(other, MaterialRows):
            return self.rows.shape == other.rows.shape and bool(np.array_equal(self.rows, other.rows))
        return NotImplemented

    __hash__ = None

    def __reduce__(self):
        return MaterialRows, (self.rows,)


@dataclass(slots=True)  # slots: a scene may hold 10^6 shapes, and a __dict__ each would add 160 bytes to each
class Shape:
    """One generic shape placed in the world.

    ``kind`` is the SDL keyword (``cylinder`` and ``cone`` stay themselves so that they are written back
    as they were read).  ``parameters`` are the numbers its keyword takes (tracer.shapes: the kind's
    Parameters, in SDL order; its defaults when none are given).  ``mesh`` is filled for polyhedra, the
    teapot and meshes; ``mesh_file`` keeps the file name a ``mesh`` statement gave.
    """

    kind: str
    matrix: np.ndarray = field(default_factory=lambda: np.eye(4))
    material: Material = field(default_factory=Material)
    parameters: tuple[float, ...] = ()
    mesh: Optional[MeshData] = None
    mesh_file: Optional[str] = None
    #: Names of the def macros this shape was made inside, outermost first (for grouping in Blender).
    groups: tuple[str, ...] = ()
    source: Optional[SourceLocation] = None
    #: The object's name: from a ``! name:`` comment before the shape in SDL, or the Blender object's name.
    name: Optional[str] = None

    def __post_init__(self) -> None:
        arity = _ARITY.get(self.kind)
        if arity is None:
            raise SceneError(f"unknown shape kind {self.kind!r}")
        if type(self.parameters) is not tuple or len(self.parameters) != arity:
            self.parameters = _parameters_of(self.kind, self.parameters)
        matrix = np.array(self.matrix, dtype=np.float64)  # a copy of its own
        # (16 numbers are reshaped and copied again: a reshaped view would keep a second array per shape.)
        self.matrix = matrix if matrix.shape == (4, 4) else matrix.reshape(4, 4).copy()

    def __eq__(self, other) -> bool:
        # (by value, matrix and mesh included: the generated __eq__ would compare the matrices as a tuple
        # field, which NumPy refuses to turn into one bool)
        if not isinstance(other, Shape):
            return NotImplemented
        return (self.kind == other.kind and np.array_equal(self.matrix, other.matrix)
                and self.material == other.material and self.parameters == other.parameters
                and _same_mesh(self.mesh, other.mesh) and self.mesh_file == other.mesh_file
                and self.groups == other.groups and self.source == other.source and self.name == other.name)

    __hash__ = None  # (mutable)

    @property
    def inverse(self) -> np.ndarray:
        return np.linalg.inv(self.matrix)


#: How many parameters each kind's keyword takes, by keyword and by kind code.
_ARITY = {e.keyword: len(e.parameters) for e in shapes.REGISTRY}
_ARITY_OF_CODE = np.array([len(e.parameters) for e in shapes.REGISTRY])


def _parameters_of(kind: str, given) -> tuple[float, ...]:
    """A shape's parameters as floats: the kind's defaults for none, else exactly as many as it takes."""
    entry = shapes.KINDS[kind]
    values = tuple(float(v) for v in given) if given is not None else ()
    if not values:
        return entry.defaults
    if len(values) != len(entry.parameters):
        raise SceneError(f"{kind} takes {len(entry.parameters)} parameter(s), not {len(values)}")
    return values


def _same_mesh(a: Optional[MeshData], b: Optional[MeshData]) -> bool:
    """Whether two shapes' meshes are equal: the same object (a cached built-in mesh) or equal arrays."""
    if a is b:
        return True
    if a is None or b is None:
        return False
    return (np.array_equal(a.vertices, b.vertices) and np.array_equal(a.normals, b.normals)
            and (a.faces == b.faces if isinstance(a.faces, FaceList) else b.faces == a.faces)
            and (a.corner_uvs is None) == (b.corner_uvs is None)
            and (a.corner_uvs is None or np.array_equal(a.corner_uvs, b.corner_uvs)))


#: The SDL keyword of each shape kind code (tracer.shapes.REGISTRY's order; ShapeTable.kinds).
_KEYWORD_OF_CODE = tuple(e.keyword for e in shapes.REGISTRY)


@dataclass(frozen=True, eq=False)
class ShapeColumns:
    """The arrays of a :class:`ShapeTable` (see there), read-only: row i is shape i."""

    kinds: np.ndarray  # (N,) int16
    affines: np.ndarray  # (N, 12) float64, or float32 (values a float32 holds: Blender's matrices)
    material_ids: np.ndarray  # (N,) int32
    materials: Sequence[Material]  # a tuple, or a MaterialRows
    parameters: np.ndarray  # (N, shapes.MAX_PARAMETERS) float64
    lines: Optional[np.ndarray]  # (N,) int32; None: no row has a source
    columns: Optional[np.ndarray]  # (N,) int32; None with lines
    file: Optional[str] = None
    names: Optional[Union[dict[int, str], "RowNames"]] = None
    meshes: tuple[MeshData, ...] = ()
    mesh_ids: Optional[np.ndarray] = None  # (N,) int32: index into meshes, -1 for its kind's built-in mesh or none

    def __len__(self) -> int:
        return len(self.kinds)

    def mesh_of(self, i: int) -> Optional[MeshData]:
        """Row i's mesh (its own, its kind's built-in one, or None), without making its Shape."""
        if self.mesh_ids is not None and self.mesh_ids[i] >= 0:
            return self.meshes[self.mesh_ids[i]]
        kind = _KEYWORD_OF_CODE[self.kinds[i]]
        return builtin_mesh(kind) if kind in BUILTIN_MESH_KINDS else None

    def _source(self, i: int, line: int, column: int) -> Optional[SourceLocation]:
        return None if self.lines is None else SourceLocation(self.file, line, column)

    def shape(self, i: int) -> Shape:
        """Shape i, made anew (as the Python reader makes it: its own matrix, the shared material object,
        its mesh: its own, or the built-in mesh of a polyhedron or the teapot)."""
        i = range(len(self))[i]  # (negative from the end; IndexError)
        kind = _KEYWORD_OF_CODE[self.kinds[i]]
        matrix = matrices_of_affines(self.affines[i:i + 1])[0]
        lines, columns = (0, 0) if self.lines is None else (int(self.lines[i]), int(self.columns[i]))
        return Shape(kind, matrix, self.materials[self.material_ids[i]], self._parameters(kind, self.parameters[i]),
                     self.mesh_of(i), None, (), self._source(i, lines, columns),
                     None if self.names is None else self.names.get(i))

    def shapes(self) -> list[Shape]:
        """Every row's Shape, in order (as shape() makes them; a chunk of rows' matrices at a time, with the
        collector paused: a million new objects would otherwise run it hundreds of times)."""
        used = set(np.unique(self.kinds).tolist())
        meshes = {kind: builtin_mesh(kind) for kind in BUILTIN_MESH_KINDS if _KIND_CODE[kind] in used}
        names = self.names or {}
        with_parameters = any(_ARITY[_KEYWORD_OF_CODE[code]] for code in used)
        out: list[Shape] = []
        with collector_paused():
            for start in range(0, len(self), _ROWS_AT_ONCE):
                rows = slice(start, start + _ROWS_AT_ONCE)
                matrices = matrices_of_affines(self.affines[rows])
                kinds = list(map(_KEYWORD_OF_CODE.__getitem__, self.kinds[rows].tolist()))
                values = self._parameter_tuples(rows) if with_parameters else repeat(())
                own = repeat(-1) if self.mesh_ids is None else self.mesh_ids[rows].tolist()
                places = repeat((0, 0)) if self.lines is None else zip(self.lines[rows].tolist(),
                                                                      self.columns[rows].tolist())
                for i, (kind, matrix, material, parameters, (line, column), mesh_id) in enumerate(zip(
                        kinds, matrices, map(self.materials.__getitem__, self.material_ids[rows].tolist()),
                        values, places, own), start):
                    mesh = self.meshes[mesh_id] if mesh_id >= 0 else meshes.get(kind)
                    out.append(Shape(kind, matrix, material, parameters, mesh, None, (),
                                     self._source(i, line, column), names.get(i)))
        return out

    @staticmethod
    def _parameters(kind: str, row: np.ndarray) -> tuple[float, ...]:
        return tuple(row[:_ARITY[kind]].tolist())

    def _parameter_tuples(self, rows: slice) -> list[tuple[float, ...]]:
        """Shape.parameters of these rows: () for the kinds that take none, the rest a kind's count at a time."""
        arity = _ARITY_OF_CODE[self.kinds[rows]]
        out: list[tuple[float, ...]] = [()] * len(arity)
        for count in np.unique(arity[arity > 0]).tolist():
            where = np.flatnonzero(arity == count)
            for j, values in zip(where.tolist(), self.parameters[rows][where, :count].tolist()):
                out[j] = tuple(values)
        return out


class RowNames:
    """The names of a ShapeTable's rows as a column: ``ids`` (N,) int32, each row's index into ``names``, -1
    for no name.  (The many rows of one Blender object's instances share its name: 4 bytes each, where a
    {row: name} entry takes about 100.)"""

    def __init__(self, ids, names: Sequence[str]):
        self.ids = np.asarray(ids, dtype=np.int32)
        self.ids.setflags(write=False)
        self.names = tuple(names)

    def get(self, row: int, default=None) -> Optional[str]:
        number = int(self.ids[row])
        return self.names[number] if number >= 0 else default

    def items(self):
        """(row, name) of every named row."""
        rows = np.flatnonzero(self.ids >= 0)
        return zip(rows.tolist(), map(self.names.__getitem__, self.ids[rows].tolist()))

    def __reduce__(self):
        return RowNames, (self.ids, self.names)


#: Rows made into Shapes at a time (their 4x4 matrices stacked: a few MB).
_ROWS_AT_ONCE = 1 << 15


def parameter_rows(parameters: Sequence[tuple[float, ...]]) -> np.ndarray:
    """(N, tracer.shapes.MAX_PARAMETERS) float64 rows of these shapes' parameters, 0 after each one's own."""
    rows = np.zeros((len(parameters), shapes.MAX_PARAMETERS))
    for i, values in enumerate(parameters):
        if values:  # (most kinds take none)
            rows[i, :len(values)] = values
    return rows


def matrices_of_affines(affines: np.ndarray) -> np.ndarray:
    """(N, 4, 4) matrices of (N, 12) affines (the bottom rows 0 0 0 1)."""
    out = np.zeros((len(affines), 4, 4))
    out[:, :3, :] = affines.reshape(-1, 3, 4)
    out[:, 3, 3] = 1.0
    return out


#: The code of each shape kind (the index of its keyword in tracer.shapes.REGISTRY).
_KIND_CODE = {keyword: code for code, keyword in enumerate(_KEYWORD_OF_CODE)}
#: Per kind code: whether a table's row of that kind may hold a mesh of its own (ShapeTable.mesh_ids).
_OWN_MESH = np.array([keyword in MESH_KINDS for keyword in _KEYWORD_OF_CODE])


def _read_only(array, dtype, shape: tuple, what: str) -> np.ndarray:
    """``array`` as a read-only C-contiguous array of this dtype and shape.  The table takes the memory over:
    the array and the array that owns its memory are made read-only; memory that no array owns (a writable
    buffer) is copied."""
    out = np.ascontiguousarray(array, dtype=dtype)
    if out.shape != shape:
        try:
            out = out.reshape(shape)
        except ValueError:
            raise ValueError(f"ShapeTable: {what} has shape {out.shape}, not {shape}") from None
    chain = [out]
    while isinstance(chain[-1].base, np.ndarray):
        chain.append(chain[-1].base)
    if chain[-1].base is not None and not isinstance(chain[-1].base, bytes) and chain[-1].flags.writeable:
        out = out.copy()
        chain = [out]
    for part in chain:
        part.setflags(write=False)
    return out


class ShapeTable(MutableSequence):
    """A scene's shapes kept as columns (one row per shape) until someone needs them as Shape objects: how a
    fast reader hands over a million shapes without making a million objects (a Shape with its matrix takes
    ~700 bytes; a row here takes ~120).

    ``kinds`` (N,) int16, each shape's kind as its index in tracer.shapes.REGISTRY; ``affines`` (N, 12)
    float64, the top three rows of each matrix, row after row (the bottom row is 0 0 0 1), or float32 where
    every matrix is made of float32 values (Blender's are: half the memory, widened exactly when read);
    ``material_ids`` (N,) int32, indices into ``materials`` (distinct Material objects, or a MaterialRows);
    ``parameters`` (N, tracer.shapes.MAX_PARAMETERS) float64, each row's Shape.parameters and then anything
    (a single column may be given as (N,)); ``lines``, ``columns`` (N,) int32, 1-based, and ``file``: each
    shape's SourceLocation (both None: no shape has one); ``names``: None, {row: Shape.name} or a RowNames.
    ``meshes`` (MeshData objects) and ``mesh_ids`` (N,) int32: the mesh of each row of a mesh kind, as an
    index into ``meshes`` (-1: its kind's built-in mesh, tracer.geometry.builtin_mesh, or none); without
    them, polyhedra and the teapot get their built-in mesh.  Every row has no groups and no mesh file.  The
    table takes the arrays over: nobody may change them afterwards (compile_scene knows a table by its
    identity).  They, and the arrays that own their memory, are made read-only; memory that no array owns
    (a writable buffer) is copied.

    It reads as the list of those Shapes.  len() makes nothing; the first access to an element (indexing,
    iteration, any change, ==) makes every Shape once, and from then on the table is a plain list of them
    (:attr:`columns` is then None).  :meth:`shape_at` makes one Shape without making the rest.  Pickled and
    copied as the arrays while nothing has been made (scenes travel to Dask workers)."""

    def __init__(self, kinds, affines, material_ids, materials, parameters, lines, columns,
                 file=None, names=None, meshes=(), mesh_ids=None):
        kinds = np.asarray(kinds)
        n = len(kinds)
        kinds = _read_only(kinds, np.int16, (n,), "kinds")
        material_ids = _read_only(material_ids, np.int32, (n,), "material_ids")
        materials = materials if isinstance(materials, MaterialRows) else tuple(materials)
        if n and not (0 <= kinds.min() and kinds.max() < len(_KEYWORD_OF_CODE)):
            raise ValueError("ShapeTable: a kind code is not in tracer.shapes.REGISTRY")
        if n and not (0 <= material_ids.min() and material_ids.max() < len(materials)):
            raise ValueError("ShapeTable: a material id is not an index into materials")
        meshes = tuple(meshes)
        if mesh_ids is not None:
            mesh_ids = _read_only(mesh_ids, np.int32, (n,), "mesh_ids")
            if n and not (-1 <= mesh_ids.min() and mesh_ids.max() < len(meshes)):
                raise ValueError("ShapeTable: a mesh id is not an index into meshes")
            if (mesh_ids[~_OWN_MESH[kinds]] >= 0).any():
                raise ValueError("ShapeTable: a row of a kind without a mesh of its own has a mesh id")
        if ((kinds == _KIND_CODE["mesh"]) & ((-1 if mesh_ids is None else mesh_ids) < 0)).any():
            raise ValueError("ShapeTable: a mesh row has no mesh")
        affines = np.asarray(affines)
        self._columns: Optional[ShapeColumns] = ShapeColumns(
            kinds, _read_only(affines, np.float32 if affines.dtype == np.float32 else np.float64, (n, 12), "affines"),
            material_ids, materials, _read_only(parameters, np.float64, (n, shapes.MAX_PARAMETERS), "parameters"),
            None if lines is None else _read_only(lines, np.int32, (n,), "lines"),
            None if lines is None else _read_only(columns, np.int32, (n,), "columns"),
            file, names if names is None or isinstance(names, RowNames) else dict(names), meshes, mesh_ids)
        self._shapes: Optional[list[SceneObject]] = None

    @classmethod
    def of_shapes(cls, shapes: Sequence[Shape]) -> "ShapeTable":
        """The table of these shapes' columns (shapes sharing a material object share its id).  Each must be
        a row a table can hold: no groups, no mesh file, its kind's built-in mesh or none, and all from one
        file; a ValueError says which is not."""
        n = len(shapes)
        files = {s.source.file for s in shapes if isinstance(s, Shape) and s.source is not None}
        for i, s in enumerate(shapes):
            if not isinstance(s, Shape) or s.groups or s.mesh_file is not None or s.source is None or (
                    s.mesh is not (builtin_mesh(s.kind) if s.kind in BUILTIN_MESH_KINDS else None)) or (
                    np.asarray(s.matrix)[3].tolist() != [0.0, 0.0, 0.0, 1.0]):
                raise ValueError(f"ShapeTable.of_shapes: object {i} cannot be a row of a table")
        if len(files) > 1:
            raise ValueError("ShapeTable.of_shapes: the shapes come from more than one file")
        material_index: dict[int, int] = {}
        materials = []
        for s in shapes:
            if id(s.material) not in material_index:
                material_index[id(s.material)] = len(materials)
                materials.append(s.material)
        return cls(np.array([_KIND_CODE[s.kind] for s in shapes], dtype=np.int16).reshape(n),
                   np.array([np.asarray(s.matrix, dtype=np.float64)[:3].reshape(12) for s in shapes]).reshape(n, 12),
                   np.array([material_index[id(s.material)] for s in shapes], dtype=np.int32).reshape(n), materials,
                   parameter_rows([s.parameters for s in shapes]),
                   np.array([s.source.line for s in shapes], dtype=np.int32).reshape(n),
                   np.array([s.source.column for s in shapes], dtype=np.int32).reshape(n),
                   files.pop() if files else None,
                   {i: s.name for i, s in enumerate(shapes) if s.name is not None} or None)

    @classmethod
    def _of_list(cls, objects: list) -> "ShapeTable":
        """A table already made into this list (how a made table is unpickled)."""
        self = cls.__new__(cls)
        self._columns, self._shapes = None, objects
        return self

    @property
    def columns(self) -> Optional[ShapeColumns]:
        """The arrays, while no Shape has been made of them; None after."""
        return self._columns

    def shape_at(self, i: int) -> Shape:
        """Shape i (negative from the end), without making the others: while the table is columns, a new Shape
        at each call, whose changes stay its own (once made, the list's element)."""
        if self._shapes is not None:
            return self._shapes[i]
        return self._columns.shape(i)

    def _made(self) -> list:
        """The list of Shapes, made on first use."""
        if self._shapes is None:
            self._shapes = self._columns.shapes()
            self._columns = None
        return self._shapes

    def __len__(self) -> int:
        return len(self._shapes) if self._shapes is not None else len(self._columns)

    def __getitem__(self, index):
        return self._made()[index]

    def __setitem__(self, index, value) -> None:
        self._made()[index] = value

    def __delitem__(self, index) -> None:
        del self._made()[index]

    def insert(self, index, value) -> None:
        self._made().insert(index, value)

    def __iter__(self):
        return iter(self._made())

    def __reversed__(self):
        return reversed(self._made())

    def __contains__(self, value) -> bool:
        return value in self._made()

    def index(self, value, *args) -> int:
        return self._made().index(value, *args)

    def count(self, value) -> int:
        return self._made().count(value)

    def append(self, value) -> None:
        self._made().append(value)

    def extend(self, values) -> None:
        self._made().extend(values)

    def clear(self) -> None:
        self._made().clear()

    def copy(self) -> list:
        return self._made().copy()

    def sort(self, *args, **kwargs) -> None:
        self._made().sort(*args, **kwargs)

    def __iadd__(self, values):
        self._made().extend(values)
        return self

    def __add__(self, other):
        return self._made() + list(other) if isinstance(other, (list, ShapeTable)) else NotImplemented

    def __radd__(self, other):
        return other + self._made() if isinstance(other, list) else NotImplemented

    def __eq__(self, other) -> bool:
        if isinstance(other, ShapeTable):
            return self._made() == other._made()
        if isinstance(other, list):
            return self._made() == other
        return NotImplemented

    __hash__ = None

    def __repr__(self) -> str:
        if self._shapes is None:
            return f"<ShapeTable of {len(self)} shapes>"
        return repr(self._shapes)

    def __copy__(self) -> "ShapeTable":
        # (a list of its own once made, as list.copy gives; the same read-only arrays before)
        return ShapeTable._of_list(list(self._shapes)) if self._shapes is not None else ShapeTable(
            *self.__reduce__()[1])

    def __reduce__(self):
        c = self._columns
        if c is None:
            return ShapeTable._of_list, (self._shapes,)
        return ShapeTable, (c.kinds, c.affines, c.material_ids, c.materials, c.parameters, c.lines,
                            c.columns, c.file, c.names, c.meshes, c.mesh_ids)


class TableRows:
    """A ShapeTable's rows gathered in order: a Shape at a time (:meth:`add_shape`), or many rows at once that
    share a few *parts* (kind, mesh, material, parameters, name), each under its own matrix
    (:meth:`add_block`: the instances of a Blender object).  :meth:`table` makes the table; nothing per row
    is a Python object.  For shapes made from a program's data (a Blender scene): rows have no source."""

    def __init__(self) -> None:
        self._parts: dict[tuple, int] = {}  # (kind, id(mesh), id(material), parameters, name) -> part number
        self._part_values: list[tuple] = []  # (kind code, mesh, material, parameters, name) of each part
        self._blocks: list[tuple[np.ndarray, np.ndarray]] = []  # (matrices (k, 4, 4), part numbers (k,))
        self._single_matrices: list[np.ndarray] = []  # add_shape's, not yet a block
        self._single_parts: list[int] = []

    @staticmethod
    def can_hold(obj) -> bool:
        """Whether an object can be a row: a Shape without groups, mesh file or source, whose matrix is an
        affine 4x4 and whose mesh is its own only if its kind is a mesh kind."""
        if not isinstance(obj, Shape) or obj.groups or obj.mesh_file is not None or obj.source is not None:
            return False
        matrix = np.asarray(obj.matrix)
        if matrix.shape != (4, 4) or matrix[3].tolist() != [0.0, 0.0, 0.0, 1.0]:
            return False
        return obj.kind in MESH_KINDS or obj.mesh is (builtin_mesh(obj.kind) if obj.kind in BUILTIN_MESH_KINDS
                                                       else None)

    def part(self, kind: str, mesh: Optional[MeshData], material: Material, parameters: tuple = (),
             name: Optional[str] = None) -> int:
        """The number of a part (made when new): what add_block's rows point at."""
        parameters = _parameters_of(kind, parameters)
        if kind in BUILTIN_MESH_KINDS and mesh is builtin_mesh(kind):
            mesh = None  # (the row's kind gives it: no mesh of its own)
        key = (kind, id(mesh), id(material), parameters, name)
        number = self._parts.get(key)
        if number is None:
            number = self._parts[key] = len(self._part_values)
            self._part_values.append((_KIND_CODE[kind], mesh, material, parameters, name))
        return number

    def add_shape(self, shape: Shape) -> None:
        """One row: a Shape that can_hold."""
        self._single_matrices.append(shape.matrix)
        self._single_parts.append(self.part(shape.kind, shape.mesh, shape.material, shape.parameters, shape.name))

    def add_block(self, matrices: np.ndarray, parts: np.ndarray) -> None:
        """Rows under ``matrices`` ((k, 4, 4) affine, the bottom rows 0 0 0 1: float64, or float32 where
        that is what they are), row i of part ``parts[i]`` (numbers from :meth:`part`)."""
        self._flush()
        self._blocks.append((matrices, np.asarray(parts, dtype=np.int32)))

    def _flush(self) -> None:
        if self._single_parts:
            self._blocks.append((np.stack(self._single_matrices), np.array(self._single_parts, dtype=np.int32)))
            self._single_matrices, self._single_parts = [], []

    def table(self) -> ShapeTable:
        """The table of every row so far.  Its matrices are kept as float32 where every one of them is made
        of float32 values (as Blender's are), else as float64."""
        self._flush()
        n = sum(len(parts) for _, parts in self._blocks)
        single = all(matrices.dtype == np.float32 for matrices, _ in self._blocks)
        affines = np.empty((n, 12), dtype=np.float32 if single else np.float64)
        part_of_row = np.empty(n, dtype=np.int32)
        at = 0
        for matrices, parts in self._blocks:
            affines[at:at + len(parts)].reshape(-1, 3, 4)[...] = matrices[:, :3, :]
            part_of_row[at:at + len(parts)] = parts
            at += len(parts)
        self._blocks = []
        if not single:  # (float32 blocks are float32 already; float64 ones may hold float32 values)
            narrow = affines.astype(np.float32)
            if np.array_equal(narrow, affines):
                affines = narrow
        values = self._part_values
        meshes, mesh_number = [], {}
        for kind, mesh, *_ in values:
            if mesh is not None and id(mesh) not in mesh_number:
                mesh_number[id(mesh)] = len(meshes)
                meshes.append(mesh)
        materials = list({id(v[2]): v[2] for v in values}.values())
        material_number = {id(m): i for i, m in enumerate(materials)}
        names = list(dict.fromkeys(v[4] for v in values if v[4] is not None))
        name_number = {name: i for i, name in enumerate(names)}

        def column(values, dtype):
            return np.array(values, dtype=dtype)[part_of_row]

        return ShapeTable(
            column([v[0] for v in values], np.int16), affines,
            column([material_number[id(v[2])] for v in values], np.int32), materials,
            parameter_rows([v[3] for v in values])[part_of_row], None, None, None,
            RowNames(column([name_number.get(v[4], -1) for v in values], np.int32), names) if names else None,
            meshes, column([mesh_number[id(v[1])] if v[1] is not None else -1 for v in values], np.int32))


@dataclass
class CSG:
    """A boolean of two objects: ``op`` is ``union``, ``intersection`` or ``difference``."""

    op: str
    left: "SceneObject"
    right: "SceneObject"
    groups: tuple[str, ...] = ()
    source: Optional[SourceLocation] = None

    OPS = ("union", "intersection", "difference")

    def __post_init__(self) -> None:
        if self.op not in self.OPS:
            raise SceneError(f"unknown boolean {self.op!r}")

    def leaves(self) -> list[Shape]:
        return [s for child in (self.left, self.right) for s in iter_shapes(child)]


SceneObject = Union[Shape, CSG]


def iter_shapes(obj: SceneObject):
    """Every primitive shape in an object, left to right.  Without recursion: booleans read from a file
    may nest deeper than Python's stack."""
    todo = [obj]
    while todo:
        node = todo.pop()
        if isinstance(node, CSG):
            todo += (node.right, node.left)
        else:
            yield node


#: Light.kind's values: SDL's point light (no falloff, as in the book) and the physical lights (see
#: docs/tracer.md, "Lights").
LIGHT_KINDS = ("point", "sphere", "spot", "sun", "area")
#: Light.shape's values, for area lights.
AREA_SHAPES = ("rectangle", "ellipse")
#: Light's switches, in the order of their bits in the tables (tracer.lights.LightTable.off): what Cycles lets a
#: Blender user switch off per light (Cast Shadow, Ray Visibility's Diffuse, Glossy and Transmission).
LIGHT_SWITCHES = ("cast_shadow", "visible_diffuse", "visible_glossy", "visible_transmission")


@dataclass(frozen=True)
class Light:
    """A light.  ``kind`` ``"point"`` is SDL's (no attenuation with distance, as in the book); the others are
    physical lights for Blender scenes, which fall off with distance and may cast soft shadows.  Units and
    meaning of every field: docs/tracer.md, "Lights".  Angles are in degrees, as everywhere in SDL."""

    position: Vec3  # point, sphere, spot: where it is; area: its centre; sun: unused
    color: Color
    kind: str = "point"
    #: Kept through SDL (a ``! name:`` comment before the statement), USD and Blender.
    name: Optional[str] = None
    #: spot, area: the way it shines (an area light emits on this side only); sun: the way its light travels.
    direction: Vec3 = (0.0, 0.0, -1.0)
    #: sphere, spot: the radius of the emitting sphere (0: a point, hard shadows).
    radius: float = 0.0
    #: sun: its angular diameter in degrees (0: hard shadows).
    angle: float = 0.0
    #: spot: the full angle of its cone in degrees (Blender's spot_size), and the share of it that is a
    #: smooth edge, 0..1 (Blender's spot_blend).
    spot_size: float = 45.0
    spot_blend: float = 0.0
    #: area: "rectangle" (a square is one) or "ellipse" (a disk is one), of side lengths (diameters) ``size``,
    #: the first along ``axis`` (made perpendicular to ``direction``), the second along direction x axis.
    shape: str = "rectangle"
    size: tuple[float, float] = (1.0, 1.0)
    axis: Vec3 = (1.0, 0.0, 0.0)
    #: Shadow rays per shading point, stratified over the light (soft shadows): for a sphere or spot of some
    #: radius, a sun of some angle, and every area light.
    samples: int = 1
    #: The switches of Blender scenes (docs/tracer.md, "Lights"; neither SDL nor USD carries them), all on by
    #: default.  Off: ``cast_shadow``, no shadow rays (it lights a point as if nothing were in the way);
    #: ``visible_diffuse``, no Lambert term; ``visible_glossy``, no highlight (Phong/Blinn or Cook-Torrance),
    #: and the light not seen by reflected rays; ``visible_transmission``, not seen by refracted rays (a light
    #: with an extent, seen_by_rays, is seen by both: docs/tracer.md, "Seen lights").
    cast_shadow: bool = True
    visible_diffuse: bool = True
    visible_glossy: bool = True
    visible_transmission: bool = True

    def __post_init__(self) -> None:
        for switch in LIGHT_SWITCHES:
            if not isinstance(getattr(self, switch), bool):
                raise SceneError(f"light {switch} must be True or False, not {getattr(self, switch)!r}")
        if self.kind not in LIGHT_KINDS:
            raise SceneError(f"unknown light kind {self.kind!r} (expected one of {', '.join(LIGHT_KINDS)})")
        if self.shape not in AREA_SHAPES:
            raise SceneError(f"unknown area light shape {self.shape!r} (expected one of {', '.join(AREA_SHAPES)})")
        if not (isinstance(self.samples, int) and 1 <= self.samples <= MAX_LIGHT_SAMPLES):
            raise SceneError(f"light samples must be a whole number 1..{MAX_LIGHT_SAMPLES}, not {self.samples!r}")

    @property
    def soft(self) -> bool:
        """Whether its shadows are soft (it has an extent: shadow rays go to several points of it)."""
        return (self.kind == "area" or (self.kind in ("sphere", "spot") and self.radius > 0.0)
                or (self.kind == "sun" and self.angle > 0.0))

    @property
    def seen_by_rays(self) -> bool:
        """Whether reflected and refracted rays may see it (the effect ``seen-lights``): a light with an extent
        (an area light, a sphere or spot of some radius, a sun of some angle); a point is never seen."""
        return self.soft

    @property
    def lights_surfaces(self) -> bool:
        """Whether it adds anything to the shading of a surface (diffuse or highlight)."""
        return self.visible_diffuse or self.visible_glossy

    @property
    def switched(self) -> bool:
        """Whether any of its switches is off (the effect ``light-switches``)."""
        return not all(getattr(self, switch) for switch in LIGHT_SWITCHES)


#: The most shadow rays per shading point one light may ask for.
MAX_LIGHT_SAMPLES = 1024


@dataclass(frozen=True)
class Camera:
    """The lecture's camera: eye, look-at point, up vector and vertical view angle in degrees."""

    eye: Vec3
    look: Vec3
    up: Vec3 = (0.0, 1.0, 0.0)
    view_angle: float = 45.0


#: The deepest reflection/refraction recursion traced.  A deeper maxRecursionDepth is read as this one, with
#: a warning: each level adds at most 1/2^level-ish light in any physical scene, while an unbounded depth lets
#: one file run a thread out of stack (the C core recurses about 1 KB per level) or for ever.
MAX_RECURSION_DEPTH = 64
#: How many nested transparent objects a ray remembers being inside (both tracers: a fixed-size stack per ray).
MEDIA_DEPTH = 8


def traced_depth(depth: int) -> int:
    """The recursion depth the tracers follow for a setting of ``depth``: 0 .. MAX_RECURSION_DEPTH."""
    return max(0, min(int(depth), MAX_RECURSION_DEPTH))


@dataclass
class Settings:
    """Scene-wide settings; SDL's defaults."""

    global_ambient: Color = (0.1, 0.1, 0.1)
    background: Color = (0.0, 0.0, 0.6)
    min_reflectivity: float = 0.5
    min_transparency: float = 0.5
    max_recursion_depth: int = 3
    #: Shadow rays of smooth-shaded meshes start from the smooth surface their normals describe, not the
    #: flat triangle (no stair-stepped shadow terminator on low-poly meshes; an extension, off for SDL files).
    smooth_terminator: bool = False


@dataclass
class Scene:
    objects: list[SceneObject] = field(default_factory=list)
    lights: list[Light] = field(default_factory=list)
    camera: Optional[Camera] = None  # None: the renderer frames the scene (see tracer.camera)
    settings: Settings = field(default_factory=Settings)
    #: makePixmap: image number -> file path (resolved against the scene file's folder).
    pixmaps: dict[int, str] = field(default_factory=dict)
    #: Where each makePixmap was read (image number -> place), for messages about its picture; not part of
    #: what the scene is, so not compared.
    pixmap_sources: dict[int, SourceLocation] = field(default_factory=dict, compare=False)
    #: The file this scene was read from, if any.
    source: Optional[Path] = None
    #: Problems found while reading in lenient mode, one message each ("file:line:col: what").
    warnings: list[str] = field(default_factory=list)

    def shapes(self) -> list[Shape]:
        return [s for obj in self.objects for s in iter_shapes(obj)]
