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

What each edit recomputes (docs/tracer.md, "Editing a compiled scene", has the table and the costs):

* a move (``set_transform``, ``set_transforms``, ``set_matrices``): the key's primitive rows (inverse,
  rounding, bounds) and its objects' boxes, then a *refit* of the C core's object hierarchy;
* a material (``set_material``, ``replace_material``): one material row (a new row for a new material);
* a mesh (``replace_mesh``): that mesh's BVH, built once per content (meshes stay shared by content), and
  the rows of the shapes that use it;
* ``add_objects`` / ``remove_objects`` / ``replace_objects`` with another structure: their own rows, the
  FlatScene made anew, a rebuild of the object hierarchy (on the tracer's threads);
* ``set_lights``: the light rows; ``set_settings``: the materials' traits; ``set_pixmaps``: the pictures
  whose file changed.

An edit that changes which *live effects* the scene has (the first reflective material, the first texture,
the last light) recomputes what depends on the effects (the effect set, textures, the shading variant);
the ray savings (tracer.skippable: sealed lights, dark materials) follow every edit.  Edits must not run
while a render of the same scene is tracing.
"""
from __future__ import annotations

import dataclasses
import functools
import os
from collections import Counter
from collections.abc import Hashable, Iterable, Mapping, Sequence
from contextlib import contextmanager
from typing import Optional

import numpy as np

from .bulk import one_blas_thread
from .compile import CompiledObjects, CompiledScene, CSGNode, compile_scene, delete_positions, fold_tree
from .edit_ledger import MaterialLedger
from .errors import TracerError
from .model import (CSG, MESH_KINDS, SHAPE_KINDS, Light, Material, MeshData, Scene, SceneObject, Settings, Shape,
                    ShapeTable)
from .lights import LightTable
from .native import flatten
from .skippable import sealed_lights
from .textures import TextureSet
from .textures.images import load_image
from .textures.solid import SOLID_TEXTURES
from .threads import default_threads


def _edit(method):
    """An edit: with OpenBLAS on one thread (as compile_scene inverts its matrices; else each small inverse
    wakes its threads, milliseconds each on a busy machine)."""
    @functools.wraps(method)
    def edit(self, *args, **kwargs):
        with one_blas_thread():
            return method(self, *args, **kwargs)
    return edit


class EditableScene:
    """A scene compiled once and then edited in place (see the module's docstring)."""

    def __init__(self, scene: Scene, keys: Optional[Sequence[Hashable]] = None):
        """``scene`` is taken over: its ``objects`` list is edited along with the compiled scene (a
        ShapeTable is made into its list of Shapes, and compiled from that).  ``keys``: one per top-level
        object (default: the objects' positions)."""
        if isinstance(scene.objects, ShapeTable):
            scene.objects = list(scene.objects)
        n = len(scene.objects)
        keys = list(range(n)) if keys is None else list(keys)
        if len(keys) != n:
            raise TracerError(f"{len(keys)} keys for {n} objects")
        self.scene = scene
        # Each top-level object has a serial number for life; a key names the serials of its objects, and
        # _position (by serial) says where each is now: a removal renumbers positions with one array
        # operation, and touches no other key.
        self._serials_of: dict[Hashable, list[int]] = {}
        for serial, key in enumerate(keys):
            self._serials_of.setdefault(key, []).append(serial)
        self._serial = np.arange(n, dtype=np.int64)  # by position
        self._position = np.arange(n, dtype=np.int64)  # by serial (-1: removed)
        # Shapes this scene made (by id; each in the scene once): a later move or material edit changes them
        # in place instead of making another (an animation frame makes no new Shape after the first)
        self._owned: set[int] = set()
        self.compiled: CompiledScene = compile_scene(scene)
        compiled = self.compiled
        self._materials = MaterialLedger(compiled)
        self._leaf_counts = np.ones(n, dtype=np.int64)
        for k, obj in compiled.objects.booleans.items():
            self._leaf_counts[k] = sum(1 for _ in obj.leaves())
        self._starts = np.concatenate([[0], np.cumsum(self._leaf_counts)])
        self._images = dict(getattr(compiled.textures, "images", None) or {})
        self._stamps = {number: _stamp(scene.pixmaps[number]) for number in self._images}
        # what the C core has not been told yet (see _sync): objects whose boxes changed, and how
        self._batch_depth = 0
        self._pending_objects: set[int] = set()
        self._pending_meshes = self._pending_rebuild = self._pending_flat = False
        self._refitted = 0  # objects refitted since the hierarchy was last built
        # material rows the FlatScene has not read yet (written in place, or added)
        self._rows_written: set[int] = set()
        #: what the edits did, for the tests and the bench: "rows", "materials", "effects", "textures",
        #: "refit", "rebuild", "restructure" (objects added or removed in the C core's scene), "flat" (the
        #: FlatScene made anew), counted since the scene was made editable
        self.done: Counter = Counter()

    # -- keys ---------------------------------------------------------------------------------------------

    def keys(self) -> list[Hashable]:
        """The keys, each once, in the order of their first object."""
        return list(self._serials_of)

    def __contains__(self, key: Hashable) -> bool:
        return key in self._serials_of

    def __len__(self) -> int:
        """The number of top-level objects."""
        return len(self._serial)

    def objects_of(self, key: Hashable) -> list[SceneObject]:
        """The key's top-level objects, in scene order (as they are now: a shape an edit made may be changed
        in place by a later edit; a shape the caller gave never is)."""
        return [self.scene.objects[i] for i in self._where(key)]

    def positions_of(self, key: Hashable) -> list[int]:
        """Where the key's objects are in ``scene.objects`` (and ``compiled.objects``) now."""
        return list(self._where(key))

    # -- edits --------------------------------------------------------------------------------------------

    @_edit
    def set_transform(self, key: Hashable, matrix) -> None:
        """Every shape of the key gets ``matrix`` (4 x 4, affine, invertible) as its own: for plain shapes
        (and the parts of one mesh) the new world matrix.  A boolean's leaves all get it too; to place a
        boolean's leaves one by one, use set_matrices."""
        positions = self._where(key)
        self.set_matrices(key, [matrix] * int(self._leaf_counts[positions].sum()))

    @_edit
    def set_matrices(self, key: Hashable, matrices: Sequence) -> None:
        """The key's shapes get these matrices, one per shape in scene order (a boolean's leaves left to
        right)."""
        objects = self.objects_of(key)
        count = int(self._leaf_counts[self._where(key)].sum())
        if len(matrices) != count:
            raise TracerError(f"object {key!r} has {count} shapes, not {len(matrices)} matrices")
        checked = iter([_checked_matrix(m, key) for m in matrices])
        self._replace_in_place(key, [_with_leaves(obj, lambda shape: self._changed(shape, "matrix", next(checked)))
                                     for obj in objects], checked=True)

    @_edit
    def set_transforms(self, changes: Iterable[tuple[Hashable, object]]) -> None:
        """Many set_transform at once, ``(key, matrix)`` pairs (the last one wins for a key given twice): one
        pass over their rows and one refit (or rebuild) of the hierarchy, as for an animation frame that
        moves every object.  Every matrix is checked before anything changes."""
        wanted = dict(changes)
        keys = list(wanted)
        matrices = _checked_matrices([wanted[k] for k in keys], keys)
        serials = [self._serials_of.get(key) for key in keys]
        for key, found in zip(keys, serials):
            if found is None:
                self._where(key)  # (raises naming it)
        counts = np.fromiter(map(len, serials), dtype=np.int64, count=len(keys))
        positions = self._position[np.concatenate(serials)].tolist() if keys else []
        scene_objects, changed = self.scene.objects, self._changed
        objects = [_with_leaves(scene_objects[p], lambda shape: changed(shape, "matrix", matrix))
                   for p, matrix in zip(positions, np.repeat(matrices, counts, axis=0))]
        if positions:
            self._replace_at(positions, objects, same_materials=True)

    @_edit
    def set_material(self, key: Hashable, material: Material) -> None:
        """Every shape of the key gets ``material``."""
        self._check_material(material, f"object {key!r}")  # (before any shape changes)
        self._replace_in_place(key, [_with_leaves(obj, lambda shape: self._changed(shape, "material", material))
                                     for obj in self.objects_of(key)], checked=True)

    @_edit
    def replace_material(self, old: Material, new: Material) -> None:
        """Every shape whose material is the object ``old`` gets ``new`` instead (a material edited where
        many shapes share it: its one row changes, if ``new`` has none yet)."""
        row = self._materials.rows.get(id(old))
        if row is None or old is new:
            return
        self._check_material(new, "a material")
        rows = np.flatnonzero(self.compiled.table.material_ids == row)
        positions = np.unique(np.searchsorted(self._starts, rows, side="right") - 1).tolist()
        if id(new) not in self._materials.rows:  # (the row is the new material's from now on)
            self._rows_written.add(self._materials.rewrite(old, new))
            self.done["materials"] += 1
        with self.batch():
            for p in positions:
                obj = self.scene.objects[p]
                self._replace_at([p], [_with_leaves(
                    obj, lambda s: self._changed(s, "material", new) if s.material is old else s)])

    @_edit
    def replace_mesh(self, key: Hashable, mesh: MeshData) -> None:
        """Every mesh (and teapot) shape of the key gets ``mesh`` as its triangles."""
        def remesh(shape: Shape) -> Shape:
            return dataclasses.replace(shape, mesh=mesh) if shape.kind in MESH_KINDS else shape
        self._replace_in_place(key, [_with_leaves(obj, remesh) for obj in self.objects_of(key)])

    @_edit
    def replace_objects(self, key: Hashable, objects: Iterable[SceneObject]) -> None:
        """The key's objects become ``objects`` (any number, any kind; none removes the key).  Of the same
        structure as before (as many shapes, the same booleans), the rows are updated in place; else the
        old objects are removed and the new ones added at the end."""
        objects = list(objects)
        self._disown(objects)
        if not objects:
            self.remove_objects(key)
        elif _same_structure(self.objects_of(key), objects):
            self._replace_in_place(key, objects)
        else:
            for obj in objects:
                self._check_object(obj, key)
            self._restructure(self._where(key), key, objects)

    @_edit
    def add_objects(self, key: Hashable, objects: Iterable[SceneObject]) -> None:
        """Add ``objects`` at the end of the scene under ``key`` (a new key, or more objects for one)."""
        objects = list(objects)
        for obj in objects:
            self._check_object(obj, key)
        self._disown(objects)
        if objects:
            self._restructure([], key, objects)

    @_edit
    def remove_objects(self, key: Hashable) -> None:
        """Remove every object of ``key`` (the key is then unknown)."""
        self._restructure(self._where(key), key, [])

    @_edit
    def set_lights(self, lights: Sequence[Light]) -> None:
        """The scene's lights become ``lights``."""
        compiled = self.compiled
        self.scene.lights = list(lights)
        compiled.lights = LightTable.of(self.scene.lights)
        compiled.light_positions, compiled.light_colors = compiled.lights.position, compiled.lights.color
        self._forget_sealed()
        self._take_edit(_NONE, [], materials_touched=False, lights=True)

    @_edit
    def set_settings(self, settings: Settings) -> None:
        """The scene's settings become ``settings`` (background, ambient light, the reflectivity and
        transparency thresholds, recursion depth, smooth terminator): no row but the materials' traits."""
        self.scene.settings = dataclasses.replace(settings)
        self._materials.retrait()
        self._take_edit(_NONE, [], materials_touched=True, lights=False, scene_wide=True)

    @_edit
    def set_pixmaps(self, pixmaps: Mapping[int, str]) -> None:
        """The scene's pictures (``makePixmap`` number -> file) become ``pixmaps``; a picture in use whose file
        changed (another path, or the file written again) is loaded again.  Refused, changing nothing, when a
        material in use names a number that ``pixmaps`` lacks."""
        pixmaps = dict(pixmaps)
        in_use = self._materials.pictures_in_use()
        missing = sorted(in_use - set(pixmaps))
        if missing:
            raise TracerError(f"texture {missing[0]} is used but the new pictures have no 'makePixmap {missing[0]}'")
        fresh = {number: load_image(pixmaps[number]) for number in sorted(in_use)
                 if _stamp(pixmaps[number]) != self._stamps.get(number)}
        self.scene.pixmaps = pixmaps
        for number in [k for k in self._images if k not in pixmaps or _stamp(pixmaps[k]) != self._stamps.get(k)]:
            del self._images[number]
        for number, picture in fresh.items():
            self._keep_image(number, picture)
        self._take_edit(_NONE, [], materials_touched=True, lights=False, scene_wide=True)

    @_edit
    def rebuild_hierarchy(self) -> None:
        """Build the C core's object hierarchy anew (refits keep it valid, but many large moves can make it
        slower to traverse than a fresh build)."""
        self._pending_rebuild = True
        self._sync()

    @contextmanager
    def batch(self):
        """Edits inside ``with editable.batch():`` update their rows at once but the C core's object hierarchy
        only at the end (one refit or rebuild for all of them): for the many updates of one depsgraph change."""
        self._batch_depth += 1
        try:
            yield self
        finally:
            self._batch_depth -= 1
            self._sync()

    # -- in place -----------------------------------------------------------------------------------------

    def _replace_in_place(self, key: Hashable, objects: list[SceneObject], checked: bool = False) -> None:
        if not checked:
            for obj in objects:
                self._check_object(obj, key)
        self._replace_at(self._where(key), objects)

    def _replace_at(self, positions: list[int], objects: list[SceneObject], same_materials: bool = False) -> None:
        """Objects of the same structure as those at ``positions`` take their places: their rows recomputed
        (``same_materials``: the caller knows that every shape keeps its material)."""
        table = self.compiled.table
        leaves = [leaf for obj in objects for leaf in _leaves(obj)]
        rows = self._rows_of(positions)
        before = table.material_ids[rows].copy()
        material_ids = before if same_materials else np.array([self._material_row(leaf.material) for leaf in leaves],
                                                              dtype=np.int32)
        scene_objects = self.scene.objects
        meshes_before = [table.shapes[i].mesh for i in rows.tolist()]
        for p, obj in zip(positions, objects):
            old = scene_objects[p]
            if old is not obj and self._owned:  # (shapes replaced by others leave the scene)
                kept = set(map(id, _leaves(obj)))
                self._disown(leaf for leaf in _leaves(old) if id(leaf) not in kept)
            scene_objects[p] = obj
        meshes_touched = any(a is not b.mesh for a, b in zip(meshes_before, leaves))
        table.refill(rows, leaves)
        table.material_ids[rows] = material_ids
        self._materials.reassign(before, material_ids)
        self._renew_nodes(rows, positions)
        self._update_sealed(positions)
        touched = bool(self._rows_written) or not np.array_equal(before, material_ids)
        self._take_edit(rows, positions, materials_touched=touched, lights=False, meshes_touched=meshes_touched)

    def _take_edit(self, rows: np.ndarray, positions: list[int], materials_touched: bool, lights: bool,
                   meshes_touched: bool = False, scene_wide: bool = False) -> None:
        """After the compiled rows of an in-place edit are done: the effects (and pictures) again, the FlatScene's
        rows of these primitives, objects and materials, and the C core told (now, or at the batch's end)."""
        compiled = self.compiled
        refreshed = self._refresh_effects(materials_touched, meshes_touched)
        self.done["rows"] += 1
        flat = _flat_of(compiled)
        if flat is not None:
            # (every material row read again where the effects or pictures changed, else the rows written)
            materials = True if refreshed else np.array(sorted(self._rows_written), dtype=np.int64)
            meshes = flat.edit(compiled, rows, np.asarray(positions, dtype=np.int64), materials=materials,
                               lights=lights)
            self._pending_meshes |= meshes
            self._pending_objects.update(positions)
            self._pending_flat |= lights or scene_wide
        self._rows_written = set()
        self._sync()

    def _changed(self, shape: Shape, field: str, value) -> Shape:
        """``shape`` with ``field`` (its matrix or material) set to ``value``: changed in place if this scene
        made it, else a new Shape that it then owns (a shape the caller made is never changed)."""
        if id(shape) in self._owned:
            setattr(shape, field, value)
            return shape
        new = dataclasses.replace(shape, **{field: value})
        self._owned.add(id(new))
        return new

    def _disown(self, objects: Iterable[SceneObject]) -> None:
        """These objects' shapes leave the scene, or come from the caller: none is changed in place again."""
        owned = self._owned
        if owned:
            for obj in objects:
                for leaf in _leaves(obj):
                    owned.discard(id(leaf))

    def _rows_of(self, positions: Sequence[int]) -> np.ndarray:
        """The primitive rows of the objects at these positions, object after object."""
        positions = np.asarray(positions, dtype=np.int64)
        counts = self._leaf_counts[positions]
        first = np.repeat(self._starts[positions], counts)
        return first + np.arange(len(first)) - np.repeat(np.cumsum(counts) - counts, counts)

    def _material_row(self, material: Material) -> int:
        row, new = self._materials.row(material)
        if new:
            self._rows_written.add(row)
            self.done["materials"] += 1
        return row

    def _renew_nodes(self, rows: np.ndarray, positions: list[int]) -> None:
        """The NumPy path's primitives of these rows made again when next asked for, and the booleans at these
        positions compiled again from them."""
        compiled = self.compiled
        made = compiled.primitives._made
        for i in rows.tolist():
            made.pop(i, None)
        for p in positions:
            if p in compiled.objects.booleans:
                compiled.objects.booleans[p] = self._boolean_node(p)
        compiled.objects.forget_batches()

    def _boolean_node(self, position: int) -> CSGNode:
        counter = iter(range(int(self._starts[position]), int(self._starts[position + 1])))
        primitives = self.compiled.primitives
        return fold_tree(self.scene.objects[position], lambda _: primitives[next(counter)],
                         lambda node, left, right: CSGNode(node.op, left, right))

    # -- added, removed -----------------------------------------------------------------------------------

    def _restructure(self, removed: list[int], key: Hashable, added: list[SceneObject]) -> None:
        """Remove the objects at ``removed`` and append ``added`` under ``key``: their own rows, then the
        FlatScene made anew, and the C core's hierarchy renumbered (the added objects outside it until there
        are many: then it is built again)."""
        compiled, table = self.compiled, self.compiled.table
        incremental = not self._pending_rebuild
        if incremental:
            self._sync(force=True)  # (moves not yet sent name objects by their positions before this edit)
        n = len(self._serial)
        keep = np.ones(n, dtype=bool)
        keep[removed] = False
        keep_rows = np.repeat(keep, self._leaf_counts)
        leaves = [leaf for obj in added for leaf in _leaves(obj)]
        material_ids = np.array([self._material_row(leaf.material) for leaf in leaves], dtype=np.int32)
        self._materials.reassign(table.material_ids[~keep_rows], material_ids)
        kept = np.flatnonzero(keep)
        self._disown(self.scene.objects[p] for p in removed)
        delete_positions(self.scene.objects, removed)
        self.scene.objects.extend(added)
        if removed:
            del self._serials_of[key]
        serials = np.arange(len(self._position), len(self._position) + len(added))
        if len(added):
            self._serials_of.setdefault(key, []).extend(serials.tolist())
        self._position[self._serial[removed]] = -1
        self._serial = np.concatenate([self._serial[kept], serials])
        self._position = np.concatenate([self._position, serials])  # (the new serials' entries)
        self._position[self._serial] = np.arange(len(self._serial))
        self._leaf_counts = np.concatenate([self._leaf_counts[kept], [_leaf_count(obj) for obj in added]]).astype(np.int64)
        self._starts = np.concatenate([[0], np.cumsum(self._leaf_counts)])
        table.resize(keep_rows, leaves, material_ids)
        compiled.primitives._made.clear()
        # (a boolean has two leaves or more; the booleans' positions shift, so each is compiled again)
        index = np.where(self._leaf_counts == 1, self._starts[:-1], -1)
        compiled.objects = CompiledObjects(compiled.primitives, index, {})
        for p in np.flatnonzero(index < 0).tolist():
            compiled.objects.booleans[p] = self._boolean_node(p)
        self._refresh_effects(True, True)
        self._rows_written = set()  # (the new FlatScene reads them all)
        sealed = compiled.__dict__.get(_SEALED)
        if sealed is not None:
            fresh = sealed_lights(compiled, np.arange(len(kept), len(self._serial)))
            compiled.__dict__[_SEALED] = np.concatenate([sealed[kept], fresh])
        self.done["rows"] += 1
        old = _flat_of(compiled)
        if old is None:
            return
        flat = flatten.FlatScene(compiled)  # (a new flat scene; the C core's scene moves over to it)
        core = flat.core = getattr(old, "core", None)
        compiled._flat_cache = (compiled._flat_cache[0], flat)
        self.done["flat"] += 1
        if core is not None and incremental:
            had_sealed = core.sealed_sent
            core.edit(flat, None, meshes=True, rebuild=False, threads=default_threads(),
                      removed=np.asarray(removed, dtype=np.int64))
            self._resend_sealed(core, had_sealed)
            self.done["restructure"] += 1
        else:
            self._pending_flat = self._pending_meshes = self._pending_rebuild = True
            self._sync()

    # -- what depends on many rows ------------------------------------------------------------------------

    def _refresh_effects(self, materials_touched: bool, meshes_touched: bool = False) -> bool:
        """The live effects again (from the ledger's counts: no pass over the materials), and the pictures
        where the materials in use may have changed (each picture loaded once).  Whether either changed."""
        compiled = self.compiled
        effects = self._materials.effects(compiled.table.kinds_present(), bool(compiled.objects.booleans),
                                          materials_touched or meshes_touched)
        changed = effects != compiled.effects
        if changed:
            compiled.effects = effects
            self.done["effects"] += 1
        if "textures" not in effects:
            compiled.textures = None
            return changed
        if not (changed or materials_touched) and compiled.textures is not None:
            return False
        numbers = self._materials.pictures_in_use()
        for number in numbers - set(self._images):
            self._keep_image(number, load_image(self.scene.pixmaps[number]))  # (checked with the material)
        images = {k: self._images[k] for k in sorted(numbers)}
        current = getattr(compiled.textures, "images", None)
        if current is None or current.keys() != images.keys() or any(current[k] is not images[k] for k in images):
            compiled.textures = TextureSet.of_images(compiled.primitives, images)
            self.done["textures"] += 1
            return True
        return changed

    def _update_sealed(self, positions: list[int]) -> None:
        """The sealed-lights rows of these objects again, where the table has been made (as a new array)."""
        sealed = self.compiled.__dict__.get(_SEALED)
        if sealed is not None:
            sealed = sealed.copy()
            sealed[positions] = sealed_lights(self.compiled, np.asarray(positions, dtype=np.int64))
            self.compiled.__dict__[_SEALED] = sealed

    def _forget_sealed(self) -> None:
        self.compiled.__dict__.pop(_SEALED, None)

    # -- the C core ---------------------------------------------------------------------------------------

    def _sync(self, force: bool = False) -> None:
        """Tell the C core's scene (when there is one) what the edits since the last time changed (at the end
        of a batch, unless ``force``): a refit of the hierarchy to the objects that moved, or a rebuild
        (asked for, or more than REBUILD_SHARE of the objects refitted since the last build)."""
        if self._batch_depth and not force:
            return
        flat = _flat_of(self.compiled)
        core = getattr(flat, "core", None) if flat is not None else None
        objects = np.array(sorted(self._pending_objects), dtype=np.int64)
        anything = self._pending_flat or self._pending_rebuild or objects.size
        self._pending_objects = set()
        if core is None or not anything:
            self._pending_meshes = self._pending_rebuild = self._pending_flat = False
            return
        self._refitted += objects.size
        rebuild = self._pending_rebuild or self._refitted > REBUILD_SHARE * max(1, len(self._serial))
        had_sealed = core.sealed_sent
        core.edit(flat, objects, meshes=self._pending_meshes, rebuild=rebuild, threads=default_threads())
        self._resend_sealed(core, had_sealed)
        if rebuild:
            self._refitted = 0
            self.done["rebuild"] += 1
        elif objects.size:
            self.done["refit"] += 1
        self._pending_meshes = self._pending_rebuild = self._pending_flat = False

    def _resend_sealed(self, core, had: bool) -> None:
        """The C core's sealed-lights table as the compiled scene's is now, where a tracer had sent one: a tracer
        made before the edit then skips the feelers one made after it skips (none while the table is not
        known again, after a light edit)."""
        if had:
            core.send_sealed(self.compiled.__dict__.get(_SEALED))

    # -- checks -------------------------------------------------------------------------------------------

    def _check_object(self, obj: SceneObject, key: Hashable) -> None:
        for shape in _leaves(obj):
            if not isinstance(shape, Shape):
                raise TracerError(f"object {key!r}: {type(shape).__name__} is not a shape or a boolean")
            if shape.kind not in SHAPE_KINDS:
                raise TracerError(f"object {key!r}: unknown shape kind {shape.kind!r}")
            if shape.kind in MESH_KINDS and not isinstance(shape.mesh, MeshData):
                raise TracerError(f"object {key!r}: a {shape.kind} without a mesh")
            _checked_matrix(shape.matrix, key)
            self._check_material(shape.material, f"object {key!r}")

    def _check_material(self, material: Material, where: str) -> None:
        """A material's texture must be usable: a known solid texture, or a makePixmap picture (loaded now)."""
        number = int(material.texture)
        if number < 0 and number not in SOLID_TEXTURES:
            raise TracerError(f"{where}: texture {number} is not a known solid texture (use -1, -2 or -3)")
        if number > 0 and number not in self._images:
            if number not in self.scene.pixmaps:
                raise TracerError(f"{where}: texture {number} is used but the scene has no 'makePixmap {number} file'")
            self._keep_image(number, load_image(self.scene.pixmaps[number]))

    def _keep_image(self, number: int, picture: np.ndarray) -> None:
        self._images[number] = picture
        self._stamps[number] = _stamp(self.scene.pixmaps[number])

    def _where(self, key: Hashable) -> list[int]:
        try:
            serials = self._serials_of[key]
        except KeyError:
            raise TracerError(f"no object has the key {key!r}") from None
        return self._position[serials].tolist()


#: A rebuild instead of a refit once more objects than this share of all have been refitted since the last
#: build: refitted boxes of objects moved far apart overlap more and more.
REBUILD_SHARE = 0.5
_NONE = np.zeros(0, dtype=np.int64)
_SEALED = "_sealed_lights"  # (where tracer.skippable.sealed_table keeps its table)


def _stamp(path: str) -> tuple:
    """What tells a picture file's content apart: its path, size and modification time (as compile_scene's key)."""
    try:
        stat = os.stat(path)
        return str(path), stat.st_size, stat.st_mtime_ns
    except (OSError, ValueError):
        return str(path), None, None


def _flat_of(compiled: CompiledScene):
    """The compiled scene's FlatScene, if the C core has flattened it."""
    cached = getattr(compiled, "_flat_cache", None)
    return None if cached is None else cached[1]


def _leaves(obj: SceneObject) -> list[Shape]:
    if type(obj) is Shape:  # (the common case, without a tree walk)
        return [obj]
    return fold_tree(obj, lambda shape: [shape], lambda _, left, right: left + right)


def _leaf_count(obj: SceneObject) -> int:
    return 1 if type(obj) is Shape else fold_tree(obj, lambda _: 1, lambda _, left, right: left + right)


def _with_leaves(obj: SceneObject, change) -> SceneObject:
    """``obj`` with each leaf shape replaced by ``change(shape)`` (booleans made anew above changed leaves)."""
    if type(obj) is Shape:
        return change(obj)
    return fold_tree(obj, change, lambda node, left, right: dataclasses.replace(node, left=left, right=right))


def _structure(obj: SceneObject):
    return fold_tree(obj, lambda _: None, lambda node, left, right: (node.op, left, right))


def _same_structure(old: list[SceneObject], new: list[SceneObject]) -> bool:
    return len(old) == len(new) and all(_structure(a) == _structure(b) for a, b in zip(old, new))


def _checked_matrices(matrices: Sequence, keys: Sequence[Hashable]) -> np.ndarray:
    """_checked_matrix of each (keys[i] names matrices[i]), checked all at once: (N, 4, 4) float64."""
    try:
        stack = np.array(matrices, dtype=np.float64).reshape(-1, 4, 4)
    except (TypeError, ValueError):
        stack = None
    if stack is None or len(stack) != len(keys) or not np.isfinite(stack).all() or \
            np.any(stack[:, 3] != (0, 0, 0, 1)):
        return np.array([_checked_matrix(m, k) for m, k in zip(matrices, keys)]).reshape(-1, 4, 4)
    try:
        fine = np.isfinite(np.linalg.inv(stack)).all()
    except np.linalg.LinAlgError:
        fine = False
    if not fine:  # (one by one, to name the first bad one)
        for m, k in zip(matrices, keys):
            _checked_matrix(m, k)
    return stack


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
