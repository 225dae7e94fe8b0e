"""A ShapeTable whose rows hold meshes of their own (the add-on's geometry-nodes instances, gathered by
tracer.model.TableRows): it reads as the Shapes it was made of, compiles from its columns to the numbers of
that list of Shapes, and renders its image, without a Python object per row."""
from __future__ import annotations

import pickle

import numpy as np
import pytest

from tracer.compile import compile_scene
from tracer.geometry import builtin_mesh
from tracer.meshdata import MeshData
from tracer.model import (CSG, Camera, Light, Material, RowNames, Scene, Shape, ShapeTable, SourceLocation,
                          TableRows)
from tracer.render import render
from tracer.shapes import keywords

#: The kind codes a table's ``kinds`` hold: each keyword's index in tracer.shapes.REGISTRY.
KEYWORDS = keywords()


def _mesh(origin: str, lift: float = 0.0) -> MeshData:
    """A closed tetrahedron (flat normals per corner)."""
    vertices = np.array([(0, 0, 1 + lift), (1, 0, -0.5), (-0.5, 0.9, -0.5), (-0.5, -0.9, -0.5)], dtype=np.float64)
    faces = [(0, 1, 2), (0, 2, 3), (0, 3, 1), (1, 3, 2)]
    normals = []
    for a, b, c in faces:
        n = np.cross(vertices[b] - vertices[a], vertices[c] - vertices[a])
        normals += [n / np.linalg.norm(n)] * 3
    return MeshData(vertices, np.array(normals), [(f, tuple(range(3 * k, 3 * k + 3))) for k, f in enumerate(faces)],
                    origin=origin)


def _matrices(n: int, float32: bool, seed: int = 3) -> np.ndarray:
    """n rotated, scaled and moved affine matrices (of float32 values where ``float32``, as Blender's are)."""
    rng = np.random.default_rng(seed)
    out = np.zeros((n, 4, 4))
    for i in range(n):
        q, _ = np.linalg.qr(rng.normal(size=(3, 3)))
        out[i, :3, :3] = q * rng.uniform(0.3, 0.6, size=3)
        out[i, :3, 3] = (i % 5 - 2.0, i // 5 - 2.0, rng.uniform(-1, 1))
        out[i, 3, 3] = 1.0
    return out.astype(np.float32).astype(np.float64) if float32 else out


def _shapes(float32: bool = True) -> list[Shape]:
    """Instances of two meshes (each in two materials, as a Blender mesh with two material slots gives) and
    a sphere and a teapot between them."""
    red, blue, grey = Material(diffuse=(0.9, 0.1, 0.1)), Material(diffuse=(0.1, 0.2, 0.9)), Material()
    tall, short = _mesh("tall", 0.5), _mesh("short")
    shapes = []
    for i, matrix in enumerate(_matrices(20, float32)):
        mesh = tall if i % 3 else short
        shapes += [Shape("mesh", matrix, red, mesh=mesh, name="Grid"), Shape("mesh", matrix, blue, mesh=mesh, name="Grid")]
        if i == 7:
            shapes.append(Shape("sphere", np.diag([0.5, 0.5, 0.5, 1.0]) + np.eye(4, k=3) * 0.1, grey, name="Ball"))
            shapes.append(Shape("teapot", np.diag([0.3, 0.3, 0.3, 1.0]), grey, mesh=builtin_mesh("teapot")))
    return shapes


def _table(shapes: list[Shape]) -> ShapeTable:
    rows = TableRows()
    for shape in shapes:
        assert TableRows.can_hold(shape)
        rows.add_shape(shape)
    return rows.table()


def _scene(objects) -> Scene:
    return Scene(objects=objects, lights=[Light(position=(3.0, 4.0, 6.0), color=(1.0, 1.0, 1.0))],
                 camera=Camera(eye=(0.0, -7.0, 5.0), look=(0.0, 0.0, 0.0), up=(0.0, 0.0, 1.0)))


@pytest.mark.parametrize("float32", [True, False])
def test_the_rows_read_as_the_shapes_they_were_made_of(float32):
    shapes = _shapes(float32)
    table = _table(shapes)
    columns = table.columns
    # float32 matrices are kept as float32 (the sphere's 0.1 is not one: then everything is float64)
    assert columns.affines.dtype == np.float64
    exact = _table([s for s in shapes if s.kind == "mesh"]) if float32 else None
    if float32:
        assert exact.columns.affines.dtype == np.float32
        assert [exact.shape_at(i) for i in range(len(exact))] == [s for s in shapes if s.kind == "mesh"]
    assert len(columns.meshes) == 2 and columns.lines is None  # (the teapot's is its built-in mesh)
    assert [table.shape_at(i) for i in range(len(table))] == shapes
    assert table.shape_at(0).mesh is shapes[0].mesh and table.shape_at(0).source is None
    assert list(table) == shapes  # (made into Shapes all at once: the same)


def test_a_table_of_mesh_rows_compiles_and_renders_as_its_shapes():
    shapes = _shapes()
    listed, tabled = _scene(shapes), _scene(_table(shapes))
    a, b = compile_scene(listed), compile_scene(tabled)
    assert tabled.objects.columns is not None  # compiled from the columns
    for name in ("inverses", "inverse_error", "inverse_norms", "generic_size", "spheres", "boxes", "kind",
                 "parameters", "material_ids"):
        assert np.array_equal(getattr(a.table, name), getattr(b.table, name)), name
    assert [(id(mesh), rows.tolist()) for mesh, rows in a.table.mesh_groups()] == [
        (id(mesh), rows.tolist()) for mesh, rows in b.table.mesh_groups()]
    assert list(a.materials.materials) == list(b.materials.materials) and a.effects == b.effects
    expected = render(listed, 40, 30, backend="c", threads=2).image
    assert np.array_equal(render(tabled, 40, 30, backend="c", threads=2).image, expected)
    assert tabled.objects.columns is not None


def test_pickled_with_its_meshes_and_names():
    shapes = _shapes()
    table = _table(shapes)
    again = pickle.loads(pickle.dumps(table))
    assert again.columns is not None and [again.shape_at(i) for i in range(len(again))] == shapes
    names = table.columns.names
    assert isinstance(names, RowNames) and names.get(0) == "Grid" and names.get(len(table) - 1) == "Grid"
    assert dict(names.items())[16] == "Ball" and names.get(17) is None  # (the teapot has no name)


def test_rows_that_a_table_cannot_hold():
    matrix = np.eye(4)
    sphere = Shape("sphere", matrix)
    assert not TableRows.can_hold(CSG("union", sphere, Shape("cube")))
    assert not TableRows.can_hold(Shape("sphere", matrix, groups=("a",)))
    assert not TableRows.can_hold(Shape("sphere", matrix, source=SourceLocation("f.sdl", 1)))
    projective = np.eye(4)
    projective[3, 0] = 0.5
    assert not TableRows.can_hold(Shape("sphere", projective))
    assert not TableRows.can_hold(Shape("cube", matrix, mesh=_mesh("a cube that is not one")))
    assert TableRows.can_hold(sphere) and TableRows.can_hold(Shape("mesh", matrix, mesh=_mesh("m")))


def test_bad_mesh_numbers_are_refused():
    args = (np.eye(4)[:3].reshape(1, 12), [0], [Material()], np.zeros(1), None, None)
    mesh, sphere = np.array([KEYWORDS.index("mesh")]), np.array([KEYWORDS.index("sphere")])
    with pytest.raises(ValueError, match="mesh row has no mesh"):
        ShapeTable(mesh, *args)
    with pytest.raises(ValueError, match="not an index into meshes"):
        ShapeTable(mesh, *args, meshes=(_mesh("m"),), mesh_ids=[1])
    with pytest.raises(ValueError, match="without a mesh of its own"):
        ShapeTable(sphere, *args, meshes=(_mesh("m"),), mesh_ids=[0])
    assert ShapeTable(mesh, *args, meshes=(_mesh("m"),), mesh_ids=[0]).shape_at(0).mesh.origin == "m"
