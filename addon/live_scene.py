"""The tracer scene of what Blender shows, kept in step with Blender's changes by editing it in place.

The engine keeps one LiveScene for its viewport, and one for F12 while Persistent Data keeps the engine.
Blender says what changed (``depsgraph.updates``, read in view_update and RenderEngine.update:
:meth:`LiveScene.take_updates`); the next draw or render (:meth:`LiveScene.compiled`) applies it to the
compiled scene with tracer.edit's edits, each touching only its own rows (docs/tracer.md, "Editing a compiled
scene"), objects named by their Blender object's pointer:

* objects moved: their new matrices, all at once (``set_transforms``: one pass, one refit);
* an object whose geometry changed (an edit, a modifier, another mesh) is read out of Blender again, it
  alone (the object cache keeps everyone else's), and its objects replaced (``replace_objects``);
* a material edited: its one row (``replace_material``), whatever number of objects use it; an object given
  another material: its own objects;
* lights: the light rows (``set_lights``);
* objects added or removed, shown or hidden (Blender then updates the scene or a collection): the objects
  the depsgraph shows compared with those the scene has (``add_objects``, ``remove_objects``).

Everything else (the world, the recursion depth, a new picture texture, a scene with instances, another
scene or view layer, a file load or undo) builds the whole scene again, as does an edit that fails.  The
image after an edit is the image of a scene built from scratch (tests/test_addon_live.py, for each kind).
"""
from __future__ import annotations

import math
import time
from collections import Counter
from typing import Optional

import bpy
import numpy as np

from . import object_cache, props
from .scene_build import GEOMETRY_TYPES, OBJ_ORDER, SceneBuilder, matrix_np
from .tracer import model
from .tracer.edit import EditableScene


class _Pending:
    """What Blender said changed since the last sync."""

    def __init__(self) -> None:
        self.objects: dict[int, list] = {}  # object pointer -> [original object, geometry changed, shading changed]
        self.data: set[int] = set()  # meshes, curves, ... whose geometry changed
        self.materials: dict[int, object] = {}  # material pointer -> material
        self.structure = False  # the scene or a collection changed: objects may have come or gone
        self.world = False

    def __bool__(self) -> bool:
        return bool(self.objects or self.data or self.materials or self.structure or self.world)


class LiveScene:
    """The compiled scene of one engine's depsgraph, edited in place as Blender's updates say (see the
    module's docstring).  ``done`` counts what the syncs did ("full" builds; objects "moved", "replaced",
    "added", "removed"; "materials" and "lights" edited), for the tests and the bench."""

    def __init__(self, cache: Optional[object_cache.ObjectCache] = None) -> None:
        self.cache = object_cache.ObjectCache() if cache is None else cache
        self.editable: Optional[EditableScene] = None
        self.warnings: list[str] = []
        self.done: Counter = Counter()
        #: what the last sync did ("full", "edit" or "none") and the seconds it took
        self.last_sync: tuple[str, float] = ("none", 0.0)
        self._pending = _Pending()
        self._builder: Optional[SceneBuilder] = None
        self._held = None  # (scene, view layer, mode, cache clears) the scene was built for
        self._objects: dict[int, tuple] = {}  # object pointer -> (original, its material slots', its data's pointers)
        self._data_users: dict[int, set[int]] = {}  # data pointer -> pointers of the objects built from it
        self._lights: dict[int, tuple] = {}  # light object pointer -> (sort key, original)
        self._instanced = False  # the scene has instances: every sync builds it all
        self._edits = 0  # edits the editable scene had made at the last sync
        self.changed = True

    def clear(self) -> None:
        """Build everything again at the next sync."""
        self.editable = self._builder = None

    # -- what changed ---------------------------------------------------------------------------------

    def take_updates(self, depsgraph) -> None:
        """Note what ``depsgraph.updates`` says changed (call it where Blender offers them: view_update,
        RenderEngine.update); the object cache drops the geometry they invalidate."""
        updates = list(depsgraph.updates)  # (each reading looks through every datablock the depsgraph has)
        self.cache.apply_updates(updates)
        if self.editable is None:  # (the next sync builds everything: a first render lists every datablock)
            return
        pending = self._pending
        for update in updates:
            datablock = update.id
            original = getattr(datablock, "original", None) or datablock
            if isinstance(datablock, bpy.types.Object):
                entry = pending.objects.setdefault(original.as_pointer(), [original, False, False])
                entry[1] |= update.is_updated_geometry
                entry[2] |= update.is_updated_shading
            elif isinstance(datablock, bpy.types.Material):
                pending.materials[original.as_pointer()] = original
            elif isinstance(datablock, (bpy.types.Scene, bpy.types.Collection)):
                pending.structure = True
            elif isinstance(datablock, bpy.types.World):
                pending.world = True
            elif update.is_updated_geometry and not isinstance(datablock, bpy.types.NodeTree):
                pending.data.add(original.as_pointer())

    # -- the scene ------------------------------------------------------------------------------------

    def compiled(self, depsgraph, mode: str):
        """The compiled scene of ``depsgraph`` now (built, or edited as the updates since the last call say),
        and the warnings of what was made for it."""
        started = time.perf_counter()
        held = (depsgraph.scene.name_full, depsgraph.view_layer.name, mode, self.cache.clears)
        what = "none"
        if self.editable is None or held != self._held or self._instanced:
            self._build(depsgraph, mode)
            what = "full"
        elif self._pending:
            try:
                what = "edit" if self._edit(depsgraph) else "full"
            except Exception:  # noqa: BLE001 - an edit that cannot be made: the whole scene, as before
                self._build(depsgraph, mode)
                what = "full"
        self._pending = _Pending()
        self.last_sync = (what, time.perf_counter() - started)
        edits = sum(self.editable.done.values())
        #: whether the scene changed since the last call (built, or edited: a selection, say, changes nothing)
        self.changed = what == "full" or edits != self._edits
        self._edits = edits
        return self.editable.compiled, list(self.warnings)

    def _build(self, depsgraph, mode: str) -> None:
        builder = SceneBuilder(depsgraph, mode=mode, cache=self.cache)
        scene = builder.build(depsgraph.scene)
        self.editable = EditableScene(scene, builder.object_keys)
        self._builder = builder
        self._held = (depsgraph.scene.name_full, depsgraph.view_layer.name, mode, self.cache.clears)
        self._instanced = any(isinstance(key, tuple) for key in builder.object_keys)
        self.warnings = list(builder.warnings)
        keys = set(builder.object_keys)
        self._objects, self._data_users = {}, {}
        for obj in depsgraph.objects:
            original = obj.original
            if original.as_pointer() in keys:
                self._note(original)
        self._lights = {obj.original.as_pointer(): (_sort_key(obj.original), obj.original)
                        for obj in builder.light_objects}
        self.done["full"] += 1

    def _note(self, original) -> None:
        """Remember what an object's tracer objects were made from: its material slots and its data."""
        pointer = original.as_pointer()
        known = self._objects.get(pointer)
        if known is not None:
            self._data_users.get(known[2], set()).discard(pointer)
        data = original.data.as_pointer() if original.data is not None else 0
        self._objects[pointer] = (original, _slot_pointers(original), data)
        self._data_users.setdefault(data, set()).add(pointer)

    def _forget(self, pointer: int) -> None:
        _, _, data = self._objects.pop(pointer)
        self._data_users.get(data, set()).discard(pointer)
        if pointer in self.editable:
            self.editable.remove_objects(pointer)
        self.cache.forget(pointer)
        self.done["removed"] += 1

    # -- edits ----------------------------------------------------------------------------------------

    def _edit(self, depsgraph) -> bool:
        """Apply the pending updates as edits; False when the whole scene had to be built instead."""
        pending, editable, builder = self._pending, self.editable, self._builder
        mode = self._held[2]
        scene = depsgraph.scene
        if pending.world or pending.structure:
            depth = scene.sdl_render.max_recursion_depth if hasattr(scene, "sdl_render") else 3
            if props.world_settings(scene.world, depth, []) != editable.scene.settings:
                self._build(depsgraph, mode)
                return False
        pixmaps = builder.pixmaps
        materials = builder.refresh(depsgraph, pending.materials.values())
        # object pointer -> (original, remade: its geometry or its material slots changed)
        changed: dict[int, tuple] = {}
        for pointer, (original, geometry, shading) in pending.objects.items():
            known = self._objects.get(pointer)
            reslotted = shading and known is not None and _slot_pointers_safe(original) != known[1]
            changed[pointer] = (original, geometry or reslotted)
        for data in pending.data:
            for pointer in self._data_users.get(data, ()):
                changed[pointer] = (self._objects[pointer][0], True)
        lights = False
        with editable.batch():
            for old, new in materials:  # one row each, for every object that has it
                editable.replace_material(old, new)
                self.done["materials"] += 1
            if pending.structure:
                lights |= self._add_and_remove(depsgraph, changed)
            moves = []
            for pointer, (original, remade) in changed.items():
                if pointer in self._lights:
                    lights = True
                if pointer not in self._objects:
                    continue
                obj_eval = _evaluated(original, depsgraph)
                if obj_eval is None:
                    continue
                nodes = builder.object_node(obj_eval, matrix_np(obj_eval.matrix_world))
                current = editable.objects_of(pointer) if pointer in editable else []
                # (Blender reports every user of a mesh when one of them gets another material, say: what
                # comes out as it was is left alone)
                matrix = None if remade else _moved_only(current, nodes)
                if matrix is not None:
                    if not np.array_equal(matrix, current[0].matrix):
                        moves.append((pointer, matrix))
                elif not _same_objects(current, nodes):
                    self._replace(pointer, nodes)
                if remade:
                    self._note(original)
            if moves:
                editable.set_transforms(moves)
                self.done["moved"] += len(moves)
            if lights:
                self._set_lights(depsgraph)
        if builder.pixmaps != pixmaps:  # a picture no object had before: the textures are made anew
            self._build(depsgraph, mode)
            return False
        self.warnings = list(builder.warnings)
        return True

    def _replace(self, pointer: int, nodes: list) -> None:
        editable = self.editable
        if pointer in editable:
            editable.replace_objects(pointer, nodes)  # (no nodes: removed)
        elif nodes:
            editable.add_objects(pointer, nodes)
        self.done["replaced"] += 1

    def _add_and_remove(self, depsgraph, changed: dict) -> bool:
        """Compare the objects the depsgraph shows with those the scene has: forget the ones gone, mark the
        new ones to be made (in ``changed``); True if the lights changed."""
        shown: dict[int, object] = {}
        for inst in depsgraph.object_instances:
            if inst.is_instance:
                raise _Instanced()
            if getattr(inst, "show_self", True):
                original = inst.object.original
                shown[original.as_pointer()] = original
        lights = False
        for pointer in [p for p in self._objects if p not in shown]:
            self._forget(pointer)
            changed.pop(pointer, None)
        for pointer in [p for p in self._lights if p not in shown]:
            del self._lights[pointer]
            lights = True
        for pointer, original in shown.items():
            if original.type == "LIGHT":
                if pointer not in self._lights:
                    self._lights[pointer] = (_sort_key(original), original)
                    lights = True
            elif original.type in GEOMETRY_TYPES and pointer not in self._objects:
                self._note(original)
                changed[pointer] = (original, True)
                self.done["added"] += 1
        return lights

    def _set_lights(self, depsgraph) -> None:
        lights = []
        for _, original in sorted(self._lights.values(), key=lambda entry: entry[0]):
            obj_eval = _evaluated(original, depsgraph)
            if obj_eval is not None:
                lights.append(self._builder.light(obj_eval, matrix_np(obj_eval.matrix_world)))
        self.editable.set_lights(lights)
        self.done["lights"] += 1


class _Instanced(Exception):
    """The depsgraph shows instances: the scene is built whole."""


def _sort_key(original) -> tuple:
    """Where build() puts an object: import order, then name."""
    return (original.get(OBJ_ORDER, math.inf), original.name)


def _slot_pointers(original) -> tuple:
    return tuple(slot.material.as_pointer() if slot.material is not None else 0 for slot in original.material_slots)


def _slot_pointers_safe(original):
    try:
        return _slot_pointers(original)
    except ReferenceError:  # (deleted since)
        return None


def _evaluated(original, depsgraph):
    try:
        return original.evaluated_get(depsgraph)
    except (ReferenceError, RuntimeError):
        return None


def _moved_only(current: list, nodes: list):
    """The one matrix all of ``nodes`` have, when they are ``current`` moved (plain shapes of the same kind,
    parameters, mesh and material, every one at that matrix); else None."""
    if not nodes or len(nodes) != len(current):
        return None
    matrix = getattr(nodes[0], "matrix", None)
    if matrix is None:
        return None
    for old, new in zip(current, nodes):
        if not (isinstance(old, model.Shape) and isinstance(new, model.Shape)) or old.kind != new.kind \
                or old.parameters != new.parameters or old.mesh is not new.mesh or old.material is not new.material \
                or not np.array_equal(new.matrix, matrix):
            return None
    return matrix


def _same_objects(current: list, nodes: list) -> bool:
    return len(current) == len(nodes) and all(a == b for a, b in zip(current, nodes))
