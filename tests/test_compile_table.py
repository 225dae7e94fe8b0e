"""Compiling a scene whose objects are a ShapeTable: from its columns, without making a Shape, to the same
numbers and the same images as the scene of the list of Shapes it reads as."""
from __future__ import annotations

from fractions import Fraction

import numpy as np
import pytest

from tracer import compile as compile_module
from tracer.compile import compile_scene
from tracer.errors import TracerError
from tracer.model import Material, Shape, ShapeTable
from tracer.render import render
from tracer.sdl.parser import parse_sdl

#: Every closed-form kind, tapers, polyhedra, the teapot; reflective, transparent and plain materials.
TEXT = """\
camera 0 3 12  0 0.5 0  0 1 0  40
light 5 8 6  1 1 1
light -6 4 3  0.3 0.3 0.4
background 0.1 0.1 0.2
push diffuse 0.6 0.6 0.6 rotate -90 1 0 0 scale 8 8 8 square pop
diffuse 0.9 0.2 0.2 specular 0.5 0.5 0.5 specularExponent 20
push translate -3 1 0 sphere pop
push translate -1 1 0 rotate 30 0 1 0 scale 0.7 0.7 0.7 cube pop
diffuse 0.2 0.8 0.3 reflectivity 0.5
push translate 1 0 0 rotate -90 1 0 0 taperedCylinder 0.4 pop
push translate 3 0 0 rotate -90 1 0 0 scale 0.6 0.6 1.5 cone pop
push translate 3 0 -3 rotate -90 1 0 0 scale 0.5 0.5 1 cylinder pop
reflectivity 0 transparency 0.7 speedOfLight 0.8 diffuse 0.2 0.2 0.9
push translate 0 2.5 -1 scale 0.8 0.8 0.8 octahedron pop
push translate -2 2.5 -2 dodecahedron pop
transparency 0 diffuse 0.9 0.9 0.2
push translate 0 0.6 2 scale 0.4 0.4 0.4 teapot pop
push translate -3 0.3 2.5 rotate -90 1 0 0 scale 0.6 0.6 0.6 torus pop
"""


def scenes(text: str = TEXT):
    """(the scene as the Python reader gives it, the same scene with its shapes as a table)"""
    listed, tabled = parse_sdl(text, file="t.sdl"), parse_sdl(text, file="t.sdl")
    tabled.objects = ShapeTable.of_shapes(tabled.objects)
    return listed, tabled


@pytest.fixture
def shapes_made(monkeypatch):
    """How many Shape objects are made during the test."""
    made = {"count": 0}
    real = Shape.__post_init__

    def counting(self):
        made["count"] += 1
        real(self)

    monkeypatch.setattr(Shape, "__post_init__", counting)
    return made


def test_the_table_compiles_to_the_lists_numbers(shapes_made):
    listed, tabled = scenes()
    a = compile_scene(listed)
    shapes_made["count"] = 0
    b = compile_scene(tabled)
    assert shapes_made["count"] == 0 and tabled.objects.columns is not None
    for name in ("inverses", "inverse_error", "inverse_norms", "generic_size", "spheres", "boxes", "kind", "parameters",
                 "material_ids"):
        assert np.array_equal(getattr(a.table, name), getattr(b.table, name)), name
    assert a.effects == b.effects
    assert list(a.materials.materials) == list(b.materials.materials)
    assert sorted(m.origin for m in (s.mesh for s in listed.objects) if m) == sorted(
        b.table.mesh_of(i).origin for i in range(len(tabled.objects)) if b.table.mesh_of(i) is not None)


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_the_table_renders_the_lists_image(backend, shapes_made):
    listed, tabled = scenes()
    expected = render(listed, 48, 36, backend=backend, threads=2).image
    shapes_made["count"] = 0
    image = render(tabled, 48, 36, backend=backend, threads=2).image
    assert np.array_equal(image, expected)
    assert tabled.objects.columns is not None  # never made into a list of Shapes
    if backend == "c":
        # the C core reads the arrays; only the two transparent solids are probed by the NumPy path for
        # whether a light is inside them (tracer.skippable.sealed_lights), each from its own Shape
        assert shapes_made["count"] == 2
    else:  # the NumPy path's primitives make their own shape each (shape_at), once
        assert shapes_made["count"] == len(tabled.objects)


def test_primitives_of_a_table_are_its_rows():
    listed, tabled = scenes()
    compiled = compile_scene(tabled)
    for i, prim in enumerate(compiled.primitives):
        assert prim.shape == listed.objects[i] and prim.kind == listed.objects[i].kind
        assert np.array_equal(prim.inverse, compiled.table.inverses[i])
    assert compiled.primitives[-2].triangle_mesh is not None  # the teapot's


def test_compiled_once_until_the_table_changes():
    _, tabled = scenes()
    first = compile_scene(tabled)
    assert compile_scene(tabled) is first
    list(tabled.objects)  # made into Shapes: compiled anew from them, to the same numbers
    again = compile_scene(tabled)
    assert again is not first and np.array_equal(again.table.inverses, first.table.inverses)
    tabled.objects[1].matrix[0, 3] += 1.0  # an edit in place
    edited = compile_scene(tabled)
    assert edited is not again and edited.table.spheres[1, 0] == again.table.spheres[1, 0] + 1.0


def test_tables_of_other_content_have_other_keys():
    _, a = scenes()
    _, b = scenes(TEXT.replace("translate -3 1 0 sphere", "translate -3 1.5 0 sphere"))
    _, c = scenes(TEXT.replace("reflectivity 0.5", "reflectivity 0.6"))
    keys = [compile_module.content_key(s) for s in (a, b, c)]
    assert len(set(keys)) == 3
    _, a_again = scenes()
    assert compile_module.content_key(a_again)[2:] == keys[0][2:]  # (another table: its id differs only)


def test_unused_materials_of_a_table_do_not_make_effects():
    _, tabled = scenes("light 1 1 1 1 1 1\nsphere\n")
    c = tabled.objects.columns
    table = ShapeTable(c.kinds, c.affines, [1], [Material(reflectivity=0.9), c.materials[0]], c.parameters,
                       c.lines, c.columns, c.file)
    tabled.objects = table
    compiled = compile_scene(tabled)
    assert "reflection" not in compiled.effects and list(compiled.materials.materials) == [c.materials[0]]


@pytest.mark.parametrize("bad, message", [
    (np.zeros(12), "t.sdl:3:7: sphere has a singular transform (a scale of 0?)"),
    (np.r_[np.nan, np.zeros(11)], "t.sdl:3:7: sphere has a transform that is not a finite affine matrix"),
])
def test_a_bad_matrix_names_the_shapes_place(bad, message):
    n = 70_000  # (more than a chunk of rows: the bad one is in the third)
    affines = np.tile(np.eye(4)[:3].reshape(12), (n, 1))
    affines[66_000] = bad
    lines = np.full(n, 1, dtype=np.int32)
    lines[66_000] = 3
    table = ShapeTable(np.zeros(n, dtype=np.int16), affines, np.zeros(n, dtype=np.int32), [Material()],
                       np.ones(n), lines, np.full(n, 7, dtype=np.int32), "t.sdl")
    scene = parse_sdl("light 1 1 1 1 1 1\n")
    scene.objects = table
    with pytest.raises(TracerError) as info:
        compile_scene(scene)
    assert str(info.value) == message


def test_nested_unions_keep_a_tight_bound():
    """A boolean's bounding sphere is made from the box of its operands' boxes: it does not grow with the
    nesting (from spheres round spheres' boxes it grew by up to sqrt(3) a level, and 2,000 levels
    overflowed)."""
    import warnings

    from helpers import scaling, scene_of, shape, translation
    from tracer.backend import MAX_CSG_DEPTH
    from tracer.model import CSG

    node = shape("sphere", translation(0, 0, 0) @ scaling(0.5, 0.5, 0.5))
    for k in range(1, MAX_CSG_DEPTH + 1):  # a chain of unions along x, each adding a ball
        node = CSG("union", node, shape("sphere", translation(k * 1e-3, 0, 0) @ scaling(0.5, 0.5, 0.5)))
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # (no overflow on the way)
        compiled = compile_scene(scene_of(node))
    root = compiled.objects[0]
    reach = MAX_CSG_DEPTH * 1e-3
    assert np.allclose(root.center, (reach / 2, 0, 0))
    # the sphere round the box [-0.5, reach + 0.5] x [-0.5, 0.5]^2, padded by 1e-9 relatively
    expected = 0.5 * np.linalg.norm([reach + 1.0, 1.0, 1.0])
    assert expected <= root.radius <= expected * (1 + 1e-8)
    intersection = compile_scene(scene_of(CSG("intersection", shape("plane"), shape("cube")))).objects[0]
    assert intersection.radius == pytest.approx(np.sqrt(3), rel=1e-8)  # the cube's, not unbounded


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_nested_booleans_render_as_before(backend):
    """Tighter boolean bounds change no pixel: the culling only skips rays that miss."""
    from helpers import Camera, Light, scaling, scene_of, shape, translation
    from tracer.model import CSG

    node = shape("cube", scaling(0.4, 0.4, 0.4), diffuse=(0.9, 0.3, 0.2))
    for k in range(1, 40):
        other = shape("sphere", translation(0.05 * k - 1, 0.02 * k, 0) @ scaling(0.3, 0.3, 0.3), diffuse=(0.2, 0.9, 0.3))
        node = CSG("difference" if k % 3 == 0 else "union", node, other)
    scene = scene_of(node, lights=[Light((3, 4, 5), (1, 1, 1))], camera=Camera((0, 1, 4), (0, 0, 0), (0, 1, 0), 50))
    image = render(scene, 40, 30, backend=backend, threads=2).image
    assert image.std() > 0.01  # (something is drawn)
    baseline = render(scene, 40, 30, backend="c" if backend == "numpy" else "numpy", threads=2).image
    assert np.abs(image - baseline).max() <= 1 / 255


def _exact_world(matrix: np.ndarray, vertices: np.ndarray) -> list[list[Fraction]]:
    """Each vertex carried by the matrix in exact (rational) arithmetic."""
    m = [[Fraction(float(x)) for x in row] for row in matrix[:3]]
    return [[sum(m[r][j] * Fraction(float(v[j])) for j in range(3)) + m[r][3] for r in range(3)] for v in vertices]


def test_mesh_instances_are_bounded_from_the_mesh_once():
    """A mesh instance's world box comes from its mesh's own box and sphere (computed once per mesh, not by
    carrying every vertex): it holds every vertex carried in exact arithmetic, even where the translation
    cancels the vertices' size (1e8 away), and is as tight as the vertices' own box for an axis-aligned
    instance and within 0.2% of it for a rotated ball."""
    from helpers import rotation, scaling, scene_of, translation
    from tracer.meshdata import MeshData

    rng = np.random.default_rng(5)
    k = np.arange(3000) + 0.5  # (a Fibonacci sphere: points spread evenly over the unit sphere)
    z, phi = 1 - 2 * k / 3000, np.pi * (1 + 5 ** 0.5) * k
    ball = np.stack([np.sqrt(1 - z * z) * np.cos(phi), np.sqrt(1 - z * z) * np.sin(phi), z], axis=1)
    lumpy = rng.uniform(-1, 1, size=(40, 3)) * (3.0, 0.2, 1.0) + (1e8, 0.0, 0.0)
    meshes = [MeshData(v, np.zeros((0, 3)), [((0, 1, 2), ())], origin=f"test:{k}")
              for k, v in enumerate((ball, lumpy))]
    aligned = [np.eye(4), translation(5, -2, 7) @ scaling(2, 3, 4), translation(-1e8, 3.3, 1e-7) @ scaling(1, -1, 1)]
    rotated = [rotation(37, 1, 2, 3) @ scaling(0.3, 1.7, 0.9), translation(-1e8, 3.3, 1e-7) @ rotation(0.001, 0, 0, 1),
               translation(-0.7e8, 1e8, 0) @ rotation(81, 3, -1, 2) @ scaling(0.7, 0.7, 0.7)]
    objects = [Shape("mesh", m, mesh=mesh) for mesh in meshes for m in aligned + rotated]
    table = compile_scene(scene_of(*objects)).table
    for i, shape in enumerate(objects):
        lo, hi = table.boxes[i, :3], table.boxes[i, 3:]
        exact = _exact_world(shape.matrix, shape.mesh.vertices)
        assert all(Fraction(float(lo[r])) <= p[r] <= Fraction(float(hi[r])) for p in exact for r in range(3)), i
        world = shape.mesh.vertices @ shape.matrix[:3, :3].T + shape.matrix[:3, 3]
        tight_lo, tight_hi = world.min(axis=0), world.max(axis=0)
        rounding = 1e-12 * (np.abs(world).max() + np.abs(shape.matrix[:3, 3]).max() + 1.0)
        if i % len(aligned + rotated) < len(aligned):  # axis-aligned: the vertices' own box
            assert np.allclose(lo, tight_lo, rtol=0, atol=rounding), i
            assert np.allclose(hi, tight_hi, rtol=0, atol=rounding), i
        elif shape.mesh is meshes[0]:  # a rotated ball: its sphere's image, close to the vertices' own box
            assert np.all(hi - lo <= (tight_hi - tight_lo) * 1.002 + rounding), i
        assert table.generic_size[i] == np.abs(shape.mesh.vertices).max()


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_mesh_instances_render_as_when_bounded_by_their_vertices(backend, monkeypatch):
    """Bounds made from the mesh once change no pixel against bounds made from every vertex carried to the
    world (what the compile did before): the culling only skips rays that miss."""
    from helpers import Camera, Light, rotation, scaling, scene_of, translation
    from tracer.geometry import builtin_mesh

    teapot = builtin_mesh("teapot")
    rng = np.random.default_rng(2)
    objects = [Shape("mesh", translation(1.2 * (k % 5) - 2.4, 1.2 * (k // 5) - 1.2, 0)
                     @ rotation(float(rng.uniform(0, 360)), *rng.normal(size=3)) @ scaling(0.3, 0.3, 0.3),
                     Material(diffuse=(0.8, 0.4, 0.2), reflectivity=0.3), mesh=teapot) for k in range(15)]

    def scene():
        return scene_of(*objects, lights=[Light((3, 4, 5), (1, 1, 1))], camera=Camera((0, 0, 6), (0, 0, 0), (0, 1, 0), 50))

    image = render(scene(), 40, 30, backend=backend, threads=2).image

    def by_vertices(self, mesh, rows):
        self.generic_size[rows] = np.abs(mesh.vertices).max()
        self._bound(rows, np.asarray(mesh.vertices, dtype=np.float64))

    monkeypatch.setattr(compile_module.PrimitiveTable, "_bound_mesh_instances", by_vertices)
    assert np.array_equal(render(scene(), 40, 30, backend=backend, threads=2).image, image)
    assert image.std() > 0.01
