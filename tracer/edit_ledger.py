"""What tracer.edit keeps about a compiled scene's materials between edits, so that no edit reads them all.

* Each distinct Material *object* has one row of the compiled MaterialTable (as compile_scene numbers them:
  by identity); a material not seen before gets a new row at the end.
* ``users``: per row, how many primitives use it.
* ``traits``: per row, what it can call for (compile.material_traits: lit, reflects, transmits, textured, a
  Cook–Torrance share), and ``counts``: per trait, how many primitives have a material with it.  The live
  effects that depend on materials are those of the traits whose count is not 0 (compile.effects_of_traits):
  what compile_scene finds from the materials in use, kept up to date by each edit in O(its rows).
"""
from __future__ import annotations

import numpy as np

from typing import Optional

from .compile import TRAITS, CompiledScene, effects_of_traits, material_traits, uv_textured_of
from .model import Material


class MaterialLedger:
    def __init__(self, compiled: CompiledScene):
        self.compiled = compiled
        materials = compiled.materials
        # (a compiled list's materials are its distinct Material objects: the table keeps them alive, so their
        # ids stay theirs)
        self.rows = {id(m): k for k, m in enumerate(materials.materials)}
        self.traits = material_traits(materials, compiled.settings)
        ids = compiled.table.material_ids
        self.users = np.bincount(ids, minlength=len(self.traits)).astype(np.int64)
        self.counts = (self.users[:, None] * self.traits).sum(axis=0)
        self._uv_textured: Optional[bool] = None  # (effects: not looked at yet)

    def row(self, material: Material) -> tuple[int, bool]:
        """The row of this Material object, and whether it is new (appended to the table)."""
        row = self.rows.get(id(material))
        if row is not None:
            return row, False
        row = self.rows[id(material)] = self.compiled.materials.put(material)
        self.traits = np.concatenate([self.traits, self._traits_of(row)])
        self.users = np.concatenate([self.users, [0]])
        return row, True

    def rewrite(self, old: Material, new: Material) -> int:
        """Row of ``old`` now holds ``new`` (for every primitive that used it); returns the row."""
        row = self.rows.pop(id(old))
        self.rows[id(new)] = row
        self.compiled.materials.put(new, row)
        traits = self._traits_of(row)[0]
        self.counts += self.users[row] * (traits.astype(np.int64) - self.traits[row].astype(np.int64))
        self.traits[row] = traits
        return row

    def reassign(self, before: np.ndarray, after: np.ndarray) -> None:
        """Primitives that used the rows ``before`` now use the rows ``after`` (either may be empty: removed or
        added primitives)."""
        np.subtract.at(self.users, before, 1)
        np.add.at(self.users, after, 1)
        self.counts += self.traits[after].sum(axis=0) - self.traits[before].sum(axis=0)

    def retrait(self) -> None:
        """Every material's traits again (the settings' thresholds changed)."""
        self.traits = material_traits(self.compiled.materials, self.compiled.settings)
        self.counts = (self.users[:, None] * self.traits).sum(axis=0)

    def present(self) -> np.ndarray:
        """Per trait, whether some primitive's material has it."""
        return self.counts > 0

    def effects(self, kinds: set[str], any_boolean: bool, meshes_or_materials_changed: bool) -> frozenset[str]:
        """The compiled scene's live effects as they are now (shapes of ``kinds``).  Whether a picture lies on a
        mesh with texture coordinates (a walk over the meshes) is looked at again only where a picture is in
        use and ``meshes_or_materials_changed`` (some primitive's mesh or material) since it was."""
        compiled = self.compiled
        if not self.present()[TRAITS.index("textured")] or not self.pictures_in_use():
            self._uv_textured = False
        elif meshes_or_materials_changed or self._uv_textured is None:
            self._uv_textured = uv_textured_of(compiled.table, compiled.materials.texture)
        return effects_of_traits(compiled.scene, kinds, self.present(), any_boolean, self._uv_textured)

    def pictures_in_use(self) -> set[int]:
        """The image texture numbers (> 0) of the materials in use."""
        texture = self.compiled.materials.texture
        return {int(t) for t in np.unique(texture[(self.users > 0) & (texture > 0)]).tolist()}

    def _traits_of(self, row: int) -> np.ndarray:
        return material_traits(self.compiled.materials, self.compiled.settings, slice(row, row + 1))
