"""What the engine made of each object's geometry, kept between scene builds and dropped when it changes.

Converting a big mesh from Blender (reading its arrays, splitting it per material) and building its BVH are
the slow part of turning a depsgraph into a tracer scene; placing it (its matrix), its materials and the
lights are not.  So the engine keeps, per object, what came from its *geometry* alone, and each update
Blender reports (``depsgraph.updates``, read in ``view_update`` and, for final renders, in ``update``) drops
only what it invalidates:

* an object whose geometry changed (``is_updated_geometry``: an edit, a modifier, a new mesh assigned, an
  animated deformation) loses its entry, and so does every object using a changed mesh or curve datablock;
* a transform (``is_updated_transform``) or a material edit (``is_updated_shading``) drops nothing: the
  matrix and materials are read anew on every build, and the mesh, in its own coordinates under that
  matrix, keeps its arrays and so its built BVH (compile.shared_triangle_mesh finds it by content);
* an object that a build no longer meets (deleted, hidden, another scene) is dropped after that build;
* a file load, undo or redo drops everything (datablocks are reallocated: the pointers that key the
  entries may then name other objects), and so does a build for another scene or view layer.

Entries are keyed by the original object's pointer and checked against its name, type and data pointer.
Geometry that only exists inside an evaluation (instances made by geometry nodes) is not kept between
builds; within one build it is made once per evaluated datablock, so that the instances of one mesh share
what was made of it (and so one BVH).
"""
from __future__ import annotations

import weakref
from collections import Counter
from typing import Callable

import bpy

#: Every live cache, so that a file load or an undo step can empty them (see forget_everything).
_LIVE: "weakref.WeakSet[ObjectCache]" = weakref.WeakSet()


def _pointer(datablock) -> int:
    original = getattr(datablock, "original", None) or datablock
    return original.as_pointer()


def _identity(original) -> tuple:
    data = original.data
    return original.name_full, original.type, data.as_pointer() if data is not None else 0


class ObjectCache:
    """Per object, the values made from its geometry (``get``), until an update says the geometry changed.

    ``made`` counts what was made, by kind, over the cache's life (the tests check that moving a light
    makes nothing again)."""

    def __init__(self) -> None:
        self._entries: dict[int, tuple[tuple, dict]] = {}  # object pointer -> (identity, kind -> value)
        self._by_data: dict[int, set[int]] = {}  # data pointer -> pointers of objects using it
        self._seen: set[int] = set()  # objects met since begin_build
        self._this_build: dict[tuple[int, str], object] = {}  # (evaluated data pointer, kind) -> value
        self._graph = None  # (scene, view layer) of the last build
        self.made: Counter = Counter()
        self.clears = 0  # times emptied (a file load, an undo): what others keep beside it is then stale too
        _LIVE.add(self)

    def __len__(self) -> int:
        return len(self._entries)

    def clear(self) -> None:
        self._entries.clear()
        self._by_data.clear()
        self.clears += 1

    # -- what changed ---------------------------------------------------------------------------------

    def apply_updates(self, updates) -> None:
        """Drop the entries that ``updates`` (a ``depsgraph.updates``, read where Blender offers it: view_update,
        RenderEngine.update) says are out of date."""
        for update in updates:
            if not update.is_updated_geometry:
                continue
            datablock = update.id
            if isinstance(datablock, bpy.types.Object):
                self.forget(_pointer(datablock))
            else:  # a mesh, curve, ... : every object built from it
                for pointer in self._by_data.pop(_pointer(datablock), ()):
                    self.forget(pointer)

    def forget(self, pointer: int) -> None:
        """Drop what was made of one object (by its original's pointer)."""
        entry = self._entries.pop(pointer, None)
        if entry is not None:
            users = self._by_data.get(entry[0][2])
            if users is not None:
                users.discard(pointer)

    # -- one build ------------------------------------------------------------------------------------

    def begin_build(self, depsgraph) -> None:
        graph = (depsgraph.scene.name_full, depsgraph.view_layer.name)
        if graph != self._graph:
            self.clear()
            self._graph = graph
        self._seen = set()
        self._this_build = {}

    def end_build(self) -> None:
        """Drop the objects this build did not meet."""
        self._this_build = {}
        for pointer in [p for p in self._entries if p not in self._seen]:
            self.forget(pointer)

    def get(self, obj_eval, kind: str, make: Callable[[], object], own: bool = True):
        """The ``kind`` value made from this evaluated object's geometry: kept from an earlier build while
        its geometry is unchanged, else ``make()``.  ``own`` is False for an instance that geometry nodes
        made: it has the instancing object as its original, but not its geometry, so it is kept for this
        build only, by its evaluated datablock (which all the instances of one geometry share)."""
        original = getattr(obj_eval, "original", None)
        if not own or original is None or original.data is None:
            data = getattr(obj_eval, "data", None)
            key = (data.as_pointer() if data is not None else id(obj_eval), kind)
            if key not in self._this_build:
                self.made[kind] += 1
                self._this_build[key] = make()
            return self._this_build[key]
        pointer, identity = original.as_pointer(), _identity(original)
        self._seen.add(pointer)
        entry = self._entries.get(pointer)
        if entry is None or entry[0] != identity:
            self.forget(pointer)
            entry = self._entries[pointer] = (identity, {})
            self._by_data.setdefault(identity[2], set()).add(pointer)
        values = entry[1]
        if kind not in values:
            self.made[kind] += 1
            values[kind] = make()
        return values[kind]


@bpy.app.handlers.persistent
def forget_everything(*_args) -> None:
    """load_post, undo_post, redo_post: other datablocks than before, perhaps at the same addresses."""
    for cache in list(_LIVE):
        cache.clear()


#: The handlers above, by the bpy.app.handlers list they go in (see ui.register).
HANDLERS = (("load_post", forget_everything), ("undo_post", forget_everything), ("redo_post", forget_everything))
