"""Editing a compiled scene in place: move, re-material, re-mesh, add and remove objects, move lights.

An :class:`EditableScene` holds a scene, its :class:`~tracer.compile.CompiledScene` and (once the C core has
traced it) the flattened C scene, and keeps all three in step with each edit, touching only the rows the
edit concerns.  Render ``editable.compiled`` (``tracer.render``, ``backend.make_tracer``, the add-on's
``BlockRenderer``): both backends trace the edited scene, and the image is byte for byte the image of the
edited ``editable.scene`` compiled from scratch.

Objects are named by *keys*: any hashable value per top-level object of the scene (the Blender add-on uses
each Blender object's pointer), given when the scene is made editable (default: the objects' positions
then, 0, 1, ...).  Several objects may share one key — the parts of one Blender mesh, one per material —
and are then edited together, in their order in the scene.  Keys stay valid across every edit;
positions do not (a removal shifts the objects after it).

What each edit costs (see docs/tracer.md, "Editing a compiled scene"):

* ``set_transform`` / ``set_matrices``: the key's primitive rows (matrix, inverse, rounding, bounds) and
  its objects' boxes, then a *refit* of the C core's object hierarchy (each changed leaf's boxes up to the
  root); nothing else.
* ``set_material`` / ``replace_material``: one material row (a new row for a new material).
* ``replace_mesh``: that mesh's BVH, built once per content (meshes stay shared by content), and the rows
  of the shapes that use it.
* ``add_objects`` / ``remove_objects`` / ``replace_objects`` with another structure: their own rows, then a
  rebuild of the object hierarchy (on the tracer's threads).
* ``set_lights``: the light rows.

An edit that changes which *live effects* the scene has (the first reflective material, the first texture,
the last light) recomputes what depends on the effects (the effect set, textures, the shading variant);
the ray savings of tracer.savings (sealed lights, dark materials) follow every edit.  Edits must not run
while a render of the same scene is tracing.
"""
from __future__ import annotations

import dataclasses
from collections.abc import Hashable, Iterable, Sequence
from contextlib import contextmanager
from typing import Optional

import numpy as np

from .compile import CompiledScene, compile_scene, fold_tree
from .errors import TracerError
from .model import CSG, MESH_KINDS, Light, Material, MeshData, Scene, SceneObject, Shape, ShapeTable


class EditableScene:
    """A scene compiled once and then edited in place (see the module's docstring)."""

    def __init__(self, scene: Scene, keys: Optional[Sequence[Hashable]] = None):
        """``scene`` is taken over: its ``objects`` list is edited along with the compiled scene (a
        ShapeTable is made into its list of Shapes).  ``keys``: one per top-level object (default: the
        objects' positions)."""
        if isinstance(scene.objects, ShapeTable):
            scene.objects = list(scene.objects)
        n = len(scene.objects)
        keys = list(range(n)) if keys is None else list(keys)
        if len(keys) != n:
            raise TracerError(f"{len(keys)} keys for {n} objects")
        self.scene = scene
        self._keys: list[Hashable] = keys
        self._positions: dict[Hashable, list[int]] = {}
        self._index_keys()
        self._batch_depth = 0
        self._dirty = False
        self.compiled: CompiledScene = compile_scene(scene)

    # -- keys ---------------------------------------------------------------------------------------------

    def keys(self) -> list[Hashable]:
        """The keys, each once, in the order of their first object."""
        return list(self._positions)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._positions

    def __len__(self) -> int:
        """The number of top-level objects."""
        return len(self._keys)

    def objects_of(self, key: Hashable) -> list[SceneObject]:
        """The key's top-level objects, in scene order."""
        return [self.scene.objects[i] for i in self._where(key)]

    def positions_of(self, key: Hashable) -> list[int]:
        """Where the key's objects are in ``scene.objects`` (and ``compiled.objects``) now."""
        return list(self._where(key))

    # -- edits --------------------------------------------------------------------------------------------

    def set_transform(self, key: Hashable, matrix) -> None:
        """Every shape of the key gets ``matrix`` (4 x 4, affine, invertible) as its own: for plain shapes
        (and the parts of one mesh) the new world matrix.  A boolean's leaves all get it too; to place a
        boolean's leaves one by one, use set_matrices."""
        count = sum(_leaf_count(obj) for obj in self.objects_of(key))
        self.set_matrices(key, [matrix] * count)

    def set_matrices(self, key: Hashable, matrices: Sequence) -> None:
        """The key's shapes get these matrices, one per shape in scene order (a boolean's leaves left to
        right)."""
        checked = [_checked_matrix(m, key) for m in matrices]
        objects = self.objects_of(key)
        if len(checked) != sum(map(_leaf_count, objects)):
            raise TracerError(f"object {key!r} has {sum(map(_leaf_count, objects))} shapes, "
                              f"not {len(checked)} matrices")
        it = iter(checked)
        self._replace_in_place(key, [_with_leaves(obj, lambda shape: dataclasses.replace(shape, matrix=next(it)))
                                     for obj in objects])

    def set_material(self, key: Hashable, material: Material) -> None:
        """Every shape of the key gets ``material``."""
        self._replace_in_place(key, [_with_leaves(obj, lambda shape: dataclasses.replace(shape, material=material))
                                     for obj in self.objects_of(key)])

    def replace_material(self, old: Material, new: Material) -> None:
        """Every shape whose material is the object ``old`` gets ``new`` instead (a material edited where
        many shapes share it: its one row changes)."""
        changed = False
        for i, obj in enumerate(self.scene.objects):
            if any(shape.material is old for shape in _leaves(obj)):
                self.scene.objects[i] = _with_leaves(
                    obj, lambda s: dataclasses.replace(s, material=new) if s.material is old else s)
                changed = True
        if changed:
            self._recompile()

    def replace_mesh(self, key: Hashable, mesh: MeshData) -> None:
        """Every mesh (and teapot) shape of the key gets ``mesh`` as its triangles."""
        def remesh(shape: Shape) -> Shape:
            return dataclasses.replace(shape, mesh=mesh) if shape.kind in MESH_KINDS else shape
        self._replace_in_place(key, [_with_leaves(obj, remesh) for obj in self.objects_of(key)])

    def replace_objects(self, key: Hashable, objects: Iterable[SceneObject]) -> None:
        """The key's objects become ``objects`` (any number, any kind; none removes the key).  Of the same
        structure as before (as many shapes, the same booleans), the rows are updated in place; else the
        old objects are removed and the new ones added at the end."""
        objects = list(objects)
        if not objects:
            self.remove_objects(key)
            return
        self._replace_in_place(key, objects) if _same_structure(self.objects_of(key), objects) else \
            self._remove_and_add(key, objects)

    def add_objects(self, key: Hashable, objects: Iterable[SceneObject]) -> None:
        """Add ``objects`` at the end of the scene under ``key`` (a new key, or more objects for one)."""
        objects = list(objects)
        if not objects:
            return
        for obj in objects:
            _check_object(obj, key)
        self.scene.objects.extend(objects)
        self._keys.extend([key] * len(objects))
        self._index_keys()
        self._recompile()

    def remove_objects(self, key: Hashable) -> None:
        """Remove every object of ``key`` (the key is then unknown)."""
        gone = set(self._where(key))
        self.scene.objects[:] = [o for i, o in enumerate(self.scene.objects) if i not in gone]
        self._keys = [k for i, k in enumerate(self._keys) if i not in gone]
        self._index_keys()
        self._recompile()

    def set_lights(self, lights: Sequence[Light]) -> None:
        """The scene's lights become ``lights``."""
        self.scene.lights = list(lights)
        self._recompile()

    def rebuild_hierarchy(self) -> None:
        """Build the C core's object hierarchy anew (refits keep it valid, but many large moves can make it
        slower to traverse than a fresh build)."""
        self._recompile()

    @contextmanager
    def batch(self):
        """Edits inside ``with editable.batch():`` update their rows at once but the object hierarchy only
        at the end (one refit or rebuild for all of them): for the many updates of one depsgraph change."""
        self._batch_depth += 1
        try:
            yield self
        finally:
            self._batch_depth -= 1
            if self._batch_depth == 0 and self._dirty:
                self._recompile()

    # -- internals ----------------------------------------------------------------------------------------

    def _where(self, key: Hashable) -> list[int]:
        try:
            return self._positions[key]
        except KeyError:
            raise TracerError(f"no object has the key {key!r}") from None

    def _index_keys(self) -> None:
        positions: dict[Hashable, list[int]] = {}
        for i, key in enumerate(self._keys):
            positions.setdefault(key, []).append(i)
        self._positions = positions

    def _replace_in_place(self, key: Hashable, objects: list[SceneObject]) -> None:
        for obj in objects:
            _check_object(obj, key)
        for i, obj in zip(self._where(key), objects):
            self.scene.objects[i] = obj
        self._recompile()

    def _remove_and_add(self, key: Hashable, objects: list[SceneObject]) -> None:
        with self.batch():
            self.remove_objects(key)
            self.add_objects(key, objects)

    def _recompile(self) -> None:
        """(The first implementation: compile again; the in-place edits replace this step by step.)"""
        if self._batch_depth:
            self._dirty = True
            return
        self._dirty = False
        self.compiled = compile_scene(self.scene)


def _leaves(obj: SceneObject) -> list[Shape]:
    return fold_tree(obj, lambda shape: [shape], lambda _, left, right: left + right)


def _leaf_count(obj: SceneObject) -> int:
    return fold_tree(obj, lambda _: 1, lambda _, left, right: left + right)


def _with_leaves(obj: SceneObject, change) -> SceneObject:
    """``obj`` with each leaf shape replaced by ``change(shape)`` (booleans made anew above changed leaves)."""
    return fold_tree(obj, change, lambda node, left, right: dataclasses.replace(node, left=left, right=right))


def _structure(obj: SceneObject):
    return fold_tree(obj, lambda _: None, lambda node, left, right: (node.op, left, right))


def _same_structure(old: list[SceneObject], new: list[SceneObject]) -> bool:
    return len(old) == len(new) and all(_structure(a) == _structure(b) for a, b in zip(old, new))


def _checked_matrix(matrix, key: Hashable) -> np.ndarray:
    """A float64 4 x 4 copy of ``matrix``, or a TracerError naming the key if it is not a finite affine
    invertible matrix."""
    try:
        m = np.array(matrix, dtype=np.float64)
    except (TypeError, ValueError):
        m = None
    if m is None or m.shape != (4, 4) or not np.isfinite(m).all() or np.any(m[3] != (0, 0, 0, 1)):
        raise TracerError(f"object {key!r}: the transform is not a finite affine 4 x 4 matrix")
    try:
        inverse = np.linalg.inv(m)
    except np.linalg.LinAlgError:
        inverse = None
    if inverse is None or not np.isfinite(inverse).all():
        raise TracerError(f"object {key!r}: the transform is singular (a scale of 0?)")
    return m


def _check_object(obj: SceneObject, key: Hashable) -> None:
    for shape in _leaves(obj):
        if not isinstance(shape, Shape):
            raise TracerError(f"object {key!r}: {type(shape).__name__} is not a shape or a boolean")
        _checked_matrix(shape.matrix, key)
