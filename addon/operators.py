"""File > Import/Export > SDL, drag and drop of .sdl files, and adding generic shapes."""
from __future__ import annotations

import os
import time
import traceback

import bpy
import numpy as np
from bpy.props import BoolProperty, CollectionProperty, EnumProperty, FloatProperty, StringProperty
from bpy_extras.io_utils import ExportHelper, ImportHelper, orientation_helper

from . import exporter, importer
from .importer import COLOUR_MANAGEMENT
from .pure import convert
from .tracer import errors, model
from .tracer.sdl.parser import builtin_mesh
from .tracer.shapes import KINDS, REGISTRY

#: How many of a file's warnings are shown one by one (the rest are counted).
SHOWN_WARNINGS = 8
#: Seconds of importing between two redraws, at least and at most, when the import runs from Blender's window.
IMPORT_SLICE, IMPORT_SLICE_MAX = 0.1, 1.0


class _Failed(Exception):
    """An import that stopped and said why (reported to the operator)."""


def _report_warnings(op, warnings) -> None:
    for message in warnings[:SHOWN_WARNINGS]:
        op.report({"WARNING"}, message)
    if len(warnings) > SHOWN_WARNINGS:
        op.report({"WARNING"}, f"... and {len(warnings) - SHOWN_WARNINGS} more problems")


@orientation_helper(axis_forward="-Z", axis_up="Y")
class IMPORT_SCENE_OT_sdl(bpy.types.Operator, ImportHelper):
    """Import an SDL scene (F. S. Hill's Scene Description Language)"""

    bl_idname = "import_scene.sdl"
    bl_label = "Import SDL"
    bl_options = {"REGISTER", "UNDO", "PRESET"}

    filename_ext = ".sdl"
    filter_glob: StringProperty(default="*.sdl;*.dat", options={"HIDDEN"})
    files: CollectionProperty(type=bpy.types.OperatorFileListElement, options={"HIDDEN", "SKIP_SAVE"})
    directory: StringProperty(subtype="DIR_PATH", options={"HIDDEN", "SKIP_SAVE"})
    strict: BoolProperty(name="Strict", default=False,
                         description="Refuse files with any problem (otherwise import what can be read "
                                     "and report the problems)")
    set_camera: BoolProperty(name="Set Scene Camera", default=True,
                             description="Make the file's camera (or a camera framing the scene) the scene camera")
    colour_management: EnumProperty(name="Colour Management", default="AUTO", items=COLOUR_MANAGEMENT)
    interactive: BoolProperty(default=False, options={"HIDDEN", "SKIP_SAVE"})

    def invoke(self, context, event):
        self.interactive = True  # (execute() then imports a piece at a time, with a progress bar and Esc)
        if self.properties.is_property_set("filepath") and hasattr(ImportHelper, "invoke_popup"):
            return self.invoke_popup(context)  # a dropped file
        return ImportHelper.invoke(self, context, event)

    def _paths(self) -> list[str]:
        if self.directory and len(self.files) and any(f.name for f in self.files):
            return [os.path.join(self.directory, f.name) for f in self.files if f.name]
        return [self.filepath]

    def execute(self, context):
        """Import at once; or, asked from Blender's window (File > Import, a dropped file), a piece at a time
        from a timer, with a progress bar and the count in the status bar, Esc stopping it (what was made is
        removed again)."""
        self._steps = self._import(context, self.interactive)
        if not (self.interactive and context.window is not None and not bpy.app.background):
            try:
                for _ in self._steps:
                    pass
            except _Failed:
                return {"CANCELLED"}
            return {"FINISHED"}
        wm = context.window_manager
        self._timer = wm.event_timer_add(0.001, window=context.window)
        self._slice_end = None  # when the last slice ended
        wm.progress_begin(0, 1000)
        wm.modal_handler_add(self)
        return {"RUNNING_MODAL"}

    def modal(self, context, event):
        if event.type == "ESC":
            self._steps.close()  # (the importers remove what they made)
            self._end(context)
            self.report({"WARNING"}, "SDL import cancelled: nothing was imported")
            return {"CANCELLED"}
        if event.type != "TIMER":
            return {"RUNNING_MODAL"}  # (nothing else happens to the scene while it is being made)
        started = time.perf_counter()
        # What Blender did since the last slice (drawing and evaluating what was made: it grows with that):
        # the slices are long enough that it takes at most a fifth of the time, and short enough that the
        # window shows the progress and answers Esc.
        outside = started - self._slice_end if self._slice_end is not None else 0.0
        until = started + min(IMPORT_SLICE_MAX, max(IMPORT_SLICE, 4.0 * outside))
        try:
            while time.perf_counter() < until:
                done, total = next(self._steps)
                context.window_manager.progress_update(int(1000 * done / max(total, 1)))
                context.workspace.status_text_set(f"Importing SDL: {done:,} of {total:,} objects and materials "
                                                  f"(Esc to cancel)")
        except StopIteration:
            self._end(context)
            return {"FINISHED"}
        except _Failed:
            self._end(context)
            return {"CANCELLED"}
        self._slice_end = time.perf_counter()
        return {"RUNNING_MODAL"}

    def _end(self, context) -> None:
        wm = context.window_manager
        wm.event_timer_remove(self._timer)
        wm.progress_end()
        context.workspace.status_text_set(None)

    def _import(self, context, hidden_while_made: bool = False):
        """The import, as steps (done, total): every file read first, then made; raises _Failed after
        reporting why (what was made removed again, of every file)."""
        conversion = convert.axis_matrix(self.axis_forward, self.axis_up)
        parsed = []
        for path in self._paths():  # read every file before creating anything
            try:
                parsed.append((path, importer.read_scene(path, strict=self.strict)))
            except errors.TracerError as exc:  # SDLError and the rest of the tracer's errors (a folder, a FIFO)
                self.report({"ERROR"}, f"Cannot import {os.path.basename(path)}: {exc}")
                raise _Failed from exc
        total = 0
        done = []
        try:
            for path, scene in parsed:
                imp = importer.Importer(context, conversion)
                try:
                    yield from imp.steps(scene, path, set_camera=self.set_camera,
                                         colour_management=self.colour_management,
                                         hidden_while_made=hidden_while_made)
                except Exception as exc:  # noqa: BLE001 - reported in Blender's UI (the importer undid its work)
                    if not isinstance(exc, (ValueError, RuntimeError, errors.TracerError)):
                        traceback.print_exc()
                    self.report({"ERROR"}, f"Cannot import {os.path.basename(path)}: {exc}")
                    raise _Failed from exc
                done.append(imp)
                _report_warnings(self, imp.result.warnings)
                total += len(imp.result.objects)
                kept_view = not imp.result.sdl_view and self.colour_management == "AUTO"
        except BaseException:  # a failure, or Esc: and the files before it, all of them or nothing
            for earlier in reversed(done):
                earlier.undo()
            raise
        self.report({"INFO"}, f"Imported {total} shapes from {len(parsed)} SDL file(s)")
        if parsed and kept_view:
            self.report({"INFO"}, f"The scene keeps its View Transform ({context.scene.view_settings.view_transform}): "
                                  "choose Colour Management SDL's to see the tracer's colours unchanged")

    def draw(self, context):
        layout = self.layout
        layout.use_property_split = True
        layout.prop(self, "strict")
        layout.prop(self, "set_camera")
        layout.prop(self, "colour_management")
        layout.prop(self, "axis_forward")
        layout.prop(self, "axis_up")


@orientation_helper(axis_forward="-Z", axis_up="Y")
class EXPORT_SCENE_OT_sdl(bpy.types.Operator, ExportHelper):
    """Export the scene as SDL (generic shapes exactly, other objects as .3vn meshes beside the file)"""

    bl_idname = "export_scene.sdl"
    bl_label = "Export SDL"
    bl_options = {"REGISTER", "PRESET"}

    filename_ext = ".sdl"
    filter_glob: StringProperty(default="*.sdl;*.dat", options={"HIDDEN"})
    use_selection: BoolProperty(name="Selected Only", default=False)

    def execute(self, context):
        conversion = convert.axis_matrix(self.axis_forward, self.axis_up)
        try:
            warnings = exporter.export_sdl(context, self.filepath, conversion, use_selection=self.use_selection)
        except Exception as exc:  # noqa: BLE001 - reported in Blender's UI, never a traceback
            if not isinstance(exc, (OSError, ValueError, errors.TracerError)):  # (a TracerError names the file)
                traceback.print_exc()
            self.report({"ERROR"}, f"Cannot export {os.path.basename(self.filepath)}: {exc}")
            return {"CANCELLED"}
        _report_warnings(self, warnings)
        self.report({"INFO"}, f"Exported {os.path.basename(self.filepath)}")
        return {"FINISHED"}


#: The Add menu's shapes: every registered kind that needs no file (tracer/shapes.py).
SHAPE_ITEMS = [(e.keyword, e.keyword, f"The generic {e.keyword}") for e in REGISTRY if e.addable]


class OBJECT_OT_sdl_add_shape(bpy.types.Operator):
    """Add an SDL generic shape (ray traced exactly by the SDL Ray Tracer)"""

    bl_idname = "object.sdl_add_shape"
    bl_label = "SDL Shape"
    bl_options = {"REGISTER", "UNDO"}

    kind: EnumProperty(name="Shape", items=SHAPE_ITEMS, default="sphere")
    # (and a FloatProperty per registered shape parameter: see _PARAMETERS below)

    def draw(self, context):
        self.layout.prop(self, "kind")
        for parameter in KINDS[self.kind].parameters:
            self.layout.prop(self, parameter.name)

    def execute(self, context):
        entry = KINDS[self.kind]
        shape = model.Shape(self.kind, parameters=tuple(getattr(self, p.name) for p in entry.parameters))
        if entry.builtin_mesh:
            shape.mesh = builtin_mesh(self.kind)
        matrix = np.eye(4)
        matrix[:3, 3] = tuple(context.scene.cursor.location)
        shape.matrix = matrix
        imp = importer.Importer(context, np.eye(4))
        imp.result.collection = context.collection or context.scene.collection
        try:
            obj = imp.shape_object(shape, importer.default_material(imp.created))
            context.view_layer.update()
            obj[importer.OBJ_SHOWN] = importer.flat(obj.matrix_world)
        except Exception as exc:  # noqa: BLE001 - reported in Blender's UI, what was made removed again
            imp.created.remove_all()
            traceback.print_exc()
            self.report({"ERROR"}, f"Cannot add {self.kind}: {exc}")
            return {"CANCELLED"}
        for other in context.selected_objects:
            other.select_set(False)
        obj.select_set(True)
        context.view_layer.objects.active = obj
        return {"FINISHED"}


#: The Add operator's property for each registered shape parameter (by its name, shared by the kinds that
#: have it), labelled as the registry says.
_PARAMETERS = {p.name: FloatProperty(name=p.label, default=p.add_value, description=p.description)
               for e in REGISTRY for p in e.parameters}
OBJECT_OT_sdl_add_shape.__annotations__.update(_PARAMETERS)


class VIEW3D_MT_sdl_add(bpy.types.Menu):
    bl_idname = "VIEW3D_MT_sdl_add"
    bl_label = "SDL Shape"

    def draw(self, context):
        for kind, label, _ in SHAPE_ITEMS:
            self.layout.operator(OBJECT_OT_sdl_add_shape.bl_idname, text=label).kind = kind


def menu_import(self, context):
    self.layout.operator(IMPORT_SCENE_OT_sdl.bl_idname, text="SDL (.sdl, .dat)")


def menu_export(self, context):
    self.layout.operator(EXPORT_SCENE_OT_sdl.bl_idname, text="SDL (.sdl)")


def menu_add(self, context):
    self.layout.menu(VIEW3D_MT_sdl_add.bl_idname, icon="SHADING_RENDERED")


CLASSES = [IMPORT_SCENE_OT_sdl, EXPORT_SCENE_OT_sdl, OBJECT_OT_sdl_add_shape, VIEW3D_MT_sdl_add]

if hasattr(bpy.types, "FileHandler"):  # Blender 4.1+: drag and drop
    class IO_FH_sdl(bpy.types.FileHandler):
        bl_idname = "IO_FH_sdl"
        bl_label = "SDL scene"
        bl_import_operator = "import_scene.sdl"
        bl_file_extensions = ".sdl;.dat"

        @classmethod
        def poll_drop(cls, context):
            try:
                from bpy_extras.io_utils import poll_file_object_drop
            except ImportError:
                return context.area is not None and context.area.type == "VIEW_3D"
            return poll_file_object_drop(context)

    CLASSES.append(IO_FH_sdl)

_MENUS = (("TOPBAR_MT_file_import", menu_import), ("TOPBAR_MT_file_export", menu_export),
          ("VIEW3D_MT_add", menu_add))


def register() -> None:
    for cls in CLASSES:
        bpy.utils.register_class(cls)
    for menu, func in _MENUS:
        getattr(bpy.types, menu).append(func)


def unregister() -> None:
    for menu, func in reversed(_MENUS):
        owner = getattr(bpy.types, menu, None)
        if owner is not None:
            owner.remove(func)  # a function not in the menu is ignored
    for cls in reversed(CLASSES):
        if cls.is_registered:
            bpy.utils.unregister_class(cls)
