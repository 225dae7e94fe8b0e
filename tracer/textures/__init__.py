"""Textures: solid (procedural) ones and images, looked up at a hit's generic coordinates.

Texture numbers (the material's ``texture``): 0 none, -1 checkerboard, -2 wood grain, -3 marble, i > 0 the
image loaded by ``makePixmap i``.  A texture's colour *multiplies* the material's ambient and diffuse
colours (set ``diffuse 1 1 1`` to see it unchanged).  See docs/textures.md.
"""
from __future__ import annotations

import numpy as np

from .. import numerics
from ..errors import TracerError
from .images import load_image, sample_bilinear
from .mapping import surface_uv
from .solid import SOLID_TEXTURES


def image_repeats(parameters) -> tuple[float, float]:
    """How often an image texture repeats across u and v: the material's first two parameters, 1 if absent."""
    repeat_u, repeat_v = (tuple(parameters) + (1.0, 1.0))[:2]
    return repeat_u, repeat_v


def drop_unreadable_textures(scene) -> list[str]:
    """For lenient reading: every texture that cannot be used (a picture that cannot be read, a missing
    makePixmap, an unknown solid texture) is taken off the shapes that use it, which are then drawn with their
    material's own colours.  Returns one message per problem, naming the file."""
    from dataclasses import replace

    shapes = scene.shapes()
    problems = texture_problems(scene, shapes)
    for shape in shapes:
        if shape.material.texture in problems:
            shape.material = replace(shape.material, texture=0)
    return [f"{message}: drawn without that texture" for message in dict.fromkeys(problems.values())]


def texture_problems(scene, shapes=None) -> dict[int, str]:
    """Why each texture the scene's shapes use cannot be used (texture number -> one message naming the file:
    a missing makePixmap, a picture that cannot be read, an unknown solid texture); empty when all can.  Every
    picture is read to find out."""
    shapes = scene.shapes() if shapes is None else shapes
    problems: dict[int, str] = {}
    for number in sorted({s.material.texture for s in shapes}):
        problem = _texture_problem(scene, shapes, number)
        if problem is None and number > 0:
            try:
                _load_for(scene, shapes, number)
            except TracerError as err:
                problem = str(err)
        if problem:
            problems[number] = problem
    return problems


def _texture_numbers(shapes) -> set:
    """The texture numbers of the shapes' materials: of a table's rows (compile._RowShapes), from its distinct
    materials, without making a Shape of each row."""
    columns = getattr(shapes, "columns", None)
    if columns is not None:
        return {columns.materials[i].texture for i in np.unique(columns.material_ids).tolist()}
    return {s.material.texture for s in shapes}


def _where_used(scene, shapes, number: int) -> str:
    """Where texture ``number`` is first used (the shape's file:line:column), for messages."""
    first = next((s for s in shapes if s.material.texture == number), None)
    if first is not None and first.source is not None:
        return str(first.source)
    return str(scene.source or "scene")


def _texture_problem(scene, shapes, number: int) -> str | None:
    """Why texture ``number`` cannot be used (before any image is read), or None."""
    if number > 0 and number not in scene.pixmaps:
        return f"{_where_used(scene, shapes, number)}: texture {number} is used but the scene has no " \
               f"'makePixmap {number} file'"
    if number < 0 and number not in SOLID_TEXTURES:
        return f"{_where_used(scene, shapes, number)}: texture {number} is not a known solid texture " \
               f"(use -1, -2 or -3)"
    return None


def _load_for(scene, shapes, number: int) -> np.ndarray:
    """The picture of texture ``number``; an error names the makePixmap that asked for it (where the reader
    recorded it; else where the texture is first used), then the image file."""
    try:
        return load_image(scene.pixmaps[number])
    except TracerError as err:
        made_at = scene.pixmap_sources.get(number)
        where = f"{made_at}: makePixmap {number}" if made_at is not None else _where_used(scene, shapes, number)
        raise TracerError(f"{where}: {err}") from None


class TextureSet:
    """The textures a compiled scene uses, with its images loaded once."""

    def __init__(self, scene, primitives):
        self.primitives = primitives
        self.images: dict[int, np.ndarray] = {}
        loaded: dict[str, np.ndarray] = {}  # one picture per file, however many numbers name it
        # (a compiled scene's shapes, not its primitives: the C core's scene makes none of those)
        table = getattr(primitives, "table", None)
        shapes = table.shapes if table is not None else [p.shape for p in primitives]
        for number in sorted(_texture_numbers(shapes)):
            problem = _texture_problem(scene, shapes, number)
            if problem:
                raise TracerError(problem)
            if number > 0:
                path = scene.pixmaps[number]
                if path not in loaded:
                    loaded[path] = _load_for(scene, shapes, number)
                self.images[number] = loaded[path]

    @classmethod
    def of_images(cls, primitives, images: dict[int, np.ndarray]) -> "TextureSet":
        """A TextureSet of these primitives with the pictures already loaded (by texture number): tracer.edit's,
        which loads only a picture it has not loaded before."""
        self = cls.__new__(cls)
        self.primitives, self.images = primitives, dict(images)
        return self

    def colors(self, shape_index: np.ndarray, points: np.ndarray, parts: np.ndarray,
               uv: np.ndarray | None = None) -> np.ndarray:
        """Texture colours (N, 3) at world ``points`` on primitives ``shape_index`` hit on ``parts`` (1 where
        untextured); ``uv``: the hits' barycentrics on meshes (a mesh with texture coordinates is looked up
        at them), or None."""
        out = np.ones_like(points)
        for index in np.unique(shape_index):
            prim = self.primitives[index]
            material = prim.shape.material
            if material.texture == 0:
                continue
            rows = np.nonzero(shape_index == index)[0]
            generic = numerics.affine_points(prim.inverse, points[rows])  # (as the C core sums: texture.h)
            if material.texture < 0:
                out[rows] = SOLID_TEXTURES[material.texture](generic, material.parameters)
            else:
                mesh = prim.triangle_mesh
                if uv is not None and mesh is not None and mesh.tri_uv is not None:  # its own coordinates repeat
                    (u, v), wrap_u, wrap_v = mesh.texture_uv(parts[rows], uv[rows, 0], uv[rows, 1]), True, True
                else:
                    u, v, wrap_u, wrap_v = surface_uv(prim.kind, generic, parts[rows])
                repeat_u, repeat_v = image_repeats(material.parameters)
                if (repeat_u, repeat_v) != (1.0, 1.0):
                    u, v, wrap_u, wrap_v = u * repeat_u, v * repeat_v, True, True
                out[rows] = sample_bilinear(self.images[material.texture], u, v, wrap_u, wrap_v)
        return out
