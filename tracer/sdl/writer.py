"""Write a :class:`tracer.model.Scene` as SDL text that reads back to the same scene.

Exactness is the point: numbers are written with ``repr`` (the shortest text that reads back as the same
float), and every shape's 4x4 matrix, including shears and mirror images, is rebuilt from SDL's three
transform statements.  Any invertible 3x3 matrix A factors by the SVD as A = U·diag(s)·Vᵀ with U and V
rotations (one singular value goes negative when det A < 0), which SDL spells
``translate t  rotate <U>  scale s  rotate <Vᵀ>``, since each statement post-multiplies.  Simpler forms
(pure scale; rotation then scale; scale then rotation) and rounded numbers are tried first for
readability, and each candidate is used only if replaying it the way the parser does reproduces the matrix
to a few units in the last place.
"""
from __future__ import annotations

import itertools
import math
import os
import re
from pathlib import Path
from typing import Iterator, Optional, Union

import numpy as np

from .. import shapes, transforms
from ..errors import WriteError
from ..meshio import write_3vn, write_text_atomic
from ..model import CSG, Material, MeshData, Scene, SceneObject, Shape
from .lights import statement_of
from .parser import COLOR_MATERIAL, FLOAT_MATERIAL, KEYWORDS, is_singular

PathLike = Union[str, "os.PathLike[str]"]

_EPS = np.finfo(np.float64).eps


# ---------------------------------------------------------------------------------------------------------
# Numbers and names

def fmt(x: float) -> str:
    """A number as SDL text that reads back as exactly the same float ('2' rather than '2.0')."""
    x = float(x)
    if not math.isfinite(x):
        raise WriteError(f"SDL has no way to write the number {x!r}")
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def _fmt_all(values) -> str:
    return " ".join(fmt(v) for v in values)


def _whole(x: float, what: str) -> str:
    if not float(x).is_integer():
        raise WriteError(f"{what} must be a whole number, not {x!r}")
    return str(int(x))


_BAD_NAME = re.compile(r"[\s{}!]")


def _name(name: str, what: str) -> str:
    """A file name as one SDL token; names the lexer would split or misread cannot be written."""
    if not name or _BAD_NAME.search(name) or name in KEYWORDS:
        raise WriteError(f"{what} {name!r} cannot be written in SDL (no spaces, braces, '!' or keywords)")
    return name


# ---------------------------------------------------------------------------------------------------------
# Transforms

def _axis_angle(rotation: np.ndarray) -> Optional[tuple[float, np.ndarray]]:
    """(angle in degrees, unit axis) of a proper rotation matrix, or None for the identity.

    Goes through the unit quaternion (Shepperd's method: divide by the largest of its four components),
    which stays accurate near 0 and 180 degrees where reading the angle off the trace does not.
    """
    r = rotation
    trace = r[0, 0] + r[1, 1] + r[2, 2]
    largest = int(np.argmax([trace, r[0, 0], r[1, 1], r[2, 2]]))
    if largest == 0:
        w = 0.5 * math.sqrt(max(0.0, 1.0 + trace))
        x, y, z = (r[2, 1] - r[1, 2]) / (4 * w), (r[0, 2] - r[2, 0]) / (4 * w), (r[1, 0] - r[0, 1]) / (4 * w)
    elif largest == 1:
        x = 0.5 * math.sqrt(max(0.0, 1.0 + r[0, 0] - r[1, 1] - r[2, 2]))
        w, y, z = (r[2, 1] - r[1, 2]) / (4 * x), (r[0, 1] + r[1, 0]) / (4 * x), (r[0, 2] + r[2, 0]) / (4 * x)
    elif largest == 2:
        y = 0.5 * math.sqrt(max(0.0, 1.0 - r[0, 0] + r[1, 1] - r[2, 2]))
        w, x, z = (r[0, 2] - r[2, 0]) / (4 * y), (r[0, 1] + r[1, 0]) / (4 * y), (r[1, 2] + r[2, 1]) / (4 * y)
    else:
        z = 0.5 * math.sqrt(max(0.0, 1.0 - r[0, 0] - r[1, 1] + r[2, 2]))
        w, x, y = (r[1, 0] - r[0, 1]) / (4 * z), (r[0, 2] + r[2, 0]) / (4 * z), (r[1, 2] + r[2, 1]) / (4 * z)
    if w < 0:  # q and -q are the same rotation; this one has an angle in [0, 180]
        w, x, y, z = -w, -x, -y, -z
    vector = np.array([x, y, z])
    length = float(np.linalg.norm(vector))
    if length == 0.0:
        return None
    return math.degrees(2.0 * math.atan2(length, w)), vector / length


Statement = tuple[str, tuple[float, ...]]


def _rotate_statement(rotation: np.ndarray) -> list[Statement]:
    found = _axis_angle(rotation)
    if found is None:
        return []
    angle, axis = found
    return [("rotate", (angle, *axis))]


def _replay(statements: list[Statement]) -> np.ndarray:
    """The matrix the parser builds from these statements (after the numbers go through text)."""
    build = {"translate": transforms.translation, "scale": transforms.scaling, "rotate": transforms.rotation}
    matrix = np.eye(4)
    for keyword, values in statements:
        matrix = matrix @ build[keyword](*(float(fmt(v)) for v in values))
    return matrix


def _denoised(values: tuple[float, ...]) -> tuple[float, ...]:
    """Values tiny next to the largest set to 0 (the SVD's noise, e.g. an axis component of 4e-17)."""
    scale = max(abs(v) for v in values)
    return tuple(0.0 if abs(v) <= 1e-12 * scale else v for v in values)


def _rounded(values: tuple[float, ...]) -> tuple[float, ...]:
    """Values to 12 significant digits, without the noise."""
    return tuple(float(f"{v:.12g}") for v in _denoised(values))


def _tidy(statements: list[Statement]) -> Iterator[list[Statement]]:
    """Cleaner versions of the rotate and scale statements, best first, which read better
    ('rotate 45 0 1 0', 'scale 2 2 2') and are used only if they still rebuild the matrix to the last few bits.

    First everything rounded to 12 digits, with the rotation axis divided by its smallest and then by its
    largest non-zero component (so that (1, 2, 3) comes out whole); then only the noise cleared from the
    axes, with the scale rounded and then exact.
    """
    for style in ("axis/smallest", "axis/largest", "clean axis, round scale", "clean axis"):
        tidy: list[Statement] = []
        for keyword, values in statements:
            if keyword == "scale" and style != "clean axis":
                values = _rounded(values)
                if values == (1.0, 1.0, 1.0):
                    continue
            elif keyword == "rotate" and style.startswith("clean"):
                values = (values[0], *_denoised(values[1:]))
            elif keyword == "rotate":
                axis = np.array(_rounded(values[1:]))
                divisor = (min if style == "axis/smallest" else max)(abs(c) for c in axis if c != 0.0)
                values = _rounded((values[0],)) + _rounded(tuple(axis / divisor))
            tidy.append((keyword, values))  # translations are written exactly as they are
        yield tidy


def _rotation_then_scale(linear: np.ndarray) -> list[tuple[np.ndarray, np.ndarray]]:
    """Ways to write ``linear`` = R·diag(s) when its columns are orthogonal (no shear).

    With a mirror image (det < 0) any one of the three scales may carry the minus sign; all three are
    offered, since only one of them matches the rotation the file was written with.
    """
    lengths = np.linalg.norm(linear, axis=0)
    if not np.all(lengths > 0):
        return []
    gram = linear.T @ linear
    if np.max(np.abs(gram - np.diag(np.diag(gram)))) > 1e-12 * np.max(gram):
        return []  # sheared: only the SVD will do
    rotation = linear / lengths
    if np.linalg.det(rotation) > 0:
        return [(rotation, lengths)]
    options = []
    for column in (0, 1, 2):
        r, s = rotation.copy(), lengths.copy()
        r[:, column] *= -1
        s[column] *= -1
        options.append((r, s))
    return options


def transform_statements(matrix: np.ndarray) -> list[Statement]:
    """SDL transform statements that rebuild an affine ``matrix`` when applied after ``identityAffine``."""
    m = np.asarray(matrix, dtype=np.float64).reshape(4, 4)
    if not np.all(np.isfinite(m)):
        raise WriteError("cannot write a transform with non-finite entries")
    if not np.array_equal(m[3], [0.0, 0.0, 0.0, 1.0]):
        raise WriteError("cannot write a projective (non-affine) transform in SDL")
    linear, offset = m[:3, :3], m[:3, 3]
    head: list[Statement] = [("translate", tuple(offset))] if np.any(offset) else []

    def scale(s) -> list[Statement]:
        return [] if np.array_equal(s, [1.0, 1.0, 1.0]) else [("scale", tuple(s))]

    if np.count_nonzero(linear - np.diag(np.diag(linear))) == 0:
        return head + scale(np.diag(linear))  # exact, and what most files contain

    tolerance = 4 * _EPS * max(1.0, float(np.max(np.abs(m))))

    def close(statements: list[Statement]) -> bool:
        return float(np.max(np.abs(_replay(statements) - m))) <= tolerance

    # No shear: rotation then scale (orthogonal columns), or scale then rotation (orthogonal rows).
    simple = [head + _rotate_statement(r) + scale(s) for r, s in _rotation_then_scale(linear)]
    if not simple:
        simple = [head + scale(s) + _rotate_statement(r.T) for r, s in _rotation_then_scale(linear.T)]
    # Lazily, so that the first form that works ends the search.
    tidy_first = (t for plain in simple for t in _tidy(plain))
    for statements in itertools.chain(tidy_first, simple):
        if close(statements):
            return statements

    # General case, shears included: A = U diag(s) Vt, with U and Vt turned into proper rotations.
    u, s, vt = transforms.rotation_scale_rotation(linear)
    general = head + _rotate_statement(u) + scale(s) + _rotate_statement(vt)
    for statements in _tidy(general):
        if close(statements):
            return statements
    return general


def _transform_text(matrix: np.ndarray) -> str:
    return " ".join(["identityAffine"] + [f"{kw} {_fmt_all(values)}" for kw, values in
                                          transform_statements(matrix)])


# ---------------------------------------------------------------------------------------------------------
# Materials

_COLOR_FIELDS = {f: kw for kw, f in COLOR_MATERIAL.items()}
_FLOAT_FIELDS = {f: kw for kw, f in FLOAT_MATERIAL.items()}


def _material_statement(material: Material, name: str) -> str:
    value = getattr(material, name)
    if name in _COLOR_FIELDS:
        return f"{_COLOR_FIELDS[name]} {_fmt_all(value)}"
    if name in _FLOAT_FIELDS:
        return f"{_FLOAT_FIELDS[name]} {fmt(value)}"
    if name == "texture":
        return f"texture {_whole(value, 'texture')}"
    if name == "parameters":
        return " ".join(["parameters", str(len(value))] + [fmt(p) for p in value])
    if name == "fresnel":
        return f"fresnel {value}"
    if name == "fresnel_tint":
        return f"fresnelTint {_fmt_all(value)}"
    raise AssertionError(f"material field {name} has no SDL keyword")


_MATERIAL_FIELDS = list(_COLOR_FIELDS) + list(_FLOAT_FIELDS) + ["texture", "parameters", "fresnel", "fresnel_tint"]


def material_statements(current: Material, wanted: Material) -> list[str]:
    """Statements that change the current material into ``wanted``: only the keywords that differ, or
    ``defaultMaterials`` and the keywords that differ from the defaults, whichever is shorter."""
    if current == wanted:
        return []
    changes = [_material_statement(wanted, f) for f in _MATERIAL_FIELDS
               if getattr(current, f) != getattr(wanted, f)]
    default = Material()
    from_default = ["defaultMaterials"] + [_material_statement(wanted, f) for f in _MATERIAL_FIELDS
                                           if getattr(default, f) != getattr(wanted, f)]
    return from_default if len(from_default) < len(changes) else changes


# ---------------------------------------------------------------------------------------------------------
# The scene

def _shape_keyword(shape: Shape, mesh_names: dict[int, str]) -> str:
    """The keyword and what follows it: its parameters in SDL order, or a mesh's file."""
    if shapes.KINDS[shape.kind].file_argument:
        name = mesh_names.get(id(shape), shape.mesh_file)
        if name is None:
            raise WriteError("a mesh shape has no file name; save_sdl writes its mesh beside the scene")
        return f"{shape.kind} {_name(name, 'mesh file')}"
    return " ".join([shape.kind, *map(fmt, shape.parameters)])


def _scene_text(scene: Scene, mesh_names: dict[int, str], pixmaps: dict[int, str]) -> str:
    s = scene.settings
    lines = ["! SDL scene written by tracer", "",
             f"globalAmbient {_fmt_all(s.global_ambient)}",
             f"background {_fmt_all(s.background)}",
             f"minReflectivity {fmt(s.min_reflectivity)}",
             f"minTransparency {fmt(s.min_transparency)}",
             f"maxRecursionDepth {_whole(s.max_recursion_depth, 'maxRecursionDepth')}"]
    if s.smooth_terminator:
        lines.append("smoothTerminator 1")
    for light in scene.lights:
        if light.name and _one_line(light.name):
            lines.append(f"! name: {_one_line(light.name)}")
        lines.append(statement_of(light, _fmt_all))
    if scene.camera is not None:
        c = scene.camera
        lines.append(f"camera {_fmt_all(c.eye)}  {_fmt_all(c.look)}  {_fmt_all(c.up)}  {fmt(c.view_angle)}")
    for index in sorted(pixmaps):
        lines.append(f"makePixmap {_whole(index, 'makePixmap number')} {_name(pixmaps[index], 'image file')}")
    lines.append("")

    material = Material()
    groups: tuple[str, ...] = ()
    # An explicit stack rather than recursion, so that deeply nested booleans cannot overflow it.
    todo: list[tuple[SceneObject, int]] = [(obj, 0) for obj in reversed(scene.objects)]
    while todo:
        obj, depth = todo.pop()
        indent = "  " * depth
        if obj.groups != groups and obj.groups:
            lines.append(f"{indent}! group: {' / '.join(obj.groups)}")
        groups = obj.groups
        if isinstance(obj, CSG):
            lines.append(f"{indent}{obj.op}")
            todo += [(obj.right, depth + 1), (obj.left, depth + 1)]
            continue
        if is_singular(obj.matrix):
            # The reader refuses such a shape, so writing it would only move the error to the next load.
            where = f" ({obj.source})" if obj.source else ""
            raise WriteError(f"cannot write the {obj.kind}{where}: its transform is singular (a scale of 0?)")
        lines += [indent + statement for statement in material_statements(material, obj.material)]
        material = obj.material
        if obj.name and _one_line(obj.name):
            lines.append(f"{indent}! name: {_one_line(obj.name)}")
        lines.append(f"{indent}{_transform_text(obj.matrix)} {_shape_keyword(obj, mesh_names)}")
    return "\n".join(lines) + "\n"


def _one_line(name: str) -> str:
    """A name as a ``! name:`` comment holds it: the comment ends at a line break (which becomes a space), and
    the reader strips white space at either end."""
    return name.replace("\n", " ").strip()


def write_sdl(scene: Scene) -> str:
    """The scene as SDL text.  Mesh shapes must have a ``mesh_file`` (``save_sdl`` can write their data)."""
    return _scene_text(scene, {}, dict(scene.pixmaps))


def _safe_stem(path: Path) -> str:
    return re.sub(r"[^A-Za-z0-9._-]", "_", path.stem) or "scene"


def _relative_to(target: str, folder: Path) -> str:
    """``target`` (relative to the current folder, or absolute) as seen from ``folder``, if possible."""
    try:
        return os.path.relpath(os.path.abspath(target), os.path.abspath(folder))
    except ValueError:  # another drive on Windows
        return os.path.abspath(target)


def save_sdl(scene: Scene, path: PathLike) -> None:
    """Write the scene to ``path`` atomically.

    File names are rewritten to be relative to the new file's folder: pixmaps (stored resolved), and mesh
    files (relative to ``scene.source``'s folder, when known).  Mesh shapes without a file get their data
    written beside the scene as ``<stem>_mesh<k>.3vn``.  If anything fails, no file written by this call
    is left behind.
    """
    path = Path(path)
    folder = path.parent
    mesh_names: dict[int, str] = {}
    new_meshes: dict[int, tuple[MeshData, Path]] = {}  # by id(mesh): one file per distinct mesh
    for shape in scene.shapes():
        if not shapes.KINDS[shape.kind].file_argument:
            continue
        if shape.mesh_file is None:
            if shape.mesh is None:
                raise WriteError("a mesh shape has neither a file name nor mesh data")
            if id(shape.mesh) not in new_meshes:
                name = f"{_safe_stem(path)}_mesh{len(new_meshes) + 1}.3vn"
                new_meshes[id(shape.mesh)] = (shape.mesh, folder / name)
            mesh_names[id(shape)] = new_meshes[id(shape.mesh)][1].name
        elif scene.source is not None and not os.path.isabs(shape.mesh_file):
            mesh_names[id(shape)] = _relative_to(str(Path(scene.source).parent / shape.mesh_file), folder)
    pixmaps = {index: _relative_to(name, folder) for index, name in scene.pixmaps.items()}
    text = _scene_text(scene, mesh_names, pixmaps)  # every formatting error happens before any file is touched

    created: list[Path] = []
    try:
        for mesh, target in new_meshes.values():
            existed = target.exists()
            write_3vn(mesh, target)
            if not existed:
                created.append(target)
        write_text_atomic(path, text)
    except BaseException:
        for target in created:
            try:
                target.unlink()
            except OSError:
                pass
        raise
