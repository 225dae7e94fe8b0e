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

from . import meshes, props
from .pure import convert, light_units, primitives
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
        for collection_name, datablock in reversed(self.items):
            try:
                getattr(bpy.data, collection_name).remove(datablock)
            except (ReferenceError, RuntimeError):
                pass


class Importer:
    def __init__(self, context, conversion: np.ndarray, *, name: str = "SDL"):
        self.context = context
        self.conversion = np.asarray(conversion, dtype=np.float64)
        self.name = name
        self.created = _Created()
        self.mesh_cache: dict = {}
        self.material_cache: dict = {}
        self.last_material = None  # the Blender material made last (see _material)
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

    # -- materials and meshes ---------------------------------------------------------------------------

    def _material(self, sdl_material):
        mat = self.material_cache.get(sdl_material)
        if mat is None:
            d = sdl_material.diffuse
            name = f"SDL {d[0]:g} {d[1]:g} {d[2]:g}"
            # A copy of the material made last, whose node tree is there already and whose Principled inputs
            # mostly hold the values wanted (a scene's materials often differ in their colour alone): making
            # the node tree anew and setting every input makes Blender look through all the node trees in
            # the file each time, so 4,000 materials took 55 s.
            mat = self.last_material.copy() if self.last_material is not None else bpy.data.materials.new(name)
            mat.name = name
            self.created.add("materials", mat)
            if not mat.use_nodes:
                mat.use_nodes = True
            props.set_material(mat, sdl_material)
            # (the material keeps its own file's image; none for other textures, whatever it was copied from)
            image = self.pixmaps.get(sdl_material.texture, "") if sdl_material.texture > 0 else ""
            if mat.sdl.image != image:
                mat.sdl.image = image
            self.material_cache[sdl_material] = self.last_material = mat
        return mat

    def _mesh(self, shape, mesh_part: np.ndarray):
        kind, parameters = shape.kind, shape.parameters
        mesh_file = None
        if shapes.KINDS[kind].file_argument:
            mesh_file = os.path.abspath(shape.mesh.origin or shape.mesh_file or "")
        sheared = not np.array_equal(mesh_part, np.eye(4))
        key = (kind, parameters, mesh_file)
        if not sheared and key in self.mesh_cache:
            return self.mesh_cache[key]
        gm = primitives.generic_mesh(kind, parameters, shape.mesh)
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

    def shape_object(self, shape, material=None):
        """A Blender object for a tracer Shape, in the collection of its def/use groups, with ``material``
        (default: a material made from the shape's own)."""
        world = convert.to_blender(shape.matrix, self.conversion)
        object_part, mesh_part = convert.split_shear(world)
        mesh = self._mesh(shape, mesh_part)
        obj = self.created.add("objects", bpy.data.objects.new(self._object_name(shape), mesh))
        self._collection_for(shape.groups).objects.link(obj)
        obj.matrix_world = Matrix(object_part.tolist())
        if len(obj.material_slots) == 0:
            obj.data.materials.append(None)
        slot = obj.material_slots[0]
        slot.link = "OBJECT"
        slot.material = material if material is not None else self._material(shape.material)
        obj[OBJ_KIND] = shape.kind
        if shape.parameters:
            obj[OBJ_PARAM] = primitives.stored_parameters(shape.parameters)
        if shape.kind == "mesh":
            obj[OBJ_FILE] = mesh.get(meshes.FILE, "")
        obj[OBJ_MATRIX] = [float(v) for v in world.ravel()]
        obj[OBJ_ORDER] = self.order
        if shape.source is not None:
            obj["sdl_source"] = str(shape.source)
        self.order += 1
        self.result.objects.append(obj)
        return obj

    def _hide_cutter(self, obj) -> None:
        obj.hide_render = True
        obj.display_type = "WIRE"
        obj["sdl_cutter"] = True

    def _object(self, node):
        """Blender object for a shape or a CSG tree; a tree's object is its leftmost shape's, carrying one
        Boolean modifier per operation, innermost first."""
        if not isinstance(node, model.CSG):
            return self.shape_object(node)
        left = self._object(node.left)
        right = self._object(node.right)
        modifier = left.modifiers.new(name=f"SDL {node.op}", type="BOOLEAN")
        modifier.operation = SDL_TO_BOOLEAN[node.op]
        if hasattr(modifier, "operand_type"):
            modifier.operand_type = "OBJECT"
        modifier.object = right
        if hasattr(modifier, "solver"):
            modifier.solver = "EXACT"
        self._hide_cutter(right)
        return left

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
            parent = ctx.view_layer.active_layer_collection.collection if ctx.view_layer else bl_scene.collection
            root = self.created.add("collections",
                                    bpy.data.collections.new(f"SDL {os.path.basename(filepath) or self.name}"))
            parent.children.link(root)
            root["sdl_file"] = os.path.abspath(filepath) if filepath else ""
            self.result.collection = root
            for node in scene.objects:
                self._object(node)
            for index, light in enumerate(scene.lights):
                self._light(light, index)
            has_plane = any(s.kind == "plane" for s in scene.shapes())
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
            world.use_nodes = True
            props.set_world(world, scene.settings)
            bl_scene.world = world
            if settings is not None:
                settings.max_recursion_depth = int(scene.settings.max_recursion_depth)
            if sdl_view:
                set_view_settings(bl_scene, SDL_VIEW)
            self.result.sdl_view = sdl_view
            # Hide the cutters in the viewport too, and remember what Blender shows of every transform.
            if ctx.view_layer is not None:
                ctx.view_layer.update()
            for obj in self.result.objects:
                if obj.get("sdl_cutter"):
                    try:
                        obj.hide_set(True)
                    except RuntimeError:
                        obj.hide_viewport = True
                obj[OBJ_SHOWN] = flat(obj.matrix_world)
            cam_obj[CAM_SHOWN] = flat(cam_obj.matrix_world) + [float(cam_obj.data.lens),
                                                               float(cam_obj.data.sensor_height)]
            for obj in self.result.lights:
                obj["sdl_position_shown"] = [float(v) for v in obj.matrix_world.translation]
        except BaseException:
            self.undo()
            raise
        self.result.warnings = list(scene.warnings)
        return self.result

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
    mat.use_nodes = True
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
