"""SDL file -> Blender objects.

The whole file is read (and every mesh it names) before anything is created, so a file that cannot be
read leaves the Blender scene as it was; if creating fails half way, what was created is removed again.
"""
from __future__ import annotations

import math
import os
import re
from dataclasses import dataclass, field
from typing import Optional

import bpy
import numpy as np
from mathutils import Matrix

from . import meshes, props, shader_nodes
from .pure import convert, light_units, naming, primitives
from .scene_build import (OBJ_FILE, OBJ_KIND, OBJ_MATRIX, OBJ_ORDER, OBJ_PARAM, OBJ_SHOWN, SDL_TO_BOOLEAN, flat)
from .tracer import model, shapes
from .tracer.camera import CameraFrame, focal_length, framing_camera
from .tracer.compile import compile_scene
from .tracer.errors import TracerError
from .tracer.sdl import parser
from .tracer.textures import drop_unreadable_textures, texture_problems

#: Custom properties on an imported camera object: eye, look-at point, up (Blender axes) and view angle.
CAM_EXACT, CAM_SHOWN = "sdl_camera", "sdl_camera_shown"
SENSOR_HEIGHT = 24.0


@dataclass
class ImportResult:
    objects: list = field(default_factory=list)  # shape objects, in file order
    lights: list = field(default_factory=list)
    camera: Optional[object] = None
    collection: Optional[object] = None
    warnings: list[str] = field(default_factory=list)
    #: Whether the import set SDL's colour management (see COLOUR_MANAGEMENT).
    sdl_view: bool = False


def read_scene(filepath: str, strict: bool = False):
    """Parse the file (raises tracer's TracerError, an SDLError for a problem in it, if it cannot be read).
    A lenient read skips the statements it cannot read; when that leaves no shape, light or camera and
    there were problems (a binary file, a file in another format), the file is refused as a strict read
    would refuse it, so that importing it changes nothing rather than adding a camera that frames nothing."""
    scene = parser.load(filepath, strict=strict)
    if scene.warnings and not scene.shapes() and not scene.lights and scene.camera is None:
        extra = len(scene.warnings) - 1
        more = f" (and {extra} more problem{'s' if extra > 1 else ''})" if extra else ""
        raise TracerError(f"nothing in the file could be read as SDL: {scene.warnings[0]}{more}")
    # A texture that cannot be used (a makePixmap naming a missing or unreadable picture) is refused as the
    # command line refuses it; read leniently, it is taken off the shapes that use it, with a warning.
    if strict:
        problems = texture_problems(scene)
        if problems:
            raise TracerError(next(iter(problems.values())))
    else:
        scene.warnings.extend(drop_unreadable_textures(scene))
    return scene


def light_matrix(direction, axis, position) -> np.ndarray:
    """A Blender light's world matrix: at ``position``, shining along ``direction`` (its local -Z), its local X
    along ``axis`` made perpendicular to that (any perpendicular where ``axis`` is along ``direction``)."""
    z = -np.asarray(direction, dtype=np.float64)
    z /= np.linalg.norm(z)
    x = np.asarray(axis, dtype=np.float64) - np.dot(axis, z) * z
    if np.linalg.norm(x) < 1e-9:
        x = np.cross(z, [0.0, 0.0, 1.0] if abs(z[2]) < 0.9 else [1.0, 0.0, 0.0])
    x /= np.linalg.norm(x)
    matrix = np.eye(4)
    matrix[:3, 0], matrix[:3, 1], matrix[:3, 2], matrix[:3, 3] = x, np.cross(z, x), z, position
    return matrix


def camera_matrix(camera) -> np.ndarray:
    """The lecture's camera frame (u right, v up, n backwards: tracer.camera) as a Blender camera's world
    matrix; ``camera`` is in Blender's axes."""
    return CameraFrame.from_camera(camera, 1.0).to_world()


class _Created:
    """Everything made so far, to remove again if the import fails."""

    def __init__(self):
        self.items: list[tuple[str, object]] = []

    def add(self, collection_name: str, datablock):
        self.items.append((collection_name, datablock))
        return datablock

    def remove_all(self) -> None:
        """Remove everything made: at once (``batch_remove`` looks through the file once for all of them;
        removing 10^5 objects one by one looked through it 10^5 times)."""
        alive = []
        for collection_name, datablock in reversed(self.items):
            try:
                datablock.name  # (a datablock removed already raises ReferenceError)
            except ReferenceError:
                continue
            alive.append((collection_name, datablock))
        self.items.clear()
        try:
            bpy.data.batch_remove([datablock for _, datablock in alive])
        except (AttributeError, RuntimeError, ReferenceError, TypeError):
            for collection_name, datablock in alive:
                try:
                    getattr(bpy.data, collection_name).remove(datablock)
                except (ReferenceError, RuntimeError):
                    pass


def _counted(steps, before: int, total: int):
    """(before + done, total) for each of a generator's yields of ``done``; returns what it returns."""
    while True:
        try:
            done = next(steps)
        except StopIteration as stop:
            return stop.value
        yield before + done, total


def _max_name_bytes() -> int:
    """The longest datablock name this Blender keeps, in bytes (63 before 5.0)."""
    try:
        return int(bpy.types.ID.bl_rna.properties["name"].length_max) - 1
    except (KeyError, AttributeError, TypeError):
        return 63


def _distinct_materials(materials, material_ids: np.ndarray) -> tuple[list, list]:
    """The distinct materials (equal values are one) a table's shapes use, in order of first use, and each
    shape's index into them.  A MaterialRows is compared row by row, without making a Material of each."""
    if len(material_ids) == 0:
        return [], []
    if hasattr(materials, "rows"):
        rows = materials.rows
        _, first, inverse = np.unique(rows, axis=0, return_index=True, return_inverse=True)
        inverse = inverse.reshape(-1)
    else:
        index_of: dict = {}
        first = []
        inverse = np.empty(len(materials), dtype=np.int64)
        for i, material in enumerate(materials):
            if material not in index_of:
                index_of[material] = len(first)
                first.append(i)
            inverse[i] = index_of[material]
        first = np.asarray(first, dtype=np.int64)
    used = np.unique(inverse[material_ids]) if len(material_ids) else np.zeros(0, dtype=np.int64)
    # in order of first use by a shape
    first_use = np.full(len(first), len(material_ids), dtype=np.int64)
    np.minimum.at(first_use, inverse[material_ids], np.arange(len(material_ids)))
    used = used[np.argsort(first_use[used], kind="stable")]
    position = np.empty(len(first), dtype=np.int64)
    position[used] = np.arange(len(used))
    distinct = [materials[int(first[u])] for u in used]
    return distinct, position[inverse[material_ids]].tolist()


_IDENTITY = np.eye(4)


def _layer_collection(view_layer, collection):
    """The view layer's layer collection of ``collection`` (None without a view layer, or if not in it)."""
    if view_layer is None:
        return None
    pending = [view_layer.layer_collection]
    while pending:
        layer = pending.pop()
        if layer.collection == collection:
            return layer
        pending.extend(layer.children)
    return None


def _rename(datablock, name: str) -> None:
    """Rename a datablock: with ``ID.rename`` where Blender has it (4.3+); setting ``name`` first looks for
    the datablock from the start of its list (to check that it may be renamed), a walk past every material
    made before it."""
    rename = getattr(datablock, "rename", None)
    if rename is not None:
        rename(name)
    else:
        datablock.name = name


@dataclass
class _Plan:
    """The shape objects an import makes, one per shape (CSG operands included), in the file's order, as
    columns: worked out before anything is made, so that Blender's datablocks can be made in bulk."""

    kinds: list = field(default_factory=list)
    parameters: list = field(default_factory=list)  # each shape's parameters (Shape.parameters)
    meshes: list = field(default_factory=list)  # the MeshData of a polyhedron, the teapot or a mesh, else None
    mesh_files: list = field(default_factory=list)  # a mesh's file (absolute), else None
    matrices: list = field(default_factory=list)  # SDL matrices (4x4), until ``world`` is made of them
    materials: list = field(default_factory=list)  # distinct tracer Materials, in order of first use
    material_of: list = field(default_factory=list)  # each shape's index into materials
    names: list = field(default_factory=list)  # the object names wanted
    groups: list = field(default_factory=list)
    sources: list = field(default_factory=list)  # "file:line:column", or None
    booleans: list = field(default_factory=list)  # (left shape, SDL op, right shape), innermost first
    world: Optional[np.ndarray] = None  # (N, 4, 4) Blender world matrices

    def __len__(self) -> int:
        return len(self.kinds)


#: Objects or materials made between two progress reports (Importer.steps).
STEP = 500


class Importer:
    def __init__(self, context, conversion: np.ndarray, *, name: str = "SDL"):
        self.context = context
        self.conversion = np.asarray(conversion, dtype=np.float64)
        self.name = name
        self.created = _Created()
        self.mesh_cache: dict = {}
        self.collections: dict[str, object] = {}
        self.result = ImportResult()
        self.order = 0
        self.pixmaps: dict[int, str] = {}  # the file's makePixmap images, by number
        self.file_stem = ""  # the SDL file's name without its extension, as the exporter spells it
        self.soft_lights = 0  # physical lights with an extent made so far (see _physical_light)
        self._scene_before: tuple = ()  # (world, camera, recursion depth, light samples) before run(): see undo()

    # -- collections ------------------------------------------------------------------------------------

    def _collection_for(self, groups: tuple[str, ...]):
        parent = self.result.collection
        for group in groups:
            coll = self.collections.get(group)
            if coll is None:
                coll = self.created.add("collections", bpy.data.collections.new(group))
                coll["sdl_macro"] = group
                self.collections[group] = coll
            if coll.name not in parent.children:
                parent.children.link(coll)
            parent = coll
        return parent

    # -- what to make -----------------------------------------------------------------------------------

    def plan(self, objects) -> _Plan:
        """The shapes of a scene's objects (a list of shapes and CSG trees, or a ShapeTable) as a _Plan."""
        columns = getattr(objects, "columns", None)
        plan = self._plan_table(columns) if columns is not None else self._plan_list(objects)
        matrices = np.asarray(plan.matrices, dtype=np.float64).reshape(-1, 4, 4)
        plan.world = self.conversion @ matrices  # (to_blender, for all at once)
        plan.matrices = []
        return plan

    def _plan_list(self, objects) -> _Plan:
        plan = _Plan()
        index_of: dict = {}  # tracer Material -> its index (materials equal in value are one)

        def add(node) -> int:
            if isinstance(node, model.CSG):
                left, right = add(node.left), add(node.right)
                plan.booleans.append((left, node.op, right))
                return left
            material = index_of.setdefault(node.material, len(index_of))
            if material == len(plan.materials):
                plan.materials.append(node.material)
            kind = node.kind
            plan.kinds.append(kind)
            plan.parameters.append(node.parameters)
            plan.meshes.append(node.mesh)
            plan.mesh_files.append(os.path.abspath(node.mesh.origin or node.mesh_file or "")
                                   if shapes.KINDS[kind].file_argument else None)
            plan.matrices.append(node.matrix)
            plan.material_of.append(material)
            plan.names.append(self._object_name(node))
            plan.groups.append(tuple(node.groups))
            plan.sources.append(str(node.source) if node.source is not None else None)
            return len(plan.kinds) - 1

        for node in objects:
            add(node)
        return plan

    def _plan_table(self, columns) -> _Plan:
        """A ShapeTable's rows, read from its columns without making a Shape of each (10^5 shapes)."""
        count = len(columns)
        keywords = [e.keyword for e in shapes.REGISTRY]
        kinds = [keywords[code] for code in columns.kinds.tolist()]
        arity = {kind: len(shapes.KINDS[kind].parameters) for kind in set(kinds)}
        rows = columns.parameters.tolist() if any(arity.values()) else None
        builtin = {kind: parser.builtin_mesh(kind) for kind in set(kinds)
                   if kind in model.POLYHEDRON_KINDS or kind == "teapot"}
        names = columns.names or {}
        where = columns.file or "<sdl>"
        materials, material_of = _distinct_materials(columns.materials, columns.material_ids)
        return _Plan(kinds=kinds, parameters=[tuple(row[:arity[k]]) if arity[k] else () for k, row in
                                              zip(kinds, rows)] if rows is not None else [()] * count,
                     meshes=[builtin.get(k) for k in kinds], mesh_files=[None] * count,
                     matrices=model.matrices_of_affines(columns.affines), materials=materials,
                     material_of=material_of,
                     names=[names[i] if names.get(i) else kinds[i] for i in range(count)],
                     groups=[()] * count,
                     sources=[f"{where}:{line}:{column}" if column else f"{where}:{line}"
                              for line, column in zip(columns.lines.tolist(), columns.columns.tolist())])

    # -- materials and meshes ---------------------------------------------------------------------------

    def make_materials(self, sdl_materials: list):
        """Blender materials for distinct tracer Materials (a generator: yields after each STEP; the list of
        materials is its return value).

        Each is a copy of the one made before it, whose node tree is there already; the copy is renamed and
        given only the values that differ.  Made in the order of their names (see naming.py), its Principled
        inputs all written at once (props.PrincipledWriter): making node trees anew, and every set of an
        input's value, made Blender look through all the node trees in the file, and renaming in any other
        order walked its list of materials, so that 10^4 materials took time in the square of their number."""
        wanted = []
        for material in sdl_materials:
            d = material.diffuse
            wanted.append(f"SDL {d[0]:g} {d[1]:g} {d[2]:g}")
        taken = (m.name for m in bpy.data.materials if m.library is None)
        names = naming.unique_names(wanted, taken, _max_name_bytes())
        made: list = [None] * len(sdl_materials)
        previous, before, writer = None, None, None
        for count, index in enumerate(sorted(range(len(names)), key=lambda i: naming.sort_key(names[i])), 1):
            sdl_material = sdl_materials[index]
            if previous is None:
                mat = self.created.add("materials", bpy.data.materials.new(names[index]))
                shader_nodes.use_nodes(mat)
                props.set_material(mat, sdl_material)
                writer = props.PrincipledWriter.of(mat)
            else:
                mat = self.created.add("materials", previous.copy())
                _rename(mat, names[index])
                props.set_material(mat, sdl_material, before=before, writer=writer)
            # (the material keeps its own file's image; none for other textures, whatever it was copied from)
            image = self.pixmaps.get(sdl_material.texture, "") if sdl_material.texture > 0 else ""
            if mat.sdl.image != image:
                mat.sdl.image = image
            made[index] = previous = mat
            before = sdl_material
            if count % STEP == 0:
                yield count
        return made

    def _mesh(self, kind: str, parameters: tuple, mesh_data, mesh_file: Optional[str], mesh_part: np.ndarray):
        sheared = not np.array_equal(mesh_part, np.eye(4))
        key = (kind, parameters, mesh_file)
        if not sheared and key in self.mesh_cache:
            return self.mesh_cache[key]
        gm = primitives.generic_mesh(kind, parameters, mesh_data)
        if sheared:
            gm = gm.transformed(mesh_part[:3, :3])
        name = primitives.mesh_name(kind, parameters, mesh_file) + (" (sheared)" if sheared else "")
        mesh = None if sheared else meshes.find_shared(kind, parameters, mesh_file, gm.hash())
        if mesh is None:
            mesh = self.created.add("meshes", meshes.build_mesh(name, gm))
            mesh.materials.append(None)  # one slot, linked to each object's own material
            meshes.mark_generic(mesh, kind, parameters, mesh_file, mesh_part)
        if not sheared:
            self.mesh_cache[key] = mesh
        return mesh

    # -- objects ----------------------------------------------------------------------------------------

    def _object_name(self, shape) -> str:
        """The name a ``! name:`` comment gave the shape; else its kind, or a mesh's file name less the
        ``<scene>_`` the exporter puts before the name of the object it came from."""
        if shape.name:
            return shape.name
        source = shape.mesh.origin if shape.kind == "mesh" and shape.mesh is not None else None
        source = source or (shape.mesh_file if shape.kind == "mesh" else None)
        if not source:
            return shape.kind
        name = os.path.splitext(os.path.basename(source))[0]
        prefix = self.file_stem + "_"
        return name[len(prefix):] if name.startswith(prefix) and len(name) > len(prefix) else name

    def make_objects(self, plan: _Plan, materials: list):
        """An object per planned shape, on the shared mesh of its kind, with its own material in an object
        slot, its exact transform kept beside Blender's (a generator: yields after each STEP; the objects,
        in the plan's order, are its return value).  Made in the order of their names (see naming.py)."""
        count = len(plan)
        linear = plan.world[:, :3, :3]
        gram = np.einsum("nji,njk->nik", linear, linear)
        diagonal = np.einsum("nii->ni", gram)
        off = np.abs(gram - diagonal[:, :, None] * np.eye(3)).max(axis=(1, 2)) if count else np.zeros(0)
        # (convert.has_shear's test, for every shape at once; split_shear only for those it finds)
        sheared = off > 1e-9 * np.maximum(np.abs(diagonal).max(axis=1), 1e-300) if count else np.zeros(0, bool)
        exact = plan.world.reshape(count, 16).tolist()
        parts = plan.world.tolist()
        taken = (o.name for o in bpy.data.objects if o.library is None)
        names = naming.unique_names(plan.names, taken, _max_name_bytes())
        made: list = [None] * count
        first = self.order
        for done, i in enumerate(sorted(range(count), key=lambda i: naming.sort_key(names[i])), 1):
            kind = plan.kinds[i]
            if sheared[i]:
                object_part, mesh_part = convert.split_shear(plan.world[i])
                part = object_part.tolist()
            else:
                mesh_part, part = _IDENTITY, parts[i]
            mesh = self._mesh(kind, plan.parameters[i], plan.meshes[i], plan.mesh_files[i], mesh_part)
            obj = self.created.add("objects", bpy.data.objects.new(names[i], mesh))
            self._collection_for(plan.groups[i]).objects.link(obj)
            obj.matrix_world = Matrix(part)
            self._finish_shape_object(obj, kind, plan.parameters[i], exact[i], first + i, plan.sources[i],
                                      materials[plan.material_of[i]])
            made[i] = obj
            if done % STEP == 0:
                yield done
        self.order += count
        return made

    def _finish_shape_object(self, obj, kind: str, parameters: tuple, exact: list, order: int,
                             source: Optional[str], material) -> None:
        if len(obj.material_slots) == 0:
            obj.data.materials.append(None)
        slot = obj.material_slots[0]
        slot.link = "OBJECT"
        slot.material = material
        obj[OBJ_KIND] = kind
        if parameters:
            obj[OBJ_PARAM] = primitives.stored_parameters(parameters)
        if kind == "mesh":
            obj[OBJ_FILE] = obj.data.get(meshes.FILE, "")
        obj[OBJ_MATRIX] = exact
        obj[OBJ_ORDER] = order
        if source is not None:
            obj["sdl_source"] = source

    def shape_object(self, shape, material):
        """A Blender object for one tracer Shape (Add > SDL Shape), in the collection of its def/use groups,
        with ``material``."""
        world = convert.to_blender(shape.matrix, self.conversion)
        object_part, mesh_part = convert.split_shear(world)
        kind = shape.kind
        mesh_file = None
        if shapes.KINDS[kind].file_argument:
            mesh_file = os.path.abspath(shape.mesh.origin or shape.mesh_file or "")
        mesh = self._mesh(kind, shape.parameters, shape.mesh, mesh_file, mesh_part)
        obj = self.created.add("objects", bpy.data.objects.new(self._object_name(shape), mesh))
        self._collection_for(shape.groups).objects.link(obj)
        obj.matrix_world = Matrix(object_part.tolist())
        self._finish_shape_object(obj, kind, shape.parameters, [float(v) for v in world.ravel()], self.order,
                                  str(shape.source) if shape.source is not None else None, material)
        self.order += 1
        self.result.objects.append(obj)
        return obj

    def _hide_cutter(self, obj) -> None:
        obj.hide_render = True
        obj.display_type = "WIRE"
        obj["sdl_cutter"] = True

    def make_booleans(self, plan: _Plan, objects: list) -> None:
        """A CSG tree's object is its leftmost shape's, carrying one Boolean modifier per operation, innermost
        first; the other operands are hidden cutters."""
        for left, op, right in plan.booleans:
            obj = objects[left]
            modifier = obj.modifiers.new(name=f"SDL {op}", type="BOOLEAN")
            modifier.operation = SDL_TO_BOOLEAN[op]
            if hasattr(modifier, "operand_type"):
                modifier.operand_type = "OBJECT"
            modifier.object = objects[right]
            if hasattr(modifier, "solver"):
                modifier.solver = "EXACT"
            self._hide_cutter(objects[right])

    def _light(self, light, index: int):
        """A Blender light for an SDL light: SDL's ``light`` a point light that keeps SDL's meaning (see
        blender_lights); the physical kinds as the Blender light of the same meaning, in Blender's units."""
        name = light.name or f"SDL light {index + 1}"
        blender_type = {"point": "POINT", "sphere": "POINT", "spot": "SPOT", "sun": "SUN", "area": "AREA"}[light.kind]
        data = self.created.add("lights", bpy.data.lights.new(name, blender_type))
        obj = self.created.add("objects", bpy.data.objects.new(name, data))
        self.result.collection.objects.link(obj)
        position = convert.points_to_blender(light.position, self.conversion)
        if light.kind == "point":
            props.set_light(data, light.color)
            obj["sdl_position"] = [float(v) for v in position]
        else:
            self._physical_light(obj, light, position)
        obj.location = tuple(position)
        obj[OBJ_ORDER] = self.order
        self.order += 1
        self.result.lights.append(obj)
        return obj

    def _physical_light(self, obj, light, position) -> None:
        data = obj.data
        data.shadow_soft_size = float(light.radius)
        direction = convert.points_to_blender(light.direction, self.conversion)
        axis = convert.points_to_blender(light.axis, self.conversion)
        obj.matrix_world = Matrix(light_matrix(direction, axis, position).tolist())
        if light.kind == "sun":
            data.color, data.energy = light_units.strength_of_sun(light.color)
            data.angle = math.radians(light.angle)
        elif light.kind == "area":
            width, height = light.size
            data.shape = "ELLIPSE" if light.shape == "ellipse" else "RECTANGLE"
            data.size, data.size_y = width, height
            surface = width * height * (math.pi / 4.0 if light.shape == "ellipse" else 1.0)
            data.color, data.energy = light_units.watts_of_area_light(light.color, surface)
        else:
            data.color, data.energy = light_units.watts_of_sphere_light(light.color)
            if light.kind == "spot":
                data.spot_size, data.spot_blend = math.radians(light.spot_size), light.spot_blend
        settings = getattr(self.context.scene, "sdl_render", None)
        if light.soft and settings is not None:  # (one setting for the scene: its lights' most)
            settings.light_samples = max(settings.light_samples if self.soft_lights else 1, light.samples)
            self.soft_lights += 1

    def _camera(self, camera, framed: bool, far: float):
        data = self.created.add("cameras", bpy.data.cameras.new("SDL camera"))
        data.sensor_fit = "VERTICAL"
        data.sensor_height = SENSOR_HEIGHT
        data.lens = focal_length(camera.view_angle, SENSOR_HEIGHT)  # sensor fit vertical
        data.clip_start = 0.05
        data.clip_end = far
        obj = self.created.add("objects", bpy.data.objects.new("SDL camera", data))
        self.result.collection.objects.link(obj)
        eye, look, up = (tuple(float(v) for v in convert.points_to_blender(p, self.conversion))
                         for p in (camera.eye, camera.look, camera.up))
        obj.matrix_world = Matrix(camera_matrix(model.Camera(eye, look, up, camera.view_angle)).tolist())
        obj[CAM_EXACT] = [float(v) for v in (*eye, *look, *up, camera.view_angle)]
        obj["sdl_framed"] = bool(framed)
        self.result.camera = obj
        return obj

    # -- the whole scene --------------------------------------------------------------------------------

    def run(self, scene, filepath: str, set_camera: bool = True, colour_management: str = "AUTO") -> ImportResult:
        """Make the scene at once (steps() made to the end)."""
        for _ in self.steps(scene, filepath, set_camera, colour_management):
            pass
        return self.result

    def steps(self, scene, filepath: str, set_camera: bool = True, colour_management: str = "AUTO",
              hidden_while_made: bool = False):
        """Make the scene, a piece at a time: a generator that yields (done, total) after every STEP objects
        or materials, so that a caller can show progress and stop (closing the generator removes what was
        made).  If making fails, what was made is removed again and the error raised.

        ``hidden_while_made``: the new collection stays out of the view layer until its last step, so that
        Blender, redrawing between the steps, neither evaluates nor draws a scene half made (each time
        longer: 10^4 spheres took seconds a redraw in software OpenGL)."""
        ctx = self.context
        bl_scene = ctx.scene
        sdl_view = colour_management == "SDL" or (colour_management == "AUTO" and len(bl_scene.objects) == 0)
        settings = getattr(bl_scene, "sdl_render", None)
        self._scene_before = (bl_scene.world, bl_scene.camera,
                              settings.max_recursion_depth if settings is not None else None,
                              settings.light_samples if settings is not None else None)
        self._view_before = view_settings(bl_scene)
        self.file_stem = re.sub(r"[^A-Za-z0-9._-]", "_", os.path.splitext(os.path.basename(filepath))[0])
        self.pixmaps = dict(scene.pixmaps)
        try:
            plan = self.plan(scene.objects)
            total = len(plan.materials) + len(plan)
            yield 0, total
            parent = ctx.view_layer.active_layer_collection.collection if ctx.view_layer else bl_scene.collection
            root = self.created.add("collections",
                                    bpy.data.collections.new(f"SDL {os.path.basename(filepath) or self.name}"))
            parent.children.link(root)
            root["sdl_file"] = os.path.abspath(filepath) if filepath else ""
            self.result.collection = root
            excluded = _layer_collection(ctx.view_layer, root) if hidden_while_made else None
            if excluded is not None:
                excluded.exclude = True
            materials = yield from _counted(self.make_materials(plan.materials), 0, total)
            objects = yield from _counted(self.make_objects(plan, materials), len(plan.materials), total)
            self.make_booleans(plan, objects)
            self.result.objects = objects
            for index, light in enumerate(scene.lights):
                self._light(light, index)
            has_plane = "plane" in plan.kinds
            far = 3.0 * primitives.PLANE_HALF_SIZE if has_plane else 1000.0
            camera, framed = scene.camera, False
            if camera is None:
                render = bl_scene.render
                aspect = (render.resolution_x * render.pixel_aspect_x) / max(1e-9, render.resolution_y * render.pixel_aspect_y)
                compiled = compile_scene(scene)
                camera, framed = framing_camera(compiled, aspect), True
            cam_obj = self._camera(camera, framed, far)
            if set_camera:
                bl_scene.camera = cam_obj
            world = self.created.add("worlds", bpy.data.worlds.new(f"SDL world {os.path.basename(filepath)}"))
            shader_nodes.use_nodes(world)
            props.set_world(world, scene.settings)
            bl_scene.world = world
            if settings is not None:
                settings.max_recursion_depth = int(scene.settings.max_recursion_depth)
            if sdl_view:
                set_view_settings(bl_scene, SDL_VIEW)
            self.result.sdl_view = sdl_view
            if excluded is not None:
                excluded.exclude = False
            # Hide the cutters in the viewport too, and remember what Blender shows of every transform: for
            # an object without a parent, its matrix_basis (location, rotation and scale put together again),
            # bit for bit what evaluating the scene makes its world matrix, without evaluating 10^5 objects.
            for obj in self.result.objects:
                if obj.get("sdl_cutter"):
                    try:
                        obj.hide_set(True)
                    except RuntimeError:
                        obj.hide_viewport = True
                obj[OBJ_SHOWN] = flat(obj.matrix_basis)
            cam_obj[CAM_SHOWN] = flat(cam_obj.matrix_basis) + [float(cam_obj.data.lens),
                                                               float(cam_obj.data.sensor_height)]
            for obj in self.result.lights:
                obj["sdl_position_shown"] = [float(v) for v in obj.matrix_basis.translation]
            yield total, total
        except BaseException:
            self.undo()
            raise
        self.result.warnings = list(scene.warnings)

    def undo(self) -> None:
        """Remove what run() made and give the scene back the world, camera, recursion depth and colour
        management it had."""
        bl_scene = self.context.scene
        if self._scene_before:
            bl_scene.world, bl_scene.camera, depth, samples = self._scene_before
            if depth is not None:
                bl_scene.sdl_render.max_recursion_depth = depth
                bl_scene.sdl_render.light_samples = samples
            set_view_settings(bl_scene, self._view_before)
        self.created.remove_all()


#: Import > SDL's Colour Management choices: SDL's view (SDL_VIEW) for a file imported into an empty scene
#: (the scene is the file's), always, or never (a scene of the user's keeps the view it was made for).
COLOUR_MANAGEMENT = (
    ("AUTO", "SDL's in an Empty Scene", "Importing into an empty scene, show colours as SDL and the tracer do "
                                        "(View Transform Raw); a scene with objects keeps its own"),
    ("SDL", "SDL's", "Show colours as SDL and the tracer do: the scene's View Transform becomes Raw (values shown "
                     "unchanged; Standard, Filmic and AgX change them)"),
    ("KEEP", "The Scene's", "Leave the scene's colour management as it is"))

#: The colour management an imported SDL scene gets.  SDL colours are the values a screen shows (the
#: tracer's PNG holds each traced value times 255, with no transfer curve), and Blender's *Raw* view shows
#: scene values unchanged, so F12 displays (and saves) what the tracer writes.  *Standard* would apply the
#: sRGB curve (a background of 0.35 shown as 160/255 instead of 89), Filmic and AgX compress besides.
SDL_VIEW = {"view_transform": "Raw", "look": "None", "exposure": 0.0, "gamma": 1.0, "use_curve_mapping": False}


def view_settings(scene) -> dict:
    return {name: getattr(scene.view_settings, name) for name in SDL_VIEW}


def set_view_settings(scene, values: dict) -> None:
    for name, value in values.items():
        setattr(scene.view_settings, name, value)


def default_material(created: Optional[_Created] = None):
    """The SDL default material that added shapes share (made, and added to ``created``, if there is none)."""
    for mat in bpy.data.materials:
        if mat.get("sdl_default") and mat.library is None:
            return mat
    mat = bpy.data.materials.new("SDL default")
    if created is not None:
        created.add("materials", mat)
    mat["sdl_default"] = True
    shader_nodes.use_nodes(mat)
    props.set_material(mat, model.Material())
    return mat


def import_sdl(context, filepath: str, conversion: Optional[np.ndarray] = None, strict: bool = False,
               set_camera: bool = True, colour_management: str = "AUTO") -> ImportResult:
    """Read ``filepath`` and build it in ``context.scene``.  Raises the tracer's SDLError (nothing created)
    if the file cannot be read."""
    scene = read_scene(filepath, strict=strict)
    conversion = convert.axis_matrix() if conversion is None else conversion
    return Importer(context, conversion).run(scene, filepath, set_camera=set_camera,
                                             colour_management=colour_management)
