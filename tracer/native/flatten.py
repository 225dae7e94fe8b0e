"""A CompiledScene as flat, contiguous arrays for the C core, and the ctypes mirror of its SceneDesc.

Nothing is recomputed here that the NumPy path computes: inverse matrices, bounding spheres, polyhedron
planes, mesh BVHs and material tables are taken from the compiled scene as they are, so both backends
trace the same numbers.  What is added is a padded world bounding box per top-level object, for the C
core's BVH over objects.

:func:`unsupported_reason` decides which scenes the C core traces: anything it does not know (an effect it
has not implemented, a node type or a mesh layout it does not understand) is refused
with a reason, and the NumPy path takes the scene.
"""
from __future__ import annotations

import ctypes
from typing import Optional

import numpy as np

from ..backend import MAX_CSG_DEPTH  # (make_tracer refuses deeper trees, for every backend)
from ..compile import CompiledScene, Primitive, PrimitiveTable, boolean_box, boolean_depth, fold_tree
from ..geometry.polyhedra import face_planes
from ..intersect.mesh import NODE, MeshArrays
from .. import numerics, shapes
from ..model import POLYHEDRON_KINDS, SHAPE_KINDS, traced_depth
from . import contract
from .contract import EFFECT_BITS, KIND_CODES, OP_CODES

#: Effects the C core implements; any other live effect sends the scene to the NumPy path.
HANDLED_EFFECTS = frozenset(EFFECT_BITS) | {"csg"} | {f"shape:{kind}" for kind in KIND_CODES}
#: Relative padding of the objects' world boxes: far above the rounding of any hit, and of the shapes'
#: own edge tolerances (1e-12 of their size), far below anything that costs time.
BOX_PADDING = 1e-8

#: The tracer.intersect.mesh constants the C core reads (SceneDesc.mesh_constants, in this order).
MESH_CONSTANTS = ("ROUNDING_FACTOR", "BARYCENTRIC_EPSILON_MAX", "PARALLEL_EPSILON", "DEDUPE_RELATIVE",
                  "DEDUPE_RELATIVE_ADJACENT")
#: SceneDesc's per-mesh address fields and the MeshArrays field each points into, with its element type.
MESH_ADDRESSES = {"mesh_nodes": "nodes", "mesh_order": "tri_order", "mesh_tri_vertex": "tri_vertex",
                  "mesh_tri_normal": "tri_normal", "mesh_vertices": "vertices", "mesh_normals": "normals"}
MESH_DTYPES = {"nodes": NODE, "tri_order": np.int32, "tri_vertex": np.int32, "tri_normal": np.int32,
               "vertices": np.float64, "normals": np.float64}
_SHARED = contract.constant_values()
TEX_PARAMS = _SHARED["TEX_PARAMS"]


class SceneDesc(ctypes.Structure):
    _fields_ = contract.ctypes_fields()



def unsupported_reason(compiled: CompiledScene) -> Optional[str]:
    """None if the C core traces this scene exactly as the NumPy path does, else why not."""
    unknown = sorted(e for e in compiled.effects if e not in HANDLED_EFFECTS)
    if unknown:
        return f"not implemented in C: {', '.join(unknown)}"
    for kind in SHAPE_KINDS:  # a shape kind added to the model but not here
        if kind not in KIND_CODES:
            return f"not implemented in C: shape {kind}"

    def check_boolean(node, left: Optional[str], right: Optional[str]) -> Optional[str]:
        return (None if node.op in OP_CODES else f"unknown boolean {node.op!r}") or left or right

    def check(node) -> Optional[str]:
        return None if isinstance(node, Primitive) else f"unknown scene node {type(node).__name__}"

    # Every primitive is a row of the table: its kind has a C code (checked above), a polyhedron has its
    # kind's face planes; only a mesh's triangles can be missing.
    table = compiled.table
    for mesh, rows in table.mesh_groups():
        if id(mesh) not in table.meshes:
            return f"{shapes.REGISTRY[table.kind[rows[0]]].keyword} has no triangle mesh"
    for obj in compiled.objects.booleans.values():
        reason = fold_tree(obj, check, check_boolean)
        if reason:
            return reason
        if boolean_depth(obj) > MAX_CSG_DEPTH:
            return f"booleans nested more than {MAX_CSG_DEPTH} deep"
    if table.meshes:
        from ..intersect import mesh as mesh_module
        missing = [c for c in MESH_CONSTANTS if not hasattr(mesh_module, c)]
        if missing:
            return f"mesh constants not found: {', '.join(missing)}"
    return None


#: Per shape registry entry: its C kind code, and whether it is bounded.
_CODE_OF_ENTRY = np.array([KIND_CODES[e.keyword] for e in shapes.REGISTRY], dtype=np.int32)
_BOUNDED = np.array([e.bounded for e in shapes.REGISTRY])


def _padded_boxes(table: PrimitiveTable) -> np.ndarray:
    """The primitives' world boxes (P, 6: lo, hi), padded relatively (meaningless for unbounded shapes):
    by BOX_PADDING times the largest coordinate's size plus the box's longest side.  (The maxima over the
    three axes spelt out: NumPy's reductions over rows of three take several times longer.)"""
    lo, hi = table.boxes[:, :3], table.boxes[:, 3:]
    size, side = np.maximum(np.abs(lo), np.abs(hi)), hi - lo
    pad = BOX_PADDING * (np.maximum(np.maximum(size[:, 0], size[:, 1]), size[:, 2])
                         + np.maximum(np.maximum(side[:, 0], side[:, 1]), side[:, 2]))
    boxes = np.empty_like(table.boxes)
    np.subtract(lo, pad[:, None], out=boxes[:, :3])
    np.add(hi, pad[:, None], out=boxes[:, 3:])
    return boxes


def _box(node, lo: np.ndarray, hi: np.ndarray, bounded: np.ndarray):
    """World box (lo, hi) that holds every surface point of the node's solid, or None if unbounded."""
    return fold_tree(node, lambda prim: _primitive_box(prim, lo, hi, bounded), _boolean_box)


def _primitive_box(prim, lo: np.ndarray, hi: np.ndarray, bounded: np.ndarray):
    i = prim.index
    return (lo[i], hi[i]) if bounded[i] else None


def _boolean_box(node, left, right):
    return boolean_box(node.op, left, right)


class FlatScene:
    """The arrays (kept alive here) and the SceneDesc that points into them."""

    def __init__(self, compiled: CompiledScene):
        self.arrays: dict[str, np.ndarray] = {}
        a = self.arrays
        table = compiled.table
        n = len(table)
        codes = _CODE_OF_ENTRY[table.kind]
        a["prim_kind"] = codes
        a["prim_inverse"] = table.inverses.reshape(n, 16)  # (a view: the C core reads the table's own inverses)
        a["prim_sphere"] = table.spheres
        a["prim_param"] = table.top  # (0 but for tapered cylinders)
        a["prim_material"] = table.material_ids
        rounding = numerics.gamma(table.tolerances.hit_ulps) + table.inverse_error  # (Primitive.rounding)
        a["prim_rounding"] = np.concatenate([(rounding / table.generic_size)[:, None], table.generic_size[:, None],
                                             table.inverse_norms], axis=1)

        # Polyhedra planes (one set per kind) and meshes (instances share one mesh).
        aux = np.zeros((n, 2), dtype=np.int64)
        planes, first_plane = [], 0
        for kind in POLYHEDRON_KINDS:
            rows = table.rows([kind])
            if rows.size:
                normals, offsets = face_planes(kind)
                aux[rows] = (first_plane, len(offsets))
                planes.append(np.c_[np.asarray(normals, dtype=np.float64), np.asarray(offsets, dtype=np.float64)])
                first_plane += len(offsets)
        meshes, mesh_index = [], {}
        for data, rows in table.mesh_groups():  # (in order of first use)
            mesh = table.meshes[id(data)]
            if id(mesh) not in mesh_index:  # (meshes of equal content share one TriangleMesh)
                mesh_index[id(mesh)] = len(meshes)
                meshes.append(mesh.arrays())
            aux[rows, 0] = mesh_index[id(mesh)]
        a["prim_aux"] = aux
        a["planes"] = np.concatenate(planes) if planes else np.zeros((0, 4))
        self._flatten_meshes(meshes)

        # CSG nodes and top-level objects: the plain shapes (the common case) all at once, each boolean
        # by walking its tree.
        csg_op, csg_left, csg_right = [], [], []

        def boolean_ref(node, left: int, right: int) -> int:
            csg_op.append(OP_CODES[node.op])
            csg_left.append(left)
            csg_right.append(right)
            return -len(csg_op)  # node k is ref -k - 1

        prim_box, prim_bounded = _padded_boxes(table), _BOUNDED[table.kind]
        prim_lo, prim_hi = prim_box[:, :3], prim_box[:, 3:]
        objects = compiled.objects
        index = objects.primitive_index
        if not objects.booleans:  # object k is primitive k: its tables are the primitives'
            object_ref, object_box, bounded = index, prim_box, prim_bounded
        else:
            plain = np.flatnonzero(index >= 0)
            object_ref = index.copy()
            object_box = np.zeros((len(index), 6))
            bounded = np.zeros(len(index), dtype=bool)
            bounded[plain] = prim_bounded[index[plain]]
            object_box[plain] = prim_box[index[plain]]
        for k, obj in objects.booleans.items():
            object_ref[k] = fold_tree(obj, lambda prim: prim.index, boolean_ref)
            box = _box(obj, prim_lo, prim_hi, prim_bounded)
            if box is not None:
                bounded[k] = True
                object_box[k, :3], object_box[k, 3:] = box
        a.update(csg_op=csg_op, csg_left=csg_left, csg_right=csg_right, object_ref=object_ref,
                 object_box=object_box, object_bounded=bounded)

        mats = compiled.materials
        a.update(mat_ambient=mats.ambient, mat_diffuse=mats.diffuse, mat_specular=mats.specular,
                 mat_emissive=mats.emissive, mat_exponent=mats.specular_exponent,
                 mat_reflectivity=mats.reflectivity, mat_transparency=mats.transparency,
                 mat_speed=mats.speed_of_light,
                 mat_specular_fraction=getattr(mats, "specular_fraction", np.zeros(len(mats.materials))),
                 mat_roughness=getattr(mats, "surface_roughness", np.ones(len(mats.materials))),
                 mat_fresnel=mats.fresnel, mat_fresnel_tint=mats.fresnel_tint)
        lights = compiled.lights
        a.update(light_pos=lights.position, light_color=lights.color, light_kind=lights.kind,
                 light_samples=lights.samples, light_frame=lights.frame, light_param=lights.param)
        n_images = self._flatten_textures(compiled)

        settings = compiled.settings
        counts = dict(n_prims=n, n_meshes=len(meshes), n_csg=len(csg_op), n_objects=len(object_ref),
                      n_materials=len(mats.materials), n_lights=len(compiled.light_positions), n_images=n_images)
        effects = sum(bit for name, bit in EFFECT_BITS.items() if name in compiled.effects)
        scalars = dict(background=tuple(settings.background), global_ambient=tuple(settings.global_ambient),
                       min_reflectivity=float(settings.min_reflectivity),
                       min_transparency=float(settings.min_transparency),
                       max_depth=traced_depth(settings.max_recursion_depth), effects=effects,
                       mesh_constants=self._mesh_constants(meshes))
        tol = compiled.tolerances
        scalars.update(tol_hit_ulps=float(tol.hit_ulps), tol_offset_ulps=float(tol.offset_ulps),
                       tol_torus_residual_ulps=float(tol.torus_residual_ulps),
                       tol_torus_newton_steps=int(tol.torus_newton_steps),
                       tol_torus_pair_shortcut=float(tol.torus_pair_shortcut), tol_square_edge=float(tol.square_edge))
        self.desc = SceneDesc()
        for f in contract.SCENE_DESC:
            if not f.is_pointer:
                value = counts[f.name] if f.name in counts else scalars[f.name]
                setattr(self.desc, f.name, f.ctype(*value) if isinstance(value, tuple) else value)
                continue
            array = np.ascontiguousarray(np.asarray(a.get(f.name, ()), dtype=f.dtype).reshape(-1))
            if array.size == 0:  # a valid pointer even for empty tables
                array = np.zeros(1, dtype=f.dtype)
            a[f.name] = array
            setattr(self.desc, f.name, array.ctypes.data_as(f.ctype))

    def _flatten_textures(self, compiled: CompiledScene) -> int:
        """Per-material texture numbers, parameters (defaults filled in as tracer.textures does) and image
        indices; the pictures (by address: each is already one contiguous array, no copy); the noise
        tables.  Nothing for a scene without textures.  Returns the number of pictures."""
        from ..textures import image_repeats
        from ..textures.noise import GRADIENTS, PERM
        from ..textures.solid import SOLID_DEFAULTS, with_defaults

        a = self.arrays
        if "textures" not in compiled.effects:  # the C core never reads these tables then
            return 0
        images = getattr(compiled.textures, "images", None) or {}
        numbers = sorted(images)
        pictures = [np.ascontiguousarray(images[k], dtype=np.uint8) for k in numbers]  # 8-bit, as loaded
        materials = compiled.materials.materials
        texture = np.zeros(len(materials), dtype=np.int32)
        params = np.zeros((len(materials), TEX_PARAMS))
        image_index = np.full(len(materials), -1, dtype=np.int64)
        for m, material in enumerate(materials):
            number = int(material.texture)
            texture[m] = number
            if number < 0 and number in SOLID_DEFAULTS:
                values = with_defaults(tuple(material.parameters), SOLID_DEFAULTS[number])
            elif number > 0:
                values = image_repeats(material.parameters)
                image_index[m] = numbers.index(number) if number in images else -1
            else:
                values = ()
            params[m, :len(values)] = values
        self._pictures = pictures  # the C side points into these
        a.update(mat_texture=texture, mat_tex_param=params, mat_tex_image=image_index,
                 image_info=[(p.shape[1], p.shape[0]) for p in pictures],
                 image_data=np.array([p.ctypes.data for p in pictures], dtype=np.uintp),
                 noise_perm=PERM, noise_gradients=GRADIENTS)
        return len(pictures)

    @staticmethod
    def _mesh_constants(meshes) -> tuple:
        if not meshes:
            return (0.0,) * 5
        from ..intersect import mesh as mesh_module
        return tuple(float(getattr(mesh_module, name)) for name in MESH_CONSTANTS)

    def _flatten_meshes(self, meshes: list[MeshArrays]) -> None:
        """Per mesh, its counts and the addresses of its own arrays (nothing is copied: the C core reads
        the arrays the NumPy path reads; self.arrays keeps them alive)."""
        a = self.arrays
        a["mesh_info"] = [(len(m.nodes), len(m.tri_order), len(m.vertices), len(m.normals)) for m in meshes]
        a["mesh_extent"] = [float(m.extent) for m in meshes]
        kept = []
        for field, column in MESH_ADDRESSES.items():
            arrays = [getattr(m, column) for m in meshes]
            checked = [None if x is None else np.ascontiguousarray(x, dtype=MESH_DTYPES[column]) for x in arrays]
            kept += [x for x in checked if x is not None]
            a[field] = np.array([0 if x is None else x.ctypes.data for x in checked], dtype=np.uintp)
        self._mesh_arrays = kept  # the C side points into these
