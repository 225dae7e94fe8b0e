"""Compile once: compile_scene keeps its result on the scene and gives it back while the scene is unchanged,
every kind of change compiles again, and a mesh is built once per content however often it is used."""
from __future__ import annotations

import weakref
from dataclasses import replace

import numpy as np
import pytest

import tracer
from helpers import Camera, Light, scene_of, shape, translation
from tracer import compile as compile_module
from tracer.compile import compile_scene
from tracer.intersect import mesh as mesh_module
from tracer.meshio import write_3vn
from tracer.model import CSG, Material, MeshData
from tracer.render import render


@pytest.fixture
def counted(monkeypatch):
    """Counts of scene compilations and of triangle-mesh builds during the test."""
    counts = {"compile": 0, "mesh": 0}
    real_compile, real_init = compile_module._compile, mesh_module.TriangleMesh.__init__

    def counting_compile(scene, *args):
        counts["compile"] += 1
        return real_compile(scene, *args)

    def counting_init(self, *args, **kwargs):
        counts["mesh"] += 1
        real_init(self, *args, **kwargs)

    monkeypatch.setattr(compile_module, "_TRIANGLE_MESHES", weakref.WeakValueDictionary())  # start empty
    monkeypatch.setattr(compile_module, "_compile", counting_compile)
    monkeypatch.setattr(mesh_module.TriangleMesh, "__init__", counting_init)
    return counts


def _pyramid(scale: float = 1.0) -> MeshData:
    vertices = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0], [0, 0, 1]], dtype=float) * scale
    faces = [((3, 2, 1, 0), ()), ((0, 1, 4), ()), ((1, 2, 4), ()), ((2, 3, 4), ()), ((3, 0, 4), ())]
    return MeshData(vertices, np.zeros((0, 3)), faces, origin="test:pyramid")


def _scene():
    mesh = shape("mesh", translation(-1.5, 0, 0))
    mesh.mesh = _pyramid()
    return scene_of(shape("sphere", translation(1.5, 0, 0)), mesh,
                    CSG("difference", shape("cube"), shape("sphere", translation(0, 0, 1))),
                    lights=[Light((3, 4, 5), (1, 1, 1))], camera=Camera((0, 1, 8), (0, 0, 0), (0, 1, 0), 45))


def test_an_unchanged_scene_is_compiled_once(counted):
    scene = _scene()
    first = compile_scene(scene)
    assert compile_scene(scene) is first
    a = render(scene, 24, 18, backend="numpy")
    b = render(scene, 24, 18, backend="numpy", samples=2)
    assert counted == {"compile": 1, "mesh": 1}
    assert a.image.shape == b.image.shape == (18, 24, 3)


def _changes():
    def matrix_in_place(s):
        s.objects[0].matrix[0, 3] += 0.5

    def material(s):
        s.objects[0].material = Material(diffuse=(0.1, 0.9, 0.1))

    def new_object(s):
        s.objects.append(shape("sphere", translation(0, 2, 0)))

    def reorder(s):
        s.objects.reverse()

    def csg_operation(s):
        s.objects[2].op = "union"

    def csg_operand(s):
        s.objects[2].right = shape("cube", translation(0, 0, 1.2))

    def light(s):
        s.lights[0] = Light((-3, 4, 5), (1, 1, 1))

    def settings(s):
        s.settings.max_recursion_depth = 0

    def camera(s):
        s.camera = Camera((0, 2, 8), (0, 0, 0), (0, 1, 0), 45)

    def mesh_vertices_in_place(s):
        s.objects[1].mesh.vertices[4, 2] = 2.0

    def taper(s):
        s.objects[0].kind = "taperedCylinder"
        s.objects[0].parameters = (0.3,)

    return [matrix_in_place, material, new_object, reorder, csg_operation, csg_operand, light, settings, camera,
            mesh_vertices_in_place, taper]


@pytest.mark.parametrize("change", _changes(), ids=lambda f: f.__name__)
def test_every_change_compiles_again_and_renders_the_change(counted, change):
    scene = _scene()
    before = compile_scene(scene)
    image = render(scene, 24, 18, backend="numpy").image
    change(scene)
    after = compile_scene(scene)
    assert after is not before and counted["compile"] == 2
    assert compile_scene(scene) is after
    # The picture is the one a fresh compile of the changed scene gives.
    fresh = render(compile_module._compile(scene), 24, 18, backend="numpy").image
    assert np.array_equal(render(scene, 24, 18, backend="numpy").image, fresh)
    if change.__name__ == "reorder":  # the same picture, the primitives numbered the other way round
        assert after.primitives[-1].shape is before.primitives[0].shape
    elif change.__name__ != "settings":  # (depth 0 changes nothing without mirrors)
        assert not np.array_equal(image, fresh)


def test_a_copy_of_a_scene_does_not_share_its_cache(counted):
    scene = _scene()
    compile_scene(scene)
    shallower = replace(scene, settings=replace(scene.settings, max_recursion_depth=0))
    assert compile_scene(shallower).settings.max_recursion_depth == 0
    assert counted["compile"] == 2 and counted["mesh"] == 1  # the mesh's content did not change


def test_a_mesh_file_used_a_thousand_times_is_read_and_built_once(tmp_path, counted, monkeypatch):
    write_3vn(_pyramid(), tmp_path / "pyramid.3vn")
    lines = ["camera 0 0 60  0 0 0  0 1 0  40", "light 10 10 10 1 1 1"]
    lines += [f"push translate {x % 40 - 20} {x // 40 - 12} 0 mesh pyramid.3vn pop" for x in range(1000)]
    (tmp_path / "many.sdl").write_text("\n".join(lines) + "\n")
    reads = []
    from tracer.sdl import parser
    real_read = parser.read_3vn
    monkeypatch.setattr(parser, "read_3vn", lambda path: reads.append(path) or real_read(path))
    scene = tracer.load(tmp_path / "many.sdl")
    compiled = compile_scene(scene)
    assert len(reads) == 1 and counted["mesh"] == 1
    assert len({id(p._mesh) for p in compiled.primitives}) == 1
    # A second scene read from the same file (new MeshData objects, same content) builds nothing either.
    compile_scene(tracer.load(tmp_path / "many.sdl"))
    assert counted["mesh"] == 1 and counted["compile"] == 2


def test_meshes_of_other_content_are_built_apart(counted):
    scene = _scene()
    other = shape("mesh", translation(0, 2, 0))
    other.mesh = _pyramid(scale=0.5)
    scene.objects.append(other)
    compiled = compile_scene(scene)
    assert counted["mesh"] == 2
    meshes = [p._mesh for p in compiled.primitives if p._mesh is not None]
    assert meshes[0] is not meshes[1] and not np.array_equal(meshes[0].bounds, meshes[1].bounds)


def test_a_second_render_in_c_flattens_nothing(counted, monkeypatch):
    native = pytest.importorskip("tracer.native")
    if native.load_error is not None:
        pytest.skip(f"no C core: {native.load_error}")
    from tracer import numerics
    from tracer.native import flatten
    made = []
    real = flatten.FlatScene.__init__
    monkeypatch.setattr(flatten.FlatScene, "__init__", lambda self, c: made.append(c) or real(self, c))
    scene = _scene()
    first = render(scene, 24, 18, backend="c").image
    assert np.array_equal(render(scene, 24, 18, backend="c").image, first)
    assert len(made) == 1 and counted["compile"] == 1
    # The solver tolerances are compiled in (tracer.accuracy varies them): a change compiles and flattens again.
    monkeypatch.setattr(numerics, "TOLERANCES", replace(numerics.TOLERANCES, hit_ulps=numerics.TOLERANCES.hit_ulps * 2))
    render(scene, 24, 18, backend="c")
    assert len(made) == 2 and counted["compile"] == 2


def test_copies_and_pickles_of_a_rendered_scene_leave_the_compiled_form_behind(counted):
    import copy
    import pickle
    scene = _scene()
    image = render(scene, 24, 18).image  # (the C core's flattened scene, with its pointers, is cached too)
    for other in (pickle.loads(pickle.dumps(scene)), copy.deepcopy(scene), copy.copy(scene)):
        assert np.array_equal(render(other, 24, 18).image, image)
    # The pickled and the deep copy compiled their own; a shallow copy has the very same objects and content,
    # so the entry it shares is still right for it.
    assert counted["compile"] == 3
