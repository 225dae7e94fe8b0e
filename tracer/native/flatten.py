"""A CompiledScene as flat, contiguous arrays for the C core, pointed to by a SceneDesc (contract.SceneDesc).

Nothing is recomputed here that the NumPy path computes: inverse matrices, bounding spheres, polyhedron
planes, mesh BVHs and material tables are taken from the compiled scene as they are, so both backends
trace the same numbers.  What is added is a padded world bounding box per top-level object, for the C
core's BVH over objects.

:func:`unsupported_reason` decides which scenes the C core traces: anything it does not know (an effect it
has not implemented, a node type or a mesh layout it does not understand) is refused
with a reason, and the NumPy path takes the scene.
"""
from __future__ import annotations

from typing import Optional, Union

import numpy as np

from ..compile import (MAX_CSG_DEPTH, CompiledScene, InstancedTable, Primitive, PrimitiveTable, boolean_box,
                       boolean_depth, fold_tree, row_chunks)
from .. import numerics, shapes
from ..geometry.polyhedra import face_planes
from ..instances import padded_boxes, single_boxes
from ..intersect import mesh as mesh_module
from ..intersect.mesh import NODE, MeshArrays
from ..model import MESH_KINDS, POLYHEDRON_KINDS, SHAPE_KINDS, traced_depth
from . import contract
from .contract import EFFECT_BITS, KIND_CODES, OP_CODES, SceneDesc

#: Effects the C core implements; any other live effect sends the scene to the NumPy path.
HANDLED_EFFECTS = frozenset(EFFECT_BITS) | {"csg"} | {f"shape:{kind}" for kind in KIND_CODES}

#: The tracer.intersect.mesh constants the C core reads (SceneDesc.mesh_constants, in this order).
MESH_CONSTANTS = ("ROUNDING_FACTOR", "BARYCENTRIC_EPSILON_MAX", "PARALLEL_EPSILON", "DEDUPE_RELATIVE",
                  "DEDUPE_RELATIVE_ADJACENT")
#: SceneDesc's per-mesh address fields and the MeshArrays field each points into, with its element type.
MESH_ADDRESSES = {"mesh_nodes": "nodes", "mesh_order": "tri_order", "mesh_tri_vertex": "tri_vertex",
                  "mesh_tri_normal": "tri_normal", "mesh_vertices": "vertices", "mesh_normals": "normals",
                  "mesh_tri_uv": "tri_uv"}
MESH_DTYPES = {"nodes": NODE, "tri_order": np.int32, "tri_vertex": np.int32, "tri_normal": np.int32,
               "vertices": np.float64, "normals": np.float64, "tri_uv": np.float64}
_SHARED = contract.constant_values()
TEX_PARAMS = _SHARED["TEX_PARAMS"]
PRIM_PARAMS = _SHARED["PRIM_PARAMS"]



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
        missing = [c for c in MESH_CONSTANTS if not hasattr(mesh_module, c)]
        if missing:
            return f"mesh constants not found: {', '.join(missing)}"
    return None


#: Per shape registry entry: its C kind code, and whether it is bounded.
_CODE_OF_ENTRY = np.array([KIND_CODES[e.keyword] for e in shapes.REGISTRY], dtype=np.int32)
_BOUNDED = np.array([e.bounded for e in shapes.REGISTRY])
#: Per shape registry entry: whether its primitives have a prim_aux entry (polyhedra's planes, meshes).
_HAS_AUX = np.array([e.keyword in POLYHEDRON_KINDS or e.keyword in MESH_KINDS for e in shapes.REGISTRY])


def _padded_boxes(table: PrimitiveTable, rows=slice(None)) -> np.ndarray:
    """The primitives' world boxes (P, 6: lo, hi), padded (instances.padded_boxes; meaningless for unbounded
    shapes).  Of every row, or of ``rows``."""
    boxes = table.boxes
    return padded_boxes(boxes[rows, :3], boxes[rows, 3:])


def _single_box(box: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """One box (lo, hi) as instances.single_boxes makes them: (6,) float32."""
    return single_boxes(np.concatenate(box)[None])[0]


def _object_boxes(table: PrimitiveTable, rows: Optional[np.ndarray] = None) -> np.ndarray:
    """single_boxes(_padded_boxes(table, rows)) (of every row when ``rows`` is None), the same numbers
    computed a chunk of rows at a time: a chunk's temporaries stay in the cache, where the whole table's
    (ten arrays of 12-48 bytes a row) were fresh pages, each faulted in and zeroed (0.55 s of the 10^6-sphere
    build)."""
    count = len(table) if rows is None else len(rows)
    out = np.empty((count, 6), dtype=np.float32)
    for part in row_chunks(count):
        out[part] = single_boxes(_padded_boxes(table, part if rows is None else rows[part]))
    return out


def _box(node, lo: np.ndarray, hi: np.ndarray, bounded: np.ndarray):
    """World box (lo, hi) that holds every surface point of the node's solid, or None if unbounded."""
    return fold_tree(node, lambda prim: _primitive_box(prim, lo, hi, bounded), _boolean_box)


def _primitive_box(prim, lo: np.ndarray, hi: np.ndarray, bounded: np.ndarray):
    i = prim.index
    return (lo[i], hi[i]) if bounded[i] else None


def _boolean_box(node, left, right):
    return boolean_box(node.op, left, right)


class FlatScene:
    """The arrays (kept alive here) and the SceneDesc that points into them.  tracer.edit changes them in place
    (:meth:`edit`) or makes a new FlatScene of the edited compiled scene."""

    def __init__(self, compiled: CompiledScene):
        self.arrays: dict[str, np.ndarray] = {}
        a = self.arrays
        table = compiled.table
        n = len(table)
        a["prim_kind"] = _CODE_OF_ENTRY[table.kind]
        a["prim_param"] = table.parameters  # (PRIM_PARAMS per primitive: what its kind's intersection takes)
        a["prim_material"] = table.material_ids
        stored = table.stored if isinstance(table, InstancedTable) else table
        # (views: the C core reads the table's own inverses and rounding terms; of an InstancedTable, its
        # stored rows' only, and each instance row's affine and box)
        a["prim_inverse"] = stored.inverses.reshape(len(stored), 16)
        a["prim_sphere"] = stored.spheres
        a["prim_rounding"] = stored.rounding_terms
        self._instance_rows = n - len(stored)
        if self._instance_rows:
            a.update(prim_slot=table.slot, instance_affine=table.affines, instance_box=table.object_boxes)

        # Polyhedra planes (one set per kind) and meshes (instances share one mesh).
        aux = np.zeros((n, 2), dtype=np.int32)
        self._planes_of: dict[str, tuple[int, int]] = {}  # polyhedron kind -> (first plane, count)
        self._plane_blocks: list[np.ndarray] = []  # each kind's planes, in that order
        for kind in POLYHEDRON_KINDS:
            rows = table.rows([kind])
            if rows.size:
                aux[rows] = self._plane_range(kind)
        self._meshes: list[MeshArrays] = []
        self._mesh_owners: list = []  # the TriangleMesh of each (its id names it while it is listed)
        self._mesh_index: dict[int, int] = {}  # id(TriangleMesh) -> its index in SceneDesc's mesh tables
        for data, rows in table.mesh_groups():  # (in order of first use)
            aux[rows, 0] = self._mesh_number(table.meshes[id(data)])
        a["prim_aux"] = aux
        self._generic_sizes = getattr(table, "generic_sizes", {})  # (an InstancedTable's, by TriangleMesh id)
        a["planes"] = np.concatenate(self._plane_blocks) if self._plane_blocks else np.zeros((0, 4))
        self._flatten_meshes(self._meshes)

        # CSG nodes and top-level objects: the plain shapes (the common case) all at once, each boolean
        # by walking its tree.
        csg_op, csg_left, csg_right = [], [], []

        def boolean_ref(node, left: int, right: int) -> int:
            csg_op.append(OP_CODES[node.op])
            csg_left.append(left)
            csg_right.append(right)
            return -len(csg_op)  # node k is ref -k - 1

        prim_bounded = _BOUNDED[table.kind]
        objects = compiled.objects
        index = objects.primitive_index
        if not objects.booleans:  # object k is primitive k: its tables are the primitives'
            object_box = table.object_boxes if isinstance(table, InstancedTable) else _object_boxes(table)
            object_ref, bounded = index, prim_bounded
        else:
            prim_box = _padded_boxes(table)
            prim_lo, prim_hi = prim_box[:, :3], prim_box[:, 3:]
            plain = np.flatnonzero(index >= 0)
            object_ref = index.copy()
            object_box = np.zeros((len(index), 6), dtype=np.float32)
            bounded = np.zeros(len(index), dtype=bool)
            bounded[plain] = prim_bounded[index[plain]]
            object_box[plain] = single_boxes(prim_box[index[plain]])
        for k, obj in objects.booleans.items():
            object_ref[k] = fold_tree(obj, lambda prim: prim.index, boolean_ref)
            box = _box(obj, prim_lo, prim_hi, prim_bounded)
            if box is not None:
                bounded[k] = True
                object_box[k] = _single_box(box)
        a.update(csg_op=csg_op, csg_left=csg_left, csg_right=csg_right, object_ref=object_ref,
                 object_box=object_box, object_bounded=bounded)
        self._counts = dict(n_prims=n, n_csg=len(csg_op), n_objects=len(object_ref),
                            instance_rows=self._instance_rows)
        self._take_materials(compiled)
        self._take_lights(compiled)
        self.desc = SceneDesc()
        self._describe(compiled)

    def _plane_range(self, kind: str) -> tuple[int, int]:
        """(first plane, count) of a polyhedron kind's face planes (added to the blocks when new)."""
        if kind not in self._planes_of:
            normals, offsets = face_planes(kind)
            first = sum(map(len, self._plane_blocks))
            self._plane_blocks.append(np.c_[np.asarray(normals, dtype=np.float64),
                                            np.asarray(offsets, dtype=np.float64)])
            self._planes_of[kind] = (first, len(offsets))
        return self._planes_of[kind]

    def _mesh_number(self, mesh) -> int:
        """The index of a TriangleMesh in the mesh tables (meshes of equal content share one), added if new."""
        number = self._mesh_index.get(id(mesh))
        if number is None:
            number = self._mesh_index[id(mesh)] = len(self._meshes)
            self._meshes.append(mesh.arrays())
            self._mesh_owners.append(mesh)
        return number

    def _take_materials(self, compiled: CompiledScene, rows: Optional[np.ndarray] = None) -> None:
        """The material tables (views of the compiled scene's columns), and the texture tables: all of them,
        or (``rows``: tracer.edit's materials written or added, the pictures and effects as they were) only
        those rows."""
        mats = compiled.materials
        self.arrays.update(mat_ambient=mats.ambient, mat_diffuse=mats.diffuse, mat_specular=mats.specular,
                           mat_emissive=mats.emissive, mat_exponent=mats.specular_exponent,
                           mat_reflectivity=mats.reflectivity, mat_transparency=mats.transparency,
                           mat_speed=mats.speed_of_light,
                           mat_specular_fraction=getattr(mats, "specular_fraction", np.zeros(len(mats.materials))),
                           mat_roughness=getattr(mats, "surface_roughness", np.ones(len(mats.materials))),
                           mat_fresnel=mats.fresnel, mat_fresnel_tint=mats.fresnel_tint)
        if rows is None:
            self._counts.update(n_materials=len(mats.materials), n_images=self._flatten_textures(compiled))
            return
        self._counts["n_materials"] = len(mats.materials)
        if "textures" in compiled.effects:
            for name, fill in (("mat_texture", 0), ("mat_tex_param", 0.0), ("mat_tex_image", -1)):
                table = self.arrays[name]
                width = TEX_PARAMS if name == "mat_tex_param" else 1
                missing = len(mats.materials) * width - len(table)
                if missing > 0:  # (materials added: their rows are among ``rows``)
                    self.arrays[name] = np.concatenate([table, np.full(missing, fill, dtype=table.dtype)])
            self._flatten_textures(compiled, rows)

    def _take_lights(self, compiled: CompiledScene) -> None:
        lights = compiled.lights
        self.arrays.update(light_pos=lights.position, light_color=lights.color, light_kind=lights.kind,
                           light_samples=lights.samples, light_frame=lights.frame, light_param=lights.param,
                           light_off=lights.off)
        self._counts["n_lights"] = len(lights.position)

    def _describe(self, compiled: CompiledScene) -> None:
        """Every field of the SceneDesc: the pointers into the arrays as they are now, the counts, the
        compiled scene's settings, effects and tolerances."""
        a = self.arrays
        settings = compiled.settings
        counts = dict(self._counts, n_meshes=len(self._meshes))
        effects = sum(bit for name, bit in EFFECT_BITS.items() if name in compiled.effects)
        scalars = dict(background=tuple(settings.background), global_ambient=tuple(settings.global_ambient),
                       min_reflectivity=float(settings.min_reflectivity),
                       min_transparency=float(settings.min_transparency),
                       max_depth=traced_depth(settings.max_recursion_depth), effects=effects,
                       mesh_constants=self._mesh_constants(self._meshes))
        tol = compiled.tolerances
        scalars.update(tol_hit_ulps=float(tol.hit_ulps), tol_offset_ulps=float(tol.offset_ulps),
                       hit_gamma=float(numerics.gamma(compiled.table.tolerances.hit_ulps)),
                       tol_torus_residual_ulps=float(tol.torus_residual_ulps),
                       tol_torus_newton_steps=int(tol.torus_newton_steps),
                       tol_torus_pair_shortcut=float(tol.torus_pair_shortcut), tol_square_edge=float(tol.square_edge))
        pointed = self.__dict__.setdefault("_pointed", {})  # field -> the array it points into now
        for f in contract.SCENE_DESC:
            if not f.is_pointer:
                value = counts[f.name] if f.name in counts else scalars[f.name]
                setattr(self.desc, f.name, f.ctype(*value) if isinstance(value, tuple) else value)
                continue
            array = a.get(f.name, ())
            if pointed.get(f.name) is array:  # (an edit changed it in place, or not at all)
                continue
            array = np.ascontiguousarray(np.asarray(array, dtype=f.dtype).reshape(-1))
            if array.size == 0:  # a valid pointer even for empty tables
                array = np.zeros(1, dtype=f.dtype)
            a[f.name] = pointed[f.name] = array
            setattr(self.desc, f.name, array.ctypes.data_as(f.ctype))

    def edit(self, compiled: CompiledScene, prims: np.ndarray, objects: np.ndarray,
             materials: Union[bool, np.ndarray], lights: bool) -> bool:
        """Take tracer.edit's in-place edits of ``compiled`` (the scene this was made from, no object added or
        removed): primitive rows ``prims`` and top-level objects ``objects`` (index arrays) recomputed, the
        materials read again (``materials``: True for all of them, their table may have grown or the
        effects or pictures changed; or the rows written, in place) and the lights (``lights``), the
        description pointed anew.  Returns whether the mesh tables changed."""
        a, table = self.arrays, compiled.table
        if self._instance_rows:
            raise TypeError("a scene with instance rows is not edited in place (tracer.edit compiles Shapes)")
        touched_meshes = bool((a["prim_kind"][prims] == KIND_CODES["mesh"]).any())  # (before: was a mesh)
        a["prim_kind"][prims] = _CODE_OF_ENTRY[table.kind[prims]]
        for name, column, width in (("prim_inverse", table.inverses, 16), ("prim_sphere", table.spheres, 4),
                                    ("prim_rounding", table.rounding_terms, 4),
                                    ("prim_param", table.parameters, PRIM_PARAMS),
                                    ("prim_material", table.material_ids, 1)):
            a[name].reshape(-1, width)[prims] = column[prims].reshape(-1, width)  # (no-ops where a is a view)
        aux = a["prim_aux"].reshape(-1, 2)
        meshes_before, plane_kinds = len(self._meshes), len(self._planes_of)
        aux[prims] = 0
        special = prims[_HAS_AUX[table.kind[prims]]]  # (polyhedra and meshes: the rest have no aux)
        for i, kind in zip(special.tolist(), table.kind[special].tolist()):
            keyword = shapes.REGISTRY[kind].keyword
            if keyword in POLYHEDRON_KINDS:
                aux[i] = self._plane_range(keyword)
            else:
                aux[i] = (self._mesh_number(table.meshes[id(table.shapes[i].mesh)]), 0)
        if len(self._planes_of) != plane_kinds:
            a["planes"] = np.concatenate(self._plane_blocks)
        touched_meshes |= bool((a["prim_kind"][prims] == KIND_CODES["mesh"]).any())
        meshes_changed = len(self._meshes) != meshes_before or (touched_meshes and self._drop_unused_meshes(table))
        if meshes_changed:
            self._flatten_meshes(self._meshes)
        self._object_rows(compiled, prims, objects)
        if materials is True:
            self._take_materials(compiled)
        elif materials is not False and len(materials):
            self._take_materials(compiled, materials)
        if lights:
            self._take_lights(compiled)
        self._describe(compiled)
        return meshes_changed

    def _object_rows(self, compiled: CompiledScene, prims: np.ndarray, objects: np.ndarray) -> None:
        """The boxes and boundedness of these top-level objects, from their primitives' rows ``prims``: the
        plain shapes at once, each boolean by walking its tree."""
        table, a = compiled.table, self.arrays
        object_box, bounded = a["object_box"].reshape(-1, 6), a["object_bounded"]
        index = compiled.objects.primitive_index[objects]
        plain = index >= 0
        rows = index[plain]
        object_box[objects[plain]] = _object_boxes(table, rows)
        bounded[objects[plain]] = _BOUNDED[table.kind[rows]]
        if plain.all():
            return
        # (the padded boxes of the booleans' rows, by row: _box reads them by primitive index)
        padded = _padded_boxes(table, prims)
        lo, hi = dict(zip(prims.tolist(), padded[:, :3])), dict(zip(prims.tolist(), padded[:, 3:]))
        prim_bounded = dict(zip(prims.tolist(), _BOUNDED[table.kind[prims]].tolist()))
        for k in objects[~plain].tolist():
            box = _box(compiled.objects.booleans[k], lo, hi, prim_bounded)
            bounded[k] = box is not None
            if box is not None:
                object_box[k] = _single_box(box)

    def _drop_unused_meshes(self, table: PrimitiveTable) -> bool:
        """Drop the meshes no primitive refers to any more (renumbering the others); whether any was."""
        aux = self.arrays["prim_aux"].reshape(-1, 2)
        rows = np.flatnonzero(self.arrays["prim_kind"][:len(table)] == KIND_CODES["mesh"])
        used = np.zeros(len(self._meshes), dtype=bool)
        used[aux[rows, 0]] = True
        if used.all():
            return False
        renumber = np.cumsum(used) - 1
        aux[rows, 0] = renumber[aux[rows, 0]]
        kept = np.flatnonzero(used).tolist()
        self._meshes = [self._meshes[k] for k in kept]
        self._mesh_owners = [self._mesh_owners[k] for k in kept]
        self._mesh_index = {id(mesh): number for number, mesh in enumerate(self._mesh_owners)}
        return True

    def _flatten_textures(self, compiled: CompiledScene, rows: Optional[np.ndarray] = None) -> int:
        """Per-material texture numbers, parameters (defaults filled in as tracer.textures does) and image
        indices; the pictures (by address: each is already one contiguous array, no copy); the noise
        tables.  Nothing for a scene without textures.  With ``rows`` (tracer.edit: the pictures and the
        number of materials as they were), only those materials' rows.  Returns the number of pictures."""
        a = self.arrays
        if "textures" not in compiled.effects:  # the C core never reads these tables then
            return 0
        # deferred: the textures (and the noise tables made as they load) wait for the first textured scene
        from ..textures.noise import GRADIENTS, PERM
        images = getattr(compiled.textures, "images", None) or {}
        numbers = sorted(images)
        materials = compiled.materials.materials
        if rows is not None:
            self._texture_rows(materials, rows, numbers)
            return len(numbers)
        pictures = [np.ascontiguousarray(images[k], dtype=np.uint8) for k in numbers]  # 8-bit, as loaded
        a.update(mat_texture=np.zeros(len(materials), dtype=np.int32), mat_tex_param=np.zeros((len(materials), TEX_PARAMS)),
                 mat_tex_image=np.full(len(materials), -1, dtype=np.int64))
        # (only the textured materials' rows differ from those defaults: 10^5 materials of their own colours
        # are not each looked at in Python)
        self._texture_rows(materials, np.flatnonzero(compiled.materials.texture != 0).tolist(), numbers)
        self._pictures = pictures  # the C side points into these
        a.update(image_info=[(p.shape[1], p.shape[0]) for p in pictures],
                 image_data=np.array([p.ctypes.data for p in pictures], dtype=np.uintp),
                 noise_perm=PERM, noise_gradients=GRADIENTS)
        return len(pictures)

    def _texture_rows(self, materials, rows, numbers: list[int]) -> None:
        """The texture tables' rows of these materials (``numbers``: the pictures' texture numbers, in order)."""
        # deferred: (as in _flatten_textures)
        from ..textures import image_repeats
        from ..textures.solid import SOLID_DEFAULTS, with_defaults

        a = self.arrays
        texture, image_index = a["mat_texture"], a["mat_tex_image"]
        params = a["mat_tex_param"].reshape(-1, TEX_PARAMS)
        for m in list(rows):
            material = materials[m]
            number = int(material.texture)
            texture[m] = number
            image_index[m] = -1
            if number < 0 and number in SOLID_DEFAULTS:
                values = with_defaults(tuple(material.parameters), SOLID_DEFAULTS[number])
            elif number > 0:
                values = image_repeats(material.parameters)
                image_index[m] = numbers.index(number) if number in numbers else -1
            else:
                values = ()
            params[m] = 0.0
            params[m, :len(values)] = values

    @staticmethod
    def _mesh_constants(meshes) -> tuple:
        if not meshes:
            return (0.0,) * 5
        return tuple(float(getattr(mesh_module, name)) for name in MESH_CONSTANTS)

    def _flatten_meshes(self, meshes: list[MeshArrays]) -> None:
        """Per mesh, its counts and the addresses of its own arrays (nothing is copied: the C core reads
        the arrays the NumPy path reads; self.arrays keeps them alive)."""
        a = self.arrays
        a["mesh_info"] = [(len(m.nodes), len(m.tri_order), len(m.vertices), len(m.normals)) for m in meshes]
        a["mesh_extent"] = [float(m.extent) for m in meshes]
        a["mesh_generic_size"] = [self._generic_sizes.get(id(mesh), 1.0) for mesh in self._mesh_owners]
        kept = []
        for field, column in MESH_ADDRESSES.items():
            arrays = [getattr(m, column) for m in meshes]
            checked = [None if x is None else np.ascontiguousarray(x, dtype=MESH_DTYPES[column]) for x in arrays]
            kept += [x for x in checked if x is not None]
            a[field] = np.array([0 if x is None else x.ctypes.data for x in checked], dtype=np.uintp)
        self._mesh_arrays = kept  # the C side points into these
