"""The contract between the NumPy reference and the C core, written once.

This table is the single source of what both sides must agree on:

* the codes of the shape kinds, CSG operations, effect bits and ray kinds;
* the constants the C core needs from the NumPy modules (each names the module attribute that holds its
  value, so the NumPy code keeps reading its own constant and the header is generated from it);
* the layout of the structs that cross the boundary: ``SceneDesc``, the struct of pointers into flat arrays
  that flatten.py fills, and ``SdlResult``, what the C SDL reader hands back (:data:`STRUCTS`);
* the prototype of every function the library exports (:data:`FUNCTIONS`).

``python -m tracer.native.contract`` writes ``contract.h`` (checked in; tests/test_contract.py fails when it
is stale): the codes, constants, structs and prototypes, so the C compiler holds every definition to this
table.  The ctypes side is made from the same tables: the struct mirrors (:data:`CTYPES`) and every
function's argument and result types (:func:`declare`), with no declaration written by hand.  The C core
exports every field's offset and size (``rt_struct_layout``), which the loader compares with ctypes' before
using the library.  How to add a field or a function: docs/contributing.md.
"""
from __future__ import annotations

import ctypes
import hashlib
import importlib
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import Optional

import numpy as np

from .. import model as _model
from .. import savings as _savings
from .. import shapes as _shapes
from ..sdl import statements as _statements

HEADER = Path(__file__).resolve().parent / "contract.h"

# ------------------------------------------------------------------------------------------------ codes

#: C shape kinds in code order, each with the SDL kinds it traces (from the shape registry).
SHAPE_KINDS: tuple[tuple[str, tuple[str, ...]], ...] = _shapes.c_kinds()
CSG_OPS = ("union", "intersection", "difference")
#: Effect names (CompiledScene.effects) and their bits in SceneDesc.effects, in bit order.
EFFECTS = ("lighting", "shadows", "reflection", "refraction", "cook-torrance", "textures",
           # the extensions for Blender scenes (docs/tracer.md): traced by one general shade function
           "physical-lights", "soft-shadows", "fresnel", "smooth-terminator", "mesh-uv", "seen-lights",
           "light-switches")
#: Light kinds in the order of their codes (tracer.lights.LIGHT_CODES; SceneDesc.light_kind).
LIGHT_KINDS = _model.LIGHT_KINDS
#: Light's switches in the order of their bits in SceneDesc.light_off (LIGHT_OFF_*: set where switched off).
LIGHT_SWITCHES = _model.LIGHT_SWITCHES
#: Material.fresnel modes in the order of their codes (SceneDesc.mat_fresnel).
FRESNEL_MODES = _model.FRESNEL_MODES
#: Ray kinds in the order of the C core's counters (tracer.trace.RAY_KINDS is the NumPy side).
RAY_KINDS = ("camera", "shadow", "reflection", "refraction")
#: After the ray kinds, the counters of rays not cast, per reason (SKIP_*); and the bits of
#: RaySavings.flags() (SAVE_*), which switch the skips other than the cutoff.
SKIP_REASONS = _savings.SKIP_REASONS
SAVINGS_SWITCHES = _savings.SWITCHES
#: The bits of rt_edit's flags (EDIT_*): the meshes may have changed; build the object hierarchy anew; objects
#: were removed (those listed) and added (at the end).
EDIT_FLAGS = ("meshes", "rebuild", "objects")


def c_name(name: str) -> str:
    """'cook-torrance' -> 'COOK_TORRANCE'."""
    return name.upper().replace("-", "_")


KIND = {c_name(kind): code for code, (kind, _) in enumerate(SHAPE_KINDS)}
#: SDL kind -> C kind code.
KIND_CODES = {sdl: code for code, (_, sdl_kinds) in enumerate(SHAPE_KINDS) for sdl in sdl_kinds}
OP_CODES = {op: code for code, op in enumerate(CSG_OPS)}
EFFECT_BITS = {name: 1 << bit for bit, name in enumerate(EFFECTS)}
EDIT_BITS = {name: 1 << bit for bit, name in enumerate(EDIT_FLAGS)}

# ------------------------------------------------------------------------------------------------ constants


@dataclass(frozen=True)
class Constant:
    """A number both sides use; its value is ``source`` ("module:attribute"), read when the header is made."""

    name: str
    source: str
    kind: str  # "double" or "int"
    doc: str

    def value(self):
        module, attribute = self.source.split(":")
        # "tracer.x" names a module of this tracer package, wherever it lives (the Blender add-on vendors
        # it as sdl_raytracer.tracer, where an absolute "tracer" is not importable)
        package = __package__.rsplit(".", 1)[0]
        value = getattr(importlib.import_module(package + module[len("tracer"):]), attribute)
        return float(value) if self.kind == "double" else int(value)


CONSTANTS = (
    Constant("TORUS_RING", "tracer.intersect.torus:RING_RADIUS", "double", "the generic torus' ring radius"),
    Constant("TORUS_TUBE", "tracer.model:TORUS_TUBE_RADIUS", "double", "the generic torus' tube radius"),
    Constant("MEDIA_DEPTH", "tracer.model:MEDIA_DEPTH", "int", "nested transparent media a ray keeps track of"),
    Constant("MAX_OCTAVES", "tracer.textures.noise:MAX_OCTAVES", "int",
             "most octaves of turbulence summed (marble); a larger count is read as this one"),
    Constant("MAX_RECURSION_DEPTH", "tracer.model:MAX_RECURSION_DEPTH", "int",
             "deepest reflection/refraction recursion traced, whatever max_depth says (bounds the stack)"),
    Constant("RAY_BUDGET", "tracer.savings:RAY_BUDGET", "int",
             "reflected and transmitted rays one camera ray's tree may trace, unless rt_trace is given another"),
    Constant("PRIM_PARAMS", "tracer.shapes:MAX_PARAMETERS", "int",
             "parameter slots per primitive in prim_param (the most any kind's intersection takes)"),
    Constant("TEX_PARAMS", "tracer.textures.solid:MAX_PARAMETERS", "int",
             "parameter slots per material in mat_tex_param (the longest defaults: marble)"),
    Constant("LIGHT_GOLDEN", "tracer.lights:GOLDEN", "double", "the shadow-sample lattice's step along v"),
    Constant("LIGHT_TWO_PI", "tracer.lights:TWO_PI", "double", "2 pi, as tracer.lights writes it"),
)


def constant_values() -> dict[str, float | int]:
    return {c.name: c.value() for c in CONSTANTS}


# ------------------------------------------------------------------------------------------------ SceneDesc

_P = ctypes.POINTER
#: Element types: C spelling, ctypes type, NumPy dtype.
SCALARS = {
    "i8": ("int8_t", ctypes.c_int8, np.int8),
    "u8": ("uint8_t", ctypes.c_uint8, np.uint8),
    "i16": ("int16_t", ctypes.c_int16, np.int16),
    "i32": ("int32_t", ctypes.c_int32, np.int32),
    "i64": ("int64_t", ctypes.c_int64, np.int64),
    "u64": ("uint64_t", ctypes.c_uint64, np.uint64),
    "f32": ("float", ctypes.c_float, np.float32),
    "f64": ("double", ctypes.c_double, np.float64),
}


@dataclass(frozen=True)
class Field:
    """One SceneDesc member.

    ``type`` is a scalar code (``"i64"``), a pointer to an array of them (``"*f64"``: flatten fills it from a
    NumPy array of that dtype) or ``"**f64"`` (an array of addresses of float64 arrays).  ``length`` makes a
    scalar an inline array (``double background[3]``).  ``section`` starts a commented group in the header."""

    name: str
    type: str
    doc: str = ""
    length: int = 0
    section: str = ""

    @property
    def is_pointer(self) -> bool:
        return self.type.startswith("*")

    @property
    def scalar(self) -> str:
        return self.type.lstrip("*")

    @property
    def ctype(self):
        base = SCALARS[self.scalar][1]
        if self.type.startswith("**"):
            return _P(_P(base))
        if self.is_pointer:
            return _P(base)
        return base * self.length if self.length else base

    @property
    def dtype(self):
        """The NumPy dtype of the array a pointer field points into (None for values)."""
        if self.type.startswith("**"):
            return np.uintp
        return SCALARS[self.scalar][2] if self.is_pointer else None

    def c_declaration(self, const: bool = True) -> str:
        """The member's declaration; ``const``: it points into memory the C core only reads."""
        base = SCALARS[self.scalar][0]
        qualifier = "const " if const else ""
        if self.type.startswith("**"):
            return f"{qualifier}{base} *const *{self.name};"
        if self.is_pointer:
            return f"{qualifier}{base} *{self.name};"
        return f"{base} {self.name}[{self.length}];" if self.length else f"{base} {self.name};"


F = Field
SCENE_DESC: tuple[Field, ...] = (
    F("n_prims", "i64", section="primitives"),
    F("prim_kind", "*i32", "K_* per primitive"),
    F("prim_inverse", "*f64", "16 per primitive"),
    F("prim_sphere", "*f64", "4: bounding-sphere centre, radius (inf: unbounded)"),
    F("prim_param", "*f64", "PRIM_PARAMS: the values its kind's intersection takes (ShapeKind.traced), 0 after"),
    F("prim_aux", "*i32", "2: polyhedron (first plane, count) or mesh (mesh index, 0)"),
    F("prim_material", "*i32"),
    F("prim_rounding", "*f64", "4: inverse error, generic size, |inverse| and |translation| (numerics; "
      "PrimitiveTable.rounding_terms): rounding / size is (hit_gamma + inverse error) / size"),
    F("instance_rows", "i64", "how many rows are instance rows (tracer.instances: numbers computed from their "
      "affine); 0: the four fields below are not read, and a primitive's row in the three above is its index"),
    F("prim_slot", "*i32", "per primitive: its row in prim_inverse, prim_sphere and prim_rounding, or -1 for an "
      "instance row"),
    F("instance_affine", "*f32", "12 per primitive: its matrix's top three rows (read for instance rows)"),
    F("instance_box", "*f32", "6 per primitive: its padded world box as object_box's (read for instance rows)"),
    F("planes", "*f64", "4 per plane: normal, offset", section="convex polyhedra: face planes n . p <= offset"),
    F("n_meshes", "i64", section="triangle meshes (TriangleMesh.arrays(): per mesh, the address of each of "
      "its own arrays)"),
    F("mesh_info", "*i64", "4 per mesh: node, triangle, vertex and normal counts"),
    F("mesh_extent", "*f64"),
    F("mesh_generic_size", "*f64", "per mesh: its largest |vertex coordinate| (MeshBound.generic_size): an "
      "instance row's generic size"),
    F("mesh_constants", "f64", "tracer.intersect.mesh: ROUNDING_FACTOR, BARYCENTRIC_EPSILON_MAX, "
      "PARALLEL_EPSILON, DEDUPE_RELATIVE, DEDUPE_RELATIVE_ADJACENT", length=5),
    F("mesh_nodes", "**u8", "per mesh: its BvhNode records (bvh_build.h; tracer.intersect.mesh.NODE), 32 bytes each"),
    F("mesh_order", "**i32", "per mesh: leaf slot -> triangle"),
    F("mesh_tri_vertex", "**i32", "per mesh: 3 vertex indices per triangle"),
    F("mesh_tri_normal", "**i32", "per mesh: 3 normal indices per triangle (< 0: none), or NULL"),
    F("mesh_vertices", "**f64", "per mesh: 3 per vertex"),
    F("mesh_normals", "**f64", "per mesh: 3 per normal (made unit where used)"),
    F("mesh_tri_uv", "**f64", "per mesh: 6 per triangle, its corners' (u, v) (MeshData.corner_uvs), or NULL"),
    F("n_csg", "i64", section="CSG"),
    F("csg_op", "*i32", "OP_* per node"),
    F("csg_left", "*i64"),
    F("csg_right", "*i64"),
    F("n_objects", "i64", section="top-level objects"),
    F("object_ref", "*i64"),
    F("object_box", "*f32", "6: lo, hi (padded, single precision rounded outward as the hierarchy's own "
      "boxes are); ignored when not bounded"),
    F("object_bounded", "*u8"),
    F("n_materials", "i64", section="materials"),
    F("mat_ambient", "*f64", "3 each"),
    F("mat_diffuse", "*f64"),
    F("mat_specular", "*f64"),
    F("mat_emissive", "*f64"),
    F("mat_exponent", "*f64", "1 each"),
    F("mat_reflectivity", "*f64"),
    F("mat_transparency", "*f64"),
    F("mat_speed", "*f64"),
    F("mat_specular_fraction", "*f64"),
    F("mat_roughness", "*f64"),
    F("mat_fresnel", "*i32", "FRESNEL_* each"),
    F("mat_fresnel_tint", "*f64", "3 each: a metal's reflectance at normal incidence"),
    F("n_lights", "i64", section="lights (tracer.lights.LightTable)"),
    F("light_pos", "*f64", "3 each"),
    F("light_color", "*f64"),
    F("light_kind", "*i32", "LIGHT_* each"),
    F("light_samples", "*i32", "shadow rays per shaded point"),
    F("light_frame", "*f64", "9 each: unit direction, an area light's half sides U and V"),
    F("light_param", "*f64", "4 each: LightTable.param"),
    F("light_off", "*i32", "LIGHT_OFF_* bits each: its switches that are off (LightTable.off; read only where "
      "the effect light-switches is live)"),
    F("background", "f64", length=3, section="settings"),
    F("global_ambient", "f64", length=3),
    F("min_reflectivity", "f64"),
    F("min_transparency", "f64"),
    F("max_depth", "i64"),
    F("effects", "i64", "FX_* bits"),
    F("mat_texture", "*i32", "per material: 0 none, -1/-2/-3 solid, i > 0 the image makePixmap i",
      section="textures (tracer.textures; see texture.h)"),
    F("mat_tex_param", "*f64", "TEX_PARAMS per material: the texture's parameters, defaults filled in"),
    F("mat_tex_image", "*i64", "per material: index into image_data, -1 for none"),
    F("n_images", "i64"),
    F("image_info", "*i64", "2 per image: width, height"),
    F("image_data", "**u8", "per image: height x width x 3 bytes (texel value = byte / 255), row 0 at the bottom"),
    F("noise_perm", "*i64", "512: tracer.textures.noise.PERM"),
    F("noise_gradients", "*f64", "12 x 3: tracer.textures.noise.GRADIENTS"),
    F("tol_hit_ulps", "f64", "CompiledScene.tolerances (tracer.numerics.Tolerances), field for field",
      section="tolerances: the compiled scene's, not constants (a measurement varies them)"),
    F("hit_gamma", "f64", "numerics.gamma(tol_hit_ulps): every primitive's rounding before its inverse's"),
    F("tol_offset_ulps", "f64"),
    F("tol_torus_residual_ulps", "f64"),
    F("tol_torus_newton_steps", "i64"),
    F("tol_torus_pair_shortcut", "f64"),
    F("tol_square_edge", "f64"),
)
del F


def field(name: str) -> Field:
    for f in SCENE_DESC:
        if f.name == name:
            return f
    raise KeyError(name)


F = Field
#: What the C SDL reader (sdl_read.h) hands back: its columns (shapes, materials, lights, cameras, names),
#: the settings the text set, and its working state.
SDL_RESULT: tuple[Field, ...] = (
    F("status", "i64", "SDL_READ or a decline reason"),
    F("decline_offset", "i64", "the byte where it declined (the caller turns it into a character offset)"),
    F("shapes", "i64"), F("materials", "i64"), F("lights", "i64"), F("cameras", "i64"), F("names", "i64"),
    F("kinds", "*i16", "shapes"),
    F("affines", "*f64", "shapes x 12"),
    F("material_ids", "*i32", "shapes"),
    F("parameters", "*f64", "shapes x PRIM_PARAMS: the numbers after each shape's keyword, 0 after them"),
    F("lines", "*i32"), F("columns", "*i32"),
    F("material_rows", "*f64", "materials x SDL_MATERIAL_WIDTH"),
    F("light_rows", "*f64", "lights x 6"),
    F("camera_rows", "*f64", "cameras x 10"),
    F("name_rows", "*i64", "names x 3: shape row, start and length of the name in the text"),
    F("settings_set", "i64", "SDL_SET_* bits"),
    F("global_ambient", "f64", length=3), F("background", "f64", length=3),
    F("min_reflectivity", "f64"), F("min_transparency", "f64"), F("max_recursion_depth", "i64"),
    F("shape_capacity", "i64", section="working state, not read by the caller"),
    F("material_capacity", "i64"), F("light_capacity", "i64"), F("camera_capacity", "i64"),
    F("name_capacity", "i64"),
    F("material_table", "*u64", "open addressing (see sdl_table_entry)"),
    F("table_size", "i64"),
    F("stack", "*f64", "transform stack, depth x 12"),
    F("depth", "i64"), F("stack_capacity", "i64"),
)
del F


@dataclass(frozen=True)
class Struct:
    """A struct that crosses the boundary: its C name, fields and whether its pointers are read-only to C."""

    name: str
    fields: tuple[Field, ...]
    const: bool
    doc: str

    @property
    def macro(self) -> str:
        """The name of its fields' X-macro: RT_SCENE_DESC_FIELDS."""
        return "RT_" + "".join(f"_{c}" if c.isupper() else c.upper() for c in self.name).lstrip("_") + "_FIELDS"


STRUCTS: tuple[Struct, ...] = (
    Struct("SceneDesc", SCENE_DESC, True, "The scene: pointers into the flat arrays flatten.py fills."),
    Struct("SdlResult", SDL_RESULT, False, "What one read of the C SDL reader gives (tracer/sdl/fastread.py)."),
)


def ctypes_fields(fields: tuple[Field, ...] = SCENE_DESC) -> list[tuple[str, object]]:
    """``_fields_`` of the ctypes mirror of a struct (SceneDesc's by default)."""
    return [(f.name, f.ctype) for f in fields]


#: The ctypes mirror of each struct, by name, made from its table.
CTYPES: dict[str, type] = {s.name: type(s.name, (ctypes.Structure,), {"_fields_": ctypes_fields(s.fields)})
                           for s in STRUCTS}
SceneDesc = CTYPES["SceneDesc"]
SdlResult = CTYPES["SdlResult"]

# ------------------------------------------------------------------------------------------------ functions

#: Argument and result types of the exported functions: code -> (C spelling, ctypes type).  "<f64" is an
#: array the C core reads (const double *), ">f64" one it writes (double *).
_VALUES = {"void": ("void", None), "int": ("int", ctypes.c_int), "f64": ("double", ctypes.c_double),
           "i64": ("int64_t", ctypes.c_int64),
           "handle": ("void *", ctypes.c_void_p),  # a scene the core made (rt_create)
           "chandle": ("const void *", ctypes.c_void_p),
           "buffer": ("void *", ctypes.c_void_p),  # memory of any type (None for none)
           ">buffer": ("void **", _P(ctypes.c_void_p)),  # where the core puts a buffer it allocated
           "str": ("const char *", ctypes.c_char_p),  # bytes (NUL-ended where no length goes with them)
           ">str": ("char *", ctypes.c_char_p),  # room for a message (ctypes.create_string_buffer)
           "text": ("const char *", ctypes.c_void_p),  # bytes, or the address of bytes (an int)
           "desc": ("const SceneDesc *", _P(SceneDesc)),
           "result": ("SdlResult *", _P(SdlResult))}


def _type(code: str) -> tuple[str, object]:
    """(C spelling, ctypes type) of an argument or result type code."""
    if code in _VALUES:
        return _VALUES[code]
    base, ctype, _ = SCALARS[code[1:]]
    return (f"const {base} *" if code[0] == "<" else f"{base} *"), _P(ctype)


@dataclass(frozen=True)
class Function:
    """A function the library exports: ``result`` and each parameter ("code name") in _VALUES' codes."""

    name: str
    result: str
    parameters: tuple[str, ...]
    doc: str = ""

    def c_prototype(self) -> str:
        arguments = []
        for parameter in self.parameters:
            code, name = parameter.split()
            c_type = _type(code)[0]
            arguments.append(f"{c_type}{name}" if c_type.endswith("*") else f"{c_type} {name}")
        result = _type(self.result)[0]
        head = f"{result}{self.name}" if result.endswith("*") else f"{result} {self.name}"
        return f"{head}({', '.join(arguments) or 'void'});"

    @property
    def argtypes(self) -> list:
        return [_type(parameter.split()[0])[1] for parameter in self.parameters]

    @property
    def restype(self):
        return _type(self.result)[1]


def _function(result: str, name: str, *parameters: str, doc: str = "") -> Function:
    return Function(name, result, parameters, doc)


_f = _function
FUNCTIONS: tuple[Function, ...] = (
    _f("i64", "rt_struct_size", "i64 which", doc="sizeof STRUCTS[which]"),
    _f("i64", "rt_struct_layout", "i64 which", ">i64 offsets", ">i64 sizes", "i64 capacity",
       doc="offset and size of each field of STRUCTS[which]; returns the count (writes them if it fits)"),
    _f("str", "rt_contract_digest"),
    _f("str", "rt_build_id", doc="RT_SOURCE_HASH=...; (build.py finds the marker in the library file)"),
    _f("handle", "rt_create", "desc desc", ">str error", "i64 capacity",
       doc="NULL when the description is refused; then `error` (capacity bytes, may be NULL) says why"),
    _f("handle", "rt_create_threaded", "desc desc", "i64 threads", ">str error", "i64 capacity"),
    _f("i64", "rt_object_tree", "chandle scene", "buffer pairs", ">i64 items", ">i64 root"),
    _f("void", "rt_destroy", "handle scene"),
    _f("int", "rt_edit", "handle scene", "desc desc", "<i64 objects", "i64 n", "i64 flags", "i64 threads",
       ">str error", "i64 capacity"),
    _f("int", "rt_set_sealed", "handle scene", "<u8 sealed", "i64 count"),
    _f("int", "rt_trace", "handle scene", "i64 n", "<f64 origins", "<f64 directions", ">f64 colors", ">i64 counts",
       "i64 threads", "f64 cutoff", "i64 savings", "i64 ray_budget", "<i32 cancel",
       doc="0; -1 out of memory; -2 stopped by `cancel` (polled at every ray; may be NULL) or a signal"),
    _f("int", "rt_first_hits", "handle scene", "i64 n", "<f64 origins", "<f64 directions", ">f64 t", ">f64 normal",
       ">i32 shape", ">i32 object", ">i8 entering", "i64 threads"),
    _f("int", "rt_occluded", "handle scene", "i64 n", "<f64 origins", "<f64 directions", "f64 t_max",
       ">i8 blocked", "i64 threads"),
    _f("i64", "rt_object_hits", "handle scene", "i64 object", "<f64 origin", "<f64 direction", "i64 capacity",
       ">f64 t", ">i8 entering", ">f64 normal", ">i32 shape", ">i32 part", ">f64 uv", ">i8 inside_at_start",
       ">f64 error", ">f64 offset"),
    _f("int", "rt_texture_colors", "handle scene", "i64 n", "<i32 shape", "<f64 points", "<i32 part",
       "<f64 bary", ">f64 out"),
    _f("i64", "rt_scan_numbers", "str text", "i64 length", ">f64 out", "i64 capacity", ">i64 bad"),
    _f("i64", "rt_scan3_state_size"),
    _f("i64", "rt_scan_3vn", ">i64 state", "str text", "i64 length", ">f64 vertices", ">f64 normals",
       ">i64 sizes", ">i32 vertex_index", ">i32 normal_index"),
    _f("i64", "rt_scan_3vn_end", ">i64 state", "int filled"),
    _f("i64", "rt_build_mesh_bvh", "i64 n", "<f64 vertices", "<i32 tri", "i64 leaf_size", "i64 bins", "f64 pad",
       "i64 threads", ">i32 order", ">buffer nodes_out"),
    _f("void", "rt_free", "buffer buffer"),
    _f("i64", "rt_mesh_wide_nodes", "chandle scene", "i64 mesh",
       doc="nodes of the mesh's four-wide tree (mesh_wide.h; 128 bytes each), 0 where it is walked as a binary "
           "tree, -1 for no such mesh"),
    _f("int", "rt_mesh_box_test", "chandle scene",
       doc="how the scene's mesh walks test boxes (mesh_wide.h): 0 binary walk, 1 scalar, 2 SSE2, 3 AVX2"),
    _f("result", "rt_sdl_read", "text text", "i64 length", "str words", "i64 words_length", "<i32 codes",
       "i64 count", "<f64 defaults", "i64 shared_libm"),
    _f("void", "rt_sdl_free", "result res"),
    _f("str", "rt_sdl_decline_names"),
    _f("int", "rt_interrupt_install", "i64 grace_ms", doc="interrupt.h: the C handler and its watchdog; 0 on success"),
    _f("void", "rt_interrupt_uninstall"),
    _f("void", "rt_interrupt_disarm"),
    _f("int", "rt_interrupt_heard", doc="the signal heard since rt_interrupt_clear(), or 0"),
    _f("void", "rt_interrupt_clear"),
    _f("int", "rt_interrupt_hold_file", "str path", doc="the watchdog removes it if it ends the process; slot or -1"),
    _f("void", "rt_interrupt_release_file", "int slot"),
    _f("i64", "rt_sdl_material_width"),
)
del _f


def declare(lib: ctypes.CDLL) -> None:
    """Give every exported function of ``lib`` its argument and result types, from :data:`FUNCTIONS`."""
    for f in FUNCTIONS:
        function = getattr(lib, f.name)
        function.restype = f.restype
        function.argtypes = f.argtypes


# ------------------------------------------------------------------------------------------------ the header


def _enum(prefix: str, names, values) -> str:
    items = [f"{prefix}_{c_name(n)} = {v}" for n, v in zip(names, values)]
    lines, line = [], "enum {"
    for k, item in enumerate(items):
        piece = f" {item}" + ("," if k < len(items) - 1 else " };")
        if len(line) + len(piece) > 110:
            lines.append(line)
            line = "      "
        line += piece
    lines.append(line)
    return "\n".join(lines)


def _double(value: float) -> str:
    text = repr(float(value))
    return text if any(c in text for c in ".en") else text + ".0"


def _per_c_kind(read) -> list[tuple[str, object]]:
    """(C kind, what ``read(entry)`` says) for every C kind, which all its SDL kinds must agree on."""
    out = []
    for c_kind, keywords in SHAPE_KINDS:
        values = {read(_shapes.KINDS[k]) for k in keywords}
        assert len(values) == 1, f"the SDL kinds of K_{c_kind} disagree on {read.__name__}"
        out.append((c_kind, values.pop()))
    return out


def _c_hits_call(entry: _shapes.ShapeKind) -> str:
    """The C call of a kind's intersection (ShapeKind's protocol), in the names core.c's analytic_hits has in
    scope: o, d, out, inside, D (the SceneDesc), param (the primitive's prim_param row) and aux (its
    prim_aux row)."""
    if entry.family == "polyhedron":
        values = ["D->planes + 4 * aux[0]", "aux[1]"]
    else:
        values = [f"param[{k}]" for k in range(len(entry.traced(entry.defaults)))]
    for name in entry.budget:
        field(f"tol_{name}")  # (a KeyError names a budget SceneDesc does not carry)
        values.append(f"D->tol_{name}")
    tail = ["out"] + ([] if entry.bounded else ["inside"])
    return f"{entry.c_intersect}({', '.join(['o', 'd'] + values + tail)})"


def _shape_dispatch() -> list[str]:
    """The C core's per-kind tables from the shape registry: X-macros over every kind's intersection call and
    texture mapping, which kinds' normals agree with their entering flags, which are meshes."""
    def call(entry):
        if entry.family == "mesh":  # (prim_hits and prim_first walk its BVH with their own buffers)
            assert entry.c_intersect == "mesh_all", f"{entry.keyword}: a mesh is traced by mesh_all"
            return None
        return _c_hits_call(entry)

    def uv(entry):
        return entry.c_uv

    def x_macro(name: str, pairs) -> list[str]:
        lines = [f"#define {name}(X) \\"] + [f"    X(K_{k}, {f}) \\" for k, f in pairs]
        lines[-1] = lines[-1][:-2]
        return lines

    agree = [k for k, words in SHAPE_KINDS if all(_shapes.KINDS[w].normals_agree for w in words)]
    meshes = [k for k, words in SHAPE_KINDS if _shapes.KINDS[words[0]].family == "mesh"]
    return ["/* Every kind's generic hits, as a call in analytic_hits' names (tracer/shapes.py: c_intersect with its",
            " * parameters, face planes and error budget; meshes are traced by the BVH instead). */",
            *x_macro("RT_SHAPE_HITS", [(k, c) for k, c in _per_c_kind(call) if c]),
            "/* Every kind's texture mapping (ShapeKind.c_uv). */",
            *x_macro("RT_SHAPE_UV", _per_c_kind(uv)),
            "/* Closed kinds: normals agree with entering flags (ShapeKind.normals_agree). */",
            "#define RT_NORMALS_AGREE(kind) (" + " || ".join(f"(kind) == K_{k}" for k in agree) + ")",
            "/* Kinds made of triangles, traced by their BVH (the mesh family). */",
            "#define RT_IS_MESH(kind) (" + " || ".join(f"(kind) == K_{k}" for k in meshes) + ")"]


def header_text() -> str:
    """The C header, as generated from the tables above (and the constants' current values)."""
    out = ["/* GENERATED by `python -m tracer.native.contract` from tracer/native/contract.py: do not edit.",
           " * The codes, constants, structs and exported functions shared by the C core and its Python side. */",
           "#ifndef RT_CONTRACT_H", "#define RT_CONTRACT_H", "", "#include <stdint.h>", ""]
    out.append(_enum("K", [k for k, _ in SHAPE_KINDS], range(len(SHAPE_KINDS))))
    out.append(_enum("OP", CSG_OPS, range(len(CSG_OPS))))
    out.append(_enum("FX", EFFECTS, [EFFECT_BITS[e] for e in EFFECTS]))
    out.append(_enum("RAY", RAY_KINDS, range(len(RAY_KINDS))))
    out.append(_enum("LIGHT", LIGHT_KINDS, range(len(LIGHT_KINDS))))
    out.append(_enum("LIGHT_OFF", LIGHT_SWITCHES, [1 << k for k in range(len(LIGHT_SWITCHES))]))
    out.append(_enum("FRESNEL", FRESNEL_MODES, range(len(FRESNEL_MODES))))
    out.append(_enum("SKIP", SKIP_REASONS, range(len(RAY_KINDS), len(RAY_KINDS) + len(SKIP_REASONS))))
    out.append(_enum("SAVE", SAVINGS_SWITCHES, [1 << k for k in range(len(SAVINGS_SWITCHES))]))
    out.append(_enum("EDIT", EDIT_FLAGS, [1 << k for k in range(len(EDIT_FLAGS))]))
    out.append(f"#define K_COUNT {len(SHAPE_KINDS)}")
    out += _shape_dispatch()
    out += ["/* The C SDL reader's actions (sdl_read.h), in code order: a statement's action code is its index",
            " * (tracer/sdl/statements.py names each statement's). */",
            "#define RT_SDL_ACTIONS(X) " + " ".join(f"X({k}, {a})" for k, a in enumerate(_statements.ACTIONS)),
            f"#define RT_SDL_ACTION_COUNT {len(_statements.ACTIONS)}"]
    out.append(f"#define RAY_KIND_COUNT {len(RAY_KINDS)}")
    out.append(f"#define N_COUNTS {len(RAY_KINDS) + len(SKIP_REASONS)}  /* rays cast per kind, then skipped per reason */")
    out.append("")
    for c in CONSTANTS:
        value = c.value()
        text = _double(value) if c.kind == "double" else str(value)
        out.append(f"/* {c.doc} ({c.source}) */")
        out.append(f"#define {c.name} {text}")
    for struct in STRUCTS:
        out += _struct_text(struct)
    out += ["", "/* Every function the library exports (FUNCTIONS), which ctypes declares from the same table. */"]
    for f in FUNCTIONS:
        if f.doc:
            out.append(f"/* {f.doc} */")
        out.append(f.c_prototype())
    out += ["", "/* The structs by number (rt_struct_size, rt_struct_layout's `which`), with their fields' X-macros. */",
            "#define RT_STRUCTS(X) " + " ".join(f"X({k}, {st.name}, {st.macro})" for k, st in enumerate(STRUCTS))]
    body = "\n".join(out)
    # A fingerprint of everything above: the loader refuses a library built from another contract.
    stamp = hashlib.sha256(body.encode()).hexdigest()[:16]
    return f"{body}\n#define RT_CONTRACT_DIGEST \"{stamp}\"\n\n#endif\n"


def _struct_text(struct: Struct) -> list[str]:
    """A struct's typedef and the X-macro over its fields in table order (rt_struct_layout reports offsetof
    and sizeof of each)."""
    out = ["", f"/* {struct.doc} */", "typedef struct {"]
    for f in struct.fields:
        if f.section:
            out.append(f"    /* {f.section} */")
        declaration = f"    {f.c_declaration(struct.const)}"
        if f.doc:
            declaration = f"{declaration:<44} /* {f.doc} */"
        out.append(declaration)
    out.append(f"}} {struct.name};")
    out += [f"#define {struct.macro}(X) \\"] + [f"    X({struct.name}, {f.name}) \\" for f in struct.fields]
    out[-1] = out[-1][:-2]
    return out


def stale_reason(path: Path = HEADER) -> Optional[str]:
    """None if ``path`` holds what :func:`header_text` generates now, else why not."""
    try:
        current = path.read_text()
    except OSError as err:
        return f"cannot read {path}: {err.strerror or err}"
    return None if current == header_text() else f"{path.name} is stale: run python -m tracer.native.contract"


def digest() -> str:
    """The RT_CONTRACT_DIGEST that :func:`header_text` writes."""
    return header_text().split('RT_CONTRACT_DIGEST "')[1].split('"')[0]


def main(argv: list[str] | None = None) -> int:
    args = sys.argv[1:] if argv is None else argv
    if "--check" in args:
        reason = stale_reason()
        if reason:
            print(f"error: {reason}", file=sys.stderr)
            return 1
        return 0
    text = header_text()
    if not HEADER.exists() or HEADER.read_text() != text:
        HEADER.write_text(text)
        print(f"wrote {HEADER}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
