"""Blender's evaluated scene as a tracer Scene, for rendering (Blender's axes) and for export (SDL's axes).

* An object whose mesh is an unedited generic shape (see meshes.generic_info), with no enabled modifiers
  but Booleans, is that exact shape: its transform is the exact one kept at import while Blender still
  shows it, else its world matrix (times the rotation baked into a sheared shape's mesh).
* Its Boolean modifiers become CSG, in modifier order: ``left op operand`` where the operand is whatever
  object (or collection of objects, folded with the same operation) the modifier names, itself a shape,
  a CSG or a mesh.
* Anything else that has geometry is traced as the triangles Blender makes of its evaluated mesh, one
  tracer mesh per material slot.
* Lights: see blender_lights (SDL's lights stay SDL's; Blender's are physical lights in Blender's units).
* Materials: SDL's values where SDL Material is ticked, else the shader nodes' (shader_nodes, pure/whitted).
* A material's texture above 0 is its own image (Material.sdl.image), numbered per image: its own number
  unless an earlier material's other image has it (two imported files may both use ``makePixmap 1``).
"""
from __future__ import annotations

import dataclasses
import itertools
from array import array
import math
import os
from typing import Optional

import bpy
import numpy as np

from . import blender_lights, images, meshes, object_cache, props
from .pure import convert
from .tracer import errors, model
from .tracer.compile import row_chunks
from .tracer.shapes import KINDS
from .tracer.model import FaceList, MeshData

BOOLEAN_OPS = {"UNION": "union", "INTERSECT": "intersection", "DIFFERENCE": "difference"}
SDL_TO_BOOLEAN = {v: k for k, v in BOOLEAN_OPS.items()}
GEOMETRY_TYPES = {"MESH", "CURVE", "SURFACE", "META", "FONT"}

#: Custom properties on an imported object.
OBJ_KIND, OBJ_PARAM, OBJ_FILE = "sdl_kind", "sdl_param", "sdl_mesh_file"
OBJ_MATRIX, OBJ_SHOWN, OBJ_ORDER = "sdl_matrix", "sdl_matrix_shown", "sdl_order"


def matrix_np(matrix) -> np.ndarray:
    return np.array([list(row) for row in matrix], dtype=np.float64)


def flat(matrix) -> list[float]:
    return [float(v) for row in matrix for v in row]


def enabled_modifiers(obj, mode: str = "RENDER") -> list:
    """The object's modifiers enabled in ``mode`` (the viewport's switch in VIEWPORT, else the render's).
    A generic shape with any of them but Booleans is traced as a mesh."""
    if mode == "VIEWPORT":
        return [m for m in obj.modifiers if m.show_viewport]
    return [m for m in obj.modifiers if m.show_render]


class SceneBuilder:
    """Builds tracer objects from evaluated Blender objects.

    ``mode`` is ``RENDER`` (final render: modifiers enabled for rendering), ``VIEWPORT`` (modifiers enabled
    in the viewport) or ``EXPORT`` (modifiers enabled for rendering, polygons kept as polygons, ``mesh``
    files referenced); which objects there are is the depsgraph's (and ``build``'s options).  ``to_target``
    maps Blender's world to the output frame (identity for rendering, Blender -> SDL axes for export).
    What is made from an object's geometry goes through ``cache`` (object_cache.ObjectCache): the engine
    passes its own, kept between builds; by default a new one, so that instances of an object share it.
    """

    def __init__(self, depsgraph, mode: str = "RENDER", to_target: Optional[np.ndarray] = None,
                 cache: Optional[object_cache.ObjectCache] = None):
        self.depsgraph = depsgraph
        self.mode = mode
        self.cache = object_cache.ObjectCache() if cache is None else cache
        self.to_target = np.eye(4) if to_target is None else np.asarray(to_target, dtype=np.float64)
        self.model = model
        self.warnings: list[str] = []
        self._generic_cache: dict = {}
        #: id(shape) -> the Blender object's name, for each mesh shape (the exporter names mesh files by it)
        self.mesh_object_names: dict[int, str] = {}
        self._materials: dict = {}
        self._pixmaps: dict[str, int] = {}  # image file -> its texture number in the built scene
        self._uv_materials: set[int] = set()  # materials whose picture is looked up through the UV map

    def refresh(self, depsgraph, materials=()) -> list[tuple]:
        """Make this builder ready to build some objects again (the add-on's live scene keeps one builder,
        so that the objects it makes share their tracer materials with those it made before): the depsgraph
        now, and ``materials`` (Blender materials that were edited) made anew.  Returns (old, new) for each
        of those whose tracer material changed; one that did not keeps its tracer material."""
        self.depsgraph = depsgraph
        self.warnings = []
        self._generic_cache.clear()
        changed = []
        for material in materials:
            pointer = material.original.as_pointer()
            old = self._materials.pop(pointer, None)
            try:
                material = material.evaluated_get(depsgraph)
            except (ReferenceError, RuntimeError):
                pass
            new = self._material(material)
            if old is not None and new == old:
                self._materials[pointer] = old
            elif old is not None:
                changed.append((old, new))
        return changed

    @property
    def pixmaps(self) -> dict:
        """Image file -> its texture number, for the images the built objects use."""
        return dict(self._pixmaps)

    # -- helpers --------------------------------------------------------------------------------------

    def _material(self, material):
        key = _material_key(material)
        if key not in self._materials:
            if material is not None and not material.sdl.use_sdl:  # Blender's own: its shader nodes
                sdl_material, picture = props.blender_material(material, self.warnings)
                image = ""
                if picture is not None:  # (a picture on Base Color, looked up through the UV map)
                    self._uv_materials.add(key)
                    sdl_material = dataclasses.replace(sdl_material, texture=1)
                    image = picture.path
                    if picture.datablock is not None:  # packed or generated: a file made of its pixels
                        image = self._pixels_file(material, picture)
                        if not image:  # (said why; drawn in its colour)
                            sdl_material = dataclasses.replace(sdl_material, texture=0)
                    elif picture.srgb and self.mode != "EXPORT" and os.path.isfile(image):
                        image = images.linear_copy(image)  # (as Cycles reads it; SDL keeps the file's values)
            else:
                sdl_material = props.material_to_sdl(material)
                image = material.sdl.image if material is not None and material.sdl.image else ""
                image = bpy.path.abspath(image, library=material.library) if image else ""
            if sdl_material.texture > 0:
                if os.path.isfile(image):
                    number = self._pixmap_number(sdl_material.texture, image)
                else:  # drawn with its own colours, as a lenient read draws it, and said
                    number = 0
                    self.warnings.append(f"{material.name}: texture image {image or '(none)'} not found: "
                                         "drawn without it")
                sdl_material = dataclasses.replace(sdl_material, texture=number)
            self._materials[key] = sdl_material
        return self._materials[key]

    def _pixels_file(self, material, picture) -> str:
        """The file the tracer reads for a picture that has none of its own (packed or generated): its pixels
        (made linear where Cycles would) in a temporary file; an export gets none, and says so."""
        if self.mode == "EXPORT":  # (an exported scene must name a file that stays: unpack the image first)
            self.warnings.append(f"{material.name}: {picture.datablock.name} is "
                                 f"{'packed' if picture.datablock.packed_file is not None else 'generated'}: "
                                 "exported without it (save or unpack the image to export it)")
            return ""
        try:
            return images.pixels_copy(picture.datablock, linear=picture.srgb)
        except errors.TracerError as err:
            self.warnings.append(f"{material.name}: {err}: drawn without it")
            return ""

    def _pixmap_number(self, wanted: int, image: str) -> int:
        """The scene's number for a material's image: its own number unless another image has it (materials
        of different files may use the same number for different images), else the first free one."""
        if image not in self._pixmaps:
            used = set(self._pixmaps.values())
            if wanted in used:
                wanted = next(n for n in itertools.count(1) if n not in used)
            self._pixmaps[image] = wanted
        return self._pixmaps[image]

    def _slot_material(self, obj, index: int = 0):
        slots = obj.material_slots
        if 0 <= index < len(slots):
            return self._material(slots[index].material)
        return self._material(None)

    def _target(self, world_matrix: np.ndarray) -> np.ndarray:
        return self.to_target @ world_matrix

    def _evaluated(self, obj):
        if getattr(obj, "is_evaluated", False):  # (an instance's own object: its original may be its instancer)
            return obj
        try:
            return obj.evaluated_get(self.depsgraph)
        except (RuntimeError, ReferenceError):
            return obj

    def _usable(self, matrix: np.ndarray, name: str) -> bool:
        linear = matrix[:3, :3]
        if not np.all(np.isfinite(matrix)):
            self.warnings.append(f"{name}: skipped, its transform is not finite")
            return False
        det = np.linalg.det(linear)
        if det == 0.0 or not np.isfinite(det) or np.linalg.cond(linear) > 1e12:
            self.warnings.append(f"{name}: skipped, its transform is singular (a scale of 0?)")
            return False
        return True

    # -- objects --------------------------------------------------------------------------------------

    def generic(self, obj, own: bool = True):
        """Generic-shape info of an object's own mesh (None if not an unedited generic shape)."""
        original = obj.original if hasattr(obj, "original") else obj
        if original.type != "MESH":
            return None
        return self.cache.get(obj, "generic", lambda: meshes.generic_info(original.data, self._generic_cache),
                              own)

    def shape_matrix(self, obj, matrix_world: np.ndarray, info) -> np.ndarray:
        """World matrix of the generic shape (Blender axes), exact while the object is where import put it."""
        original = obj.original if hasattr(obj, "original") else obj
        exact, shown = original.get(OBJ_MATRIX), original.get(OBJ_SHOWN)
        if exact is not None and shown is not None and convert.unchanged(matrix_world, list(shown)):
            return np.array(list(exact), dtype=np.float64).reshape(4, 4)
        return matrix_world @ info.mesh_matrix

    def object_node(self, obj, matrix_world: Optional[np.ndarray] = None, top_level: bool = True,
                    visiting: Optional[set] = None, own: bool = True):
        """Tracer object(s) for one evaluated object: a list (a mesh may give one per material).  ``own`` is
        False for an instance made by geometry nodes (see ObjectCache.get)."""
        obj_eval = self._evaluated(obj)
        if matrix_world is None:
            matrix_world = matrix_np(obj_eval.matrix_world)
        original = obj_eval.original
        visiting = set() if visiting is None else visiting
        if original.name in visiting:
            self.warnings.append(f"{original.name}: Boolean operands form a loop; traced as a mesh")
            return self.mesh_nodes(obj_eval, matrix_world, top_level)
        info = self.generic(obj_eval, own) if own else None  # (an instance is not its instancer's shape)
        enabled = enabled_modifiers(original, self.mode) if info is not None else []
        if info is None or any(m.type != "BOOLEAN" for m in enabled):
            return self.mesh_nodes(obj_eval, matrix_world, top_level, own)
        matrix = self.shape_matrix(original, matrix_world, info)
        if not self._usable(matrix, original.name):
            return []
        node = self.leaf_shape(original, obj_eval, matrix, info, own)
        visiting = visiting | {original.name}
        for modifier in enabled:
            operands = []
            if getattr(modifier, "operand_type", "OBJECT") == "COLLECTION":
                if modifier.collection is not None:
                    operands = [o for o in modifier.collection.all_objects if o.type in GEOMETRY_TYPES]
            elif modifier.object is not None:
                operands = [modifier.object]
            for operand in operands:
                right = self.object_node(operand, None, top_level=False, visiting=visiting)
                if not right:
                    continue
                node = self.model.CSG(BOOLEAN_OPS[modifier.operation], node, right[0])
        return [node]

    def leaf_shape(self, original, obj_eval, matrix: np.ndarray, info, own: bool = True):
        kind = info.kind
        shape = self.model.Shape(kind, matrix=self._target(matrix), material=self._slot_material(obj_eval),
                                 parameters=info.parameters, name=original.name)
        if KINDS[kind].family != "analytic":  # (polyhedra, the teapot, meshes)
            data = self.cache.get(obj_eval, "exact mesh", lambda: meshes.exact_mesh_data(info, original.data), own)
            if data is None:  # a mesh file that is gone: Blender's copy, in the mesh's own frame
                data = self.cache.get(obj_eval, f"mesh {self.mode}",
                                      lambda: self._blender_mesh(original.data), own)[0]
                shape.matrix = self._target(matrix @ np.linalg.inv(info.mesh_matrix))
            elif kind == "mesh" and self.mode == "EXPORT":
                shape.mesh_file = info.mesh_file
            shape.mesh = data
            self.mesh_object_names[id(shape)] = original.name
        return shape

    def _blender_mesh(self, mesh, name: Optional[str] = None, uvs: bool = False) -> dict:
        """A Blender mesh as tracer meshes, one per material: polygons for export, else triangles (with their
        corners' UVs where ``uvs``)."""
        name = mesh.name if name is None else name
        return polygon_meshes(mesh) if self.mode == "EXPORT" else meshes.triangle_meshes(mesh, name, uvs)

    def _evaluated_mesh(self, obj_eval, uvs: bool = False) -> dict:
        """_blender_mesh of the object's evaluated geometry (modifiers applied; curves and text as meshes)."""
        try:
            mesh = obj_eval.to_mesh()
        except RuntimeError:
            mesh = None
        if mesh is None:
            return {}
        try:
            return self._blender_mesh(mesh, obj_eval.name, uvs)
        finally:
            obj_eval.to_mesh_clear()

    def mesh_parts(self, obj_eval, own: bool = True) -> list[tuple]:
        """(tracer mesh, tracer material) of each material of an object's evaluated geometry."""
        # (the UV map is read only for a material with a picture on it)
        uvs = any(self._material(slot.material) is not None and _material_key(slot.material) in self._uv_materials
                  for slot in obj_eval.material_slots)
        kind = f"evaluated mesh {self.mode}" + (" with UVs" if uvs else "")
        parts = self.cache.get(obj_eval, kind, lambda: self._evaluated_mesh(obj_eval, uvs), own)
        return [(data, self._slot_material(obj_eval, index)) for index, data in sorted(parts.items())]

    def mesh_nodes(self, obj_eval, matrix_world: np.ndarray, top_level: bool, own: bool = True) -> list:
        if obj_eval.type not in GEOMETRY_TYPES:
            return []
        if not self._usable(matrix_world, obj_eval.name):
            return []
        shapes = [self.model.Shape("mesh", matrix=self._target(matrix_world), mesh=data, material=material)
                  for data, material in self.mesh_parts(obj_eval, own)]
        if not top_level and len(shapes) > 1:
            # A Boolean operand is one solid: keep it whole, with its first material.
            merged = self.cache.get(obj_eval, f"merged mesh {self.mode}",
                                    lambda: merge_mesh_data([s.mesh for s in shapes], self.model.MeshData), own)
            shapes = [self.model.Shape("mesh", matrix=self._target(matrix_world), mesh=merged,
                                       material=shapes[0].material)]
        for shape in shapes:
            shape.name = obj_eval.original.name
            self.mesh_object_names[id(shape)] = obj_eval.original.name
        return shapes

    # -- the scene ------------------------------------------------------------------------------------

    def light(self, obj_eval, matrix_world: np.ndarray):
        samples = self.depsgraph.scene.sdl_render.light_samples if hasattr(self.depsgraph.scene, "sdl_render") else 16
        light = blender_lights.tracer_light(obj_eval, matrix_world, self.to_target, samples, self.warnings)
        if self.mode == "EXPORT" and light.switched:  # (SDL has no words for them)
            self.warnings.append(f"{light.name}: Cast Shadow and Ray Visibility are not written: the light is "
                                 f"written as one that casts shadows and every ray sees")
        return light

    def build(self, scene, instances=None, skip_hidden_render: bool = False, selected_only: bool = False):
        """The tracer Scene of everything the depsgraph shows (its object instances).  Where geometry nodes
        make instances (and nothing needs the objects one by one: a Boolean, an export), the objects are a
        ShapeTable: a row per instance and material, no Python object per instance."""
        self.cache.begin_build(self.depsgraph)
        rows = self.mode != "EXPORT"  # (an export writes each instance's mesh file name: Shapes)
        # Geometry nodes' instances read through their instancer's geometry where Blender has that (4.3+):
        # only for rows, over the whole depsgraph (the reader counts each instancer's instances in order)
        reader = _GeometryInstances() if rows and instances is None else None
        warned = len(self.warnings)
        made, lights, later = self._gather(instances, skip_hidden_render, selected_only, rows, reader)
        if reader is not None and not reader.consistent():  # (never seen: a safety net) the plain reading
            del self.warnings[warned:]
            made, lights, later = self._gather(instances, skip_hidden_render, selected_only, rows, None)
        for key, obj, matrix, edit_key in later:
            made.append((key, self.object_node(obj, matrix), edit_key))
        made = self._runs_placed(made)
        made.sort(key=lambda entry: entry[0])
        objects = self._objects(made)
        #: for each object, the original Blender object's pointer, or ("instance", n) for an instance (the add-on's
        #: live scene edits objects by these keys: addon/live_scene.py)
        self._keys = [(nodes if isinstance(nodes, _InstanceRun) else len(nodes), edit_key) for _, nodes, edit_key in made]
        lights.sort(key=lambda entry: entry[0])
        self.light_objects = [obj for _, obj, _ in lights]  # (likewise, the lights' objects)
        lights = [self.light(obj, matrix) for _, obj, matrix in lights]
        self.cache.end_build()
        world = scene.world
        settings = props.world_settings(world, scene.sdl_render.max_recursion_depth
                                        if hasattr(scene, "sdl_render") else 3, self.warnings)
        tracer_scene = model.Scene(objects=objects, lights=lights, settings=settings)
        tracer_scene.pixmaps = {number: image for image, number in self._pixmaps.items()}
        return tracer_scene

    def _gather(self, instances, skip_hidden_render: bool, selected_only: bool, rows: bool, reader):
        """One pass over the depsgraph's object instances: (made, lights, later) for build, each entry
        (sort key, ...): import order first (so that files round-trip in their own order), then by name, then
        as the depsgraph listed them; an _InstanceRun stands for the rows of consecutive instances of one
        instancer.  ``reader`` (a _GeometryInstances, or None) gives the geometry-nodes instances it can read
        without their objects."""
        made: list[tuple[tuple, object, object]] = []
        lights: list[tuple[tuple, object, np.ndarray]] = []
        later: list[tuple[tuple, object, np.ndarray, object]] = []
        self._templates: dict[tuple, int] = {}
        self._template_parts: list[tuple] = []
        for count, inst in enumerate(instances if instances is not None else self.depsgraph.object_instances):
            instancer = reader.instancer(inst) if reader is not None and inst.is_instance else None
            if instancer is not None:  # (its object is not read: bpy would keep ~120 bytes for each read)
                self._read_instance(made, count, inst, instancer, skip_hidden_render, selected_only)
                continue
            obj = inst.object  # (for an instance, Blender's one object that each instance in turn is)
            original = obj.original
            # (an instance shows, as Blender renders it, while its instancer does, whether its object does or
            # not: a particle's or collection's source object is often hidden)
            hidden = inst.parent is not None and inst.parent.original.hide_render if inst.is_instance else \
                original.hide_render
            if skip_hidden_render and hidden:
                continue
            if not inst.is_instance and not getattr(inst, "show_self", True):
                continue  # an instancer that does not show itself (Show Instancer off; particles, vertices...)
            if selected_only and not (inst.is_instance and inst.parent and inst.parent.original.select_get()) \
                    and not original.select_get():
                continue
            # An instance whose original is its instancer was made by geometry nodes: its geometry is not that
            # object's, and only ``inst.object`` carries it, until the iteration moves on: made now.
            if inst.is_instance and inst.parent is not None and \
                    original.as_pointer() == inst.parent.original.as_pointer():
                if obj.type not in GEOMETRY_TYPES:
                    continue
                if rows:
                    run = made[-1][1] if made else None
                    if not (isinstance(run, _InstanceRun) and run.pointer == original.as_pointer()):
                        run = _InstanceRun(original.as_pointer())
                        made.append(((original.get(OBJ_ORDER, math.inf), original.name, count), run, None))
                    run.add(count, inst.matrix_world, self._instance_template(obj))
                else:
                    made.append(((original.get(OBJ_ORDER, math.inf), original.name, count),
                                 self.object_node(obj, matrix_np(inst.matrix_world), own=False), ("instance", count)))
                continue
            key = (original.get(OBJ_ORDER, math.inf), original.name, count)
            if rows and inst.is_instance and obj.type in GEOMETRY_TYPES and self.generic(obj) is None:
                # particles, collection instances, instancing by vertices or faces: a mesh's instances are rows
                # of a run, as geometry nodes' are (a generic shape stays a Shape: its kind is not a mesh)
                pointer = (inst.parent.original.as_pointer() if inst.parent is not None else 0,
                           original.as_pointer())
                run = made[-1][1] if made else None
                if not (isinstance(run, _InstanceRun) and run.pointer == pointer):
                    run = _InstanceRun(pointer)
                    made.append((key, run, None))
                run.add(count, inst.matrix_world, self._instance_template(obj, own=True))
                continue
            matrix = matrix_np(inst.matrix_world)
            stable = inst.instance_object if inst.is_instance else obj  # (the instanced object itself)
            if obj.type == "LIGHT":
                lights.append((key, stable, matrix))
            elif obj.type in GEOMETRY_TYPES:
                later.append((key, stable, matrix, ("instance", count) if inst.is_instance else
                              original.as_pointer()))
        return made, lights, later

    def _read_instance(self, made: list, count: int, inst, instancer: "_Instancer", skip_hidden_render: bool,
                       selected_only: bool) -> None:
        """A geometry-nodes instance that ``instancer`` reads: its row of the instancer's run, as _gather
        makes it, its object read only for the first instance of each geometry (its template)."""
        matrix_world = inst.matrix_world  # (Blender's float32 product, as the plain reading has it)
        reference = instancer.next(matrix_world)
        original = instancer.original
        if skip_hidden_render and original.hide_render or selected_only and not original.select_get():
            return
        template = instancer.templates.get(reference)
        if template is None:
            template = instancer.templates[reference] = self._instance_template(inst.object)
        run = made[-1][1] if made else None
        if not (isinstance(run, _InstanceRun) and run.pointer == instancer.pointer):
            run = _InstanceRun(instancer.pointer)
            made.append(((original.get(OBJ_ORDER, math.inf), original.name, count), run, None))
        run.add(count, matrix_world, template)

    @property
    def object_keys(self) -> list:
        """Per object of the last build, in order: its original Blender object's pointer, or ("instance", n)."""
        return [key for made, edit_key in self._keys
                for key in (made.keys() if isinstance(made, _InstanceRun) else [edit_key] * made)]

    def _instance_template(self, obj, own: bool = False) -> int:
        """The number of what an instance is made of (its meshes and materials, the names it goes by): the same
        for every instance of one evaluated geometry with the same materials.  ``own``: the instance is an
        object's own geometry (a particle, a collection instance: its meshes are the object's, read once for
        both), not one geometry nodes made."""
        slots = tuple(_material_key(slot.material) for slot in obj.material_slots)
        data = obj.data
        key = (data.as_pointer() if data is not None else id(obj), slots, obj.name, own)
        number = self._templates.get(key)
        if number is None:
            number = self._templates[key] = len(self._template_parts)
            self._template_parts.append((self.mesh_parts(obj, own=own), obj.name, obj.original.name))
        return number

    def _runs_placed(self, made: list) -> list:
        """``made`` with each run of instances checked (their matrices: the unusable ones skipped, with a
        warning each) and turned into rows; a run with another entry of its object's sort key between its first
        and last instance (in the depsgraph's order) is made into its instances' entries, so that sorting puts
        each where it was."""
        others: dict[tuple, list[int]] = {}  # (order, name) -> the counts of the other entries of that object
        for key, nodes, _ in made:
            if nodes and not isinstance(nodes, _InstanceRun):
                others.setdefault(key[:2], []).append(key[2])
        out = []
        for key, nodes, edit_key in made:
            if isinstance(nodes, _InstanceRun):
                nodes.finish(self)
                first, last = (int(nodes.counts[0]), int(nodes.counts[-1])) if len(nodes.counts) else (0, 0)
                if any(first < count < last for count in others.get(key[:2], ())):
                    out += [((key[0], key[1], count), shapes, ("instance", count))
                            for count, shapes in nodes.shapes_by_instance(self)]
                    continue
            out.append((key, nodes, edit_key))
        return out

    def _objects(self, made: list):
        """The scene's objects: a ShapeTable where there are runs of instances and every other object can be
        a row of it, else a list."""
        runs = [nodes for _, nodes, _ in made if isinstance(nodes, _InstanceRun)]
        if runs and all(model.TableRows.can_hold(node) for _, nodes, _ in made
                        if not isinstance(nodes, _InstanceRun) for node in nodes):
            rows = model.TableRows()
            for _, nodes, _ in made:
                if isinstance(nodes, _InstanceRun):
                    nodes.put(rows, self)
                else:
                    for node in nodes:
                        rows.add_shape(node)
            return rows.table()
        objects = []
        for _, nodes, _ in made:
            if isinstance(nodes, _InstanceRun):
                for _, shapes in nodes.shapes_by_instance(self):
                    objects += shapes
            else:
                objects += nodes
        return objects


class _InstanceRun:
    """Consecutive geometry-nodes instances of one instancer, or instances of one mesh object by one instancer
    (particles, collection instances, instancing by vertices or faces): per instance its count in the
    depsgraph's iteration (its edit key), its matrix and its template (SceneBuilder._instance_template),
    gathered as numbers, not objects."""

    def __init__(self, pointer):
        self.pointer = pointer  # (the instancer's original object; with the instanced object's, a pair)
        self.counts = array("q")
        self.templates = array("i")
        self.matrices = array("f")  # 16 per instance, row after row (Blender's are float32: held exactly)

    def add(self, count: int, matrix_world, template: int) -> None:
        self.counts.append(count)
        self.templates.append(template)
        for row in matrix_world:
            self.matrices.extend(row)

    def finish(self, builder: SceneBuilder) -> None:
        """Drop the instances whose matrix cannot be traced, as SceneBuilder._usable does (its warnings, in
        order), and keep each one's matrix in the output frame."""
        world = np.frombuffer(self.matrices, dtype=np.float32).reshape(-1, 4, 4)
        usable = np.empty(len(world), dtype=bool)
        for rows in row_chunks(len(world)):  # (float64 a chunk at a time: the tests as _usable makes them)
            usable[rows] = usable_matrices(world[rows].astype(np.float64))
        for k in np.flatnonzero(~usable).tolist():  # (few: their messages, one by one)
            builder._usable(world[k].astype(np.float64), builder._template_parts[self.templates[k]][1])
        kept = np.flatnonzero(usable)
        self.counts = np.frombuffer(self.counts, dtype=np.int64)[kept]
        self.templates = np.frombuffer(self.templates, dtype=np.int32)[kept]
        self.target = _products(builder.to_target, world, kept)  # (the products Shape's matrix had)
        self.matrices = None
        parts = builder._template_parts
        self.part_counts = np.array([len(parts[t][0]) for t in range(len(parts))], dtype=np.int64)[self.templates]

    def _row_instances(self) -> np.ndarray:
        """Per row (an instance's material, in the order of its parts), the instance's position in the run."""
        return np.repeat(np.arange(len(self.templates)), self.part_counts)

    def keys(self) -> list:
        return [("instance", count) for count in self.counts[self._row_instances()].tolist()]

    def put(self, rows: "model.TableRows", builder: SceneBuilder) -> None:
        """The run's rows, in order (each instance's parts together)."""
        numbers = [[rows.part("mesh", data, material, name=name) for data, material in parts]
                   for parts, _, name in builder._template_parts]
        offsets = np.cumsum([0] + [len(n) for n in numbers])
        flat = np.array([k for n in numbers for k in n], dtype=np.int32)
        instance = self._row_instances()
        first_row = np.repeat(np.cumsum(self.part_counts) - self.part_counts, self.part_counts)
        part_index = np.arange(len(instance)) - first_row
        one_each = len(instance) == len(self.target)  # (a part per instance: the rows are the instances)
        rows.add_block(self.target if one_each else self.target[instance],
                       flat[offsets[self.templates[instance]] + part_index])
        self.target = None  # (the table has them)

    def shapes_by_instance(self, builder: SceneBuilder):
        """(count, its Shapes) of each instance, as SceneBuilder.mesh_nodes makes them."""
        for count, template, matrix in zip(self.counts.tolist(), self.templates.tolist(), self.target):
            parts, _, name = builder._template_parts[template]
            shapes = [builder.model.Shape("mesh", matrix=matrix.astype(np.float64), mesh=data, material=material,
                                          name=name) for data, material in parts]
            for shape in shapes:
                builder.mesh_object_names[id(shape)] = name
            yield count, shapes
        self.target = None


class _GeometryInstances:
    """The geometry-nodes instances that can be read without their objects (Blender 4.3+: an evaluated
    object's ``evaluated_geometry()``): for each instancer met, an _Instancer, or None where its instances
    must be read one object at a time (older Blender; references to objects, collections or nested
    instances; other instancing on the object)."""

    def __init__(self):
        self._instancers: dict[int, Optional[_Instancer]] = {}

    def instancer(self, inst) -> Optional["_Instancer"]:
        """The _Instancer that reads this depsgraph instance, or None."""
        parent = inst.parent
        if parent is None:
            return None
        pointer = parent.original.as_pointer()
        if pointer not in self._instancers:
            self._instancers[pointer] = _Instancer.of(parent)
        return self._instancers[pointer]

    def consistent(self) -> bool:
        """Whether every instancer met its instances as its geometry lists them (see _Instancer.consistent)."""
        return all(instancer is None or instancer.consistent() for instancer in self._instancers.values())


#: The components of a geometry that Blender draws as instances of their own (besides an instance list)
_OTHER_COMPONENTS = ("pointcloud", "curves", "volume", "grease_pencil")


class _Instancer:
    """A mesh object whose geometry nodes make instances of meshes (geometries holding a mesh and nothing
    else): the depsgraph lists its instances in the order of its instance list, so the n-th instance met
    is the list's n-th, and its geometry is the n-th reference index's.  Bytes kept per instance: none
    but the 12 of its translation (for ``consistent``) until the build ends."""

    def __init__(self, original, world: np.ndarray, references: np.ndarray, translations: np.ndarray):
        self.original = original
        self.pointer = original.as_pointer()
        self.world = world  # (the instancer's world matrix)
        self.references = references  # (per instance, its geometry's number)
        self.translations = translations  # (per instance, in the instancer's frame)
        self.met = array("f")  # (the translation of each instance met, as the depsgraph gave it)
        self.templates: dict[int, int] = {}  # reference -> SceneBuilder template

    @classmethod
    def of(cls, parent) -> Optional["_Instancer"]:
        original = parent.original
        if not hasattr(parent, "evaluated_geometry") or parent.type != "MESH" or \
                original.instance_type != "NONE" or len(original.particle_systems):
            return None
        try:
            geometry = parent.evaluated_geometry()
        except (RuntimeError, ReferenceError):  # (not evaluated, or gone: read one object at a time)
            return None
        cloud = geometry.instances_pointcloud()
        if cloud is None or any(getattr(geometry, name, None) is not None for name in _OTHER_COMPONENTS):
            return None
        for reference in geometry.instance_references():
            if type(reference).__name__ != "GeometrySet" or reference.mesh is None or \
                    reference.instances_pointcloud() is not None or \
                    any(getattr(reference, name, None) is not None for name in _OTHER_COMPONENTS):
                return None
        count = len(cloud.points)
        references = np.zeros(count, dtype=np.int32)
        if ".reference_index" in cloud.attributes:
            cloud.attributes[".reference_index"].data.foreach_get("value", references)
        transforms = np.empty(count * 16, dtype=np.float32)
        cloud.attributes["instance_transform"].data.foreach_get("value", transforms)
        translations = transforms.reshape(count, 4, 4)[:, 3, :3].copy()  # (stored column after column)
        return cls(original, matrix_np(parent.matrix_world), references, translations)

    def next(self, matrix_world) -> int:
        """The reference number of the next instance met, whose world matrix is ``matrix_world``."""
        met = len(self.met) // 3
        self.met.extend((matrix_world[0][3], matrix_world[1][3], matrix_world[2][3]))
        return int(self.references[met]) if met < len(self.references) else 0

    def consistent(self) -> bool:
        """Whether the instances met were the instance list's, one for one, in its order: as many, each at
        its own place (its translation, to float32's rounding of the instancer's matrix product)."""
        met = np.frombuffer(self.met, dtype=np.float32).reshape(-1, 3).astype(np.float64)
        if len(met) != len(self.references):
            return False
        expected = self.translations @ self.world[:3, :3].T + self.world[:3, 3]
        scale = 1.0 + np.abs(expected).max(initial=0.0) + np.abs(self.world).max()
        return bool(np.all(np.abs(met - expected) <= 1e-5 * scale))


def _products(to_target: np.ndarray, world: np.ndarray, kept: np.ndarray) -> np.ndarray:
    """``to_target @ world[kept]`` as float64 products (what a Shape's matrix is), a chunk at a time, kept as
    float32 while every entry is one (Blender's float32 matrices under a render's identity), else float64:
    64 bytes an instance, not 128 and a float64 copy of each matrix besides."""
    out = np.empty((len(kept), 4, 4), dtype=np.float32)
    for rows in row_chunks(len(kept)):
        product = np.matmul(to_target, world[kept[rows]].astype(np.float64))
        if out.dtype == np.float32 and not np.array_equal(product.astype(np.float32), product):
            out = out.astype(np.float64)
        out[rows] = product
    return out


def usable_matrices(matrices: np.ndarray) -> np.ndarray:
    """(N,) bool: which of these (N, 4, 4) matrices SceneBuilder._usable accepts (the same tests, at once)."""
    usable = np.isfinite(matrices).all(axis=(1, 2))
    linear = matrices[usable, :3, :3]
    with np.errstate(all="ignore"):
        det = np.linalg.det(linear)
        cond = np.linalg.cond(linear) if len(linear) else np.zeros(0)
    usable[usable] = (det != 0.0) & np.isfinite(det) & ~(cond > 1e12)
    return usable


def _material_key(material) -> int:
    """Who a material is, for the builder's tables: its original's pointer (an evaluated object's slots give
    the evaluated copy, another datablock in each depsgraph); 0 for no material."""
    return getattr(material, "original", material).as_pointer() if material is not None else 0


def polygon_meshes(mesh) -> dict:
    """The mesh's polygons with corner normals, one tracer MeshData per material index (for export)."""
    count = len(mesh.polygons)
    if count == 0:
        return {}
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    vertices = np.array([convert.shortest32(v) for v in co], dtype=np.float64).reshape(-1, 3)
    loops = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    starts = np.empty(count, dtype=np.int32)
    totals = np.empty(count, dtype=np.int32)
    mats = np.empty(count, dtype=np.int32)
    mesh.polygons.foreach_get("loop_start", starts)
    mesh.polygons.foreach_get("loop_total", totals)
    mesh.polygons.foreach_get("material_index", mats)
    normals = meshes._corner_normals(mesh)
    out = {}
    for index in np.unique(mats):
        polys = np.nonzero(mats == index)[0]
        corner = np.concatenate([np.arange(starts[p], starts[p] + totals[p]) for p in polys])
        faces, offset = [], 0
        for p in polys:
            s, t = int(starts[p]), int(totals[p])
            faces.append((tuple(int(v) for v in loops[s:s + t]), tuple(range(offset, offset + t))))
            offset += t
        out[int(index)] = MeshData(vertices=vertices, normals=normals[corner], faces=faces, origin=mesh.name)
    return out


def merge_mesh_data(parts, MeshData):
    """One MeshData from parts that share their vertex array (the pieces of one mesh)."""
    vertices = parts[0].vertices
    if all(isinstance(p.faces, FaceList) and p.normals is parts[0].normals for p in parts):
        # triangle_meshes' parts: one normal array too, so their faces are simply put together
        faces = FaceList(*(np.concatenate([getattr(p.faces, name) for p in parts])
                           for name in ("sizes", "vertex_index", "normal_index")))
        return MeshData(vertices=vertices, normals=parts[0].normals, faces=faces, origin=parts[0].origin)
    normals, faces, offset = [], [], 0
    for part in parts:
        normals.append(np.asarray(part.normals).reshape(-1, 3))
        faces += [(v, tuple(i + offset for i in n)) for v, n in part.faces]
        offset += len(normals[-1])
    return MeshData(vertices=vertices, normals=np.concatenate(normals), faces=faces, origin=parts[0].origin)
