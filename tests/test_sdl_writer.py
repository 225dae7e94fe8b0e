import os

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from tracer import transforms
from tracer.model import CSG, Camera, Light, Material, MeshData, Scene, Settings, Shape
from tracer.sdl import parser as sdl_parser
from tracer.sdl import writer as sdl_writer
from tracer.sdl.parser import load, parse_sdl
from tracer.sdl.writer import save_sdl, transform_statements, write_sdl

TRIANGLE = MeshData(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0.5]]), np.array([[0, 0, 1.0]]), [((0, 1, 2), (0, 0, 0))])


@pytest.fixture(autouse=True)
def fake_builtins(monkeypatch):
    # The writer tests must not depend on the polyhedra/teapot modules: reading back just needs a mesh.
    monkeypatch.setattr(sdl_parser, "builtin_mesh", lambda kind: TRIANGLE)


def round_trip(scene: Scene) -> Scene:
    return parse_sdl(write_sdl(scene))


def assert_same_objects(a, b, tol=1e-12):
    assert len(a) == len(b)
    pairs = list(zip(a, b))
    while pairs:
        x, y = pairs.pop()
        assert type(x) is type(y)
        if isinstance(x, CSG):
            assert x.op == y.op
            pairs += [(x.left, y.left), (x.right, y.right)]
            continue
        assert x.kind == y.kind and x.material == y.material and x.parameters == y.parameters
        assert x.mesh_file == y.mesh_file
        assert np.max(np.abs(x.matrix - y.matrix)) <= tol


def shape_at(matrix, kind="cube", **kwargs):
    return Shape(kind, matrix=matrix, **kwargs)


# --- transforms --------------------------------------------------------------------------------------------

def affine(entries):
    m = np.eye(4)
    m[:3, :] = np.array(entries).reshape(3, 4)
    return m


entries = st.lists(st.floats(-10, 10, allow_nan=False), min_size=12, max_size=12)


@settings(max_examples=300, deadline=None)
@given(entries)
def test_any_invertible_affine_matrix_round_trips(values):
    m = affine(values)
    assume(abs(np.linalg.det(m[:3, :3])) > 1e-3)
    back = round_trip(Scene(objects=[shape_at(m)])).objects[0].matrix
    assert np.max(np.abs(back - m)) <= 1e-12


@settings(max_examples=200, deadline=None)
@given(st.floats(-360, 360), st.lists(st.floats(-1, 1), min_size=3, max_size=3),
       st.lists(st.floats(0.01, 100), min_size=3, max_size=3), st.sampled_from([1, -1]),
       st.floats(-5, 5), st.floats(-5, 5))
def test_rotations_mirrors_and_shears_round_trip(angle, axis, scales, mirror, shear_xy, shear_xz):
    assume(np.linalg.norm(axis) > 1e-3)
    shear = np.eye(4)
    shear[0, 1], shear[0, 2] = shear_xy, shear_xz
    m = (transforms.translation(3, -2, 1) @ transforms.rotation(angle, *axis)
         @ transforms.scaling(scales[0] * mirror, scales[1], scales[2]) @ shear)
    assert np.sign(np.linalg.det(m)) == mirror
    back = round_trip(Scene(objects=[shape_at(m)])).objects[0].matrix
    assert np.max(np.abs(back - m)) <= 1e-12


def test_strong_shear_with_large_scales():
    # LAPACK's SVD alone rebuilds this one only to 1.3e-12; the writer must do better.
    shear = np.eye(4)
    shear[0, 1], shear[0, 2] = 1e-5, 4.75
    m = transforms.translation(3, -2, 1) @ transforms.scaling(33, 32, 2.5) @ shear
    back = round_trip(Scene(objects=[shape_at(m)])).objects[0].matrix
    assert np.max(np.abs(back - m)) <= 1e-12


def test_reflection_with_negative_determinant():
    m = np.diag([1.0, 1.0, -1.0, 1.0])
    m = transforms.rotation(30, 1, 1, 0) @ m @ transforms.rotation(-70, 0, 1, 1)
    assert np.linalg.det(m) < 0
    back = round_trip(Scene(objects=[shape_at(m)])).objects[0].matrix
    assert np.max(np.abs(back - m)) <= 1e-12


def test_statement_order_is_translate_rotate_scale_rotate_for_shears():
    m = transforms.translation(1, 2, 3)
    m[0, 1] = 0.5  # a shear: no rotation-and-scale form exists
    keywords = [kw for kw, _ in transform_statements(m)]
    assert keywords == ["translate", "rotate", "scale", "rotate"]


def test_simple_transforms_are_written_simply():
    (text,) = [line for line in write_sdl(parse_sdl("translate 2 4 9 scale 1 4 4 sphere")).splitlines()
               if line.endswith("sphere")]
    assert text == "identityAffine translate 2 4 9 scale 1 4 4 sphere"
    (text,) = [line for line in write_sdl(parse_sdl("rotate 45 0 1 0 scale 2 1 1 cube")).splitlines()
               if line.endswith("cube")]
    assert text == "identityAffine rotate 45 0 1 0 scale 2 1 1 cube"
    assert transform_statements(np.eye(4)) == []


def test_rotation_axis_and_angle_near_180_degrees():
    for angle in (179.9999999, 180.0, -179.5, 1e-7):
        m = transforms.rotation(angle, 0.3, -0.4, 0.5)
        back = round_trip(Scene(objects=[shape_at(m)])).objects[0].matrix
        assert np.max(np.abs(back - m)) <= 1e-13


def test_singular_matrices_are_refused():
    # The reader would reject them, so the writer says so at once.
    sheared_flat = np.eye(4)
    sheared_flat[0, 1], sheared_flat[2, 2] = 0.5, 0.0
    for m in (np.diag([1.0, 0.0, 1.0, 1.0]), sheared_flat):
        with pytest.raises(ValueError, match="singular"):
            write_sdl(Scene(objects=[shape_at(m)]))


def test_non_affine_and_non_finite_matrices_are_refused():
    m = np.eye(4)
    m[3, 0] = 1
    with pytest.raises(ValueError):
        write_sdl(Scene(objects=[shape_at(m)]))
    m = np.eye(4)
    m[0, 3] = np.inf
    with pytest.raises(ValueError):
        write_sdl(Scene(objects=[shape_at(m)]))


# --- settings and materials --------------------------------------------------------------------------------

def test_settings_lights_camera_pixmaps_round_trip():
    scene = Scene(settings=Settings(global_ambient=(0.2, 0.1, 0.3), background=(1.0, 0.5, 0.0),
                                    min_reflectivity=0.1, min_transparency=0.9, max_recursion_depth=6),
                  lights=[Light((1.0, 2.0, 3.0), (1.0, 1.0, 1.0)), Light((-1e-5, 0.0, 7.5), (0.25, 0.5, 2.0))],
                  camera=Camera((0.0, 2.0, 10.0), (0.0, 0.0, 0.0), (0.0, 1.0, 0.0), 35.5),
                  pixmaps={2: "tex/wood.bmp", 0: "/abs/sky.bmp"})
    back = round_trip(scene)
    assert back.settings == scene.settings
    assert back.lights == scene.lights and back.camera == scene.camera and back.pixmaps == scene.pixmaps


def test_materials_are_written_only_when_they_change():
    red = Material(diffuse=(1.0, 0.0, 0.0))
    scene = Scene(objects=[shape_at(np.eye(4), material=red), shape_at(np.eye(4), "sphere", material=red),
                           shape_at(np.eye(4), "torus", material=Material(diffuse=(1.0, 0.0, 0.0), texture=3))])
    text = write_sdl(scene)
    assert text.count("diffuse") == 1 and text.count("texture 3") == 1
    assert_same_objects(parse_sdl(text).objects, scene.objects)


def test_default_materials_is_used_when_shorter():
    fancy = Material(ambient=(0.5, 0.5, 0.5), diffuse=(0.1, 0.2, 0.3), specular=(1.0, 1.0, 1.0),
                     reflectivity=0.5, transparency=0.2, texture=-1)
    scene = Scene(objects=[shape_at(np.eye(4), material=fancy), shape_at(np.eye(4), material=Material())])
    lines = write_sdl(scene).splitlines()
    assert "defaultMaterials" in lines
    assert_same_objects(round_trip(scene).objects, scene.objects)


colors = st.tuples(*[st.floats(0, 10, allow_nan=False)] * 3)
numbers = st.floats(-1e9, 1e9, allow_nan=False)
materials = st.builds(Material, ambient=colors, diffuse=colors, specular=colors, emissive=colors,
                      specular_exponent=numbers, reflectivity=st.floats(0, 1), transparency=st.floats(0, 1),
                      speed_of_light=st.floats(0.01, 10), specular_fraction=st.floats(0, 1),
                      surface_roughness=st.floats(0, 1), texture=st.integers(-3, 15),
                      parameters=st.lists(numbers, max_size=10).map(tuple))


@settings(max_examples=100, deadline=None)
@given(st.lists(materials, min_size=1, max_size=5), st.builds(
    Settings, global_ambient=colors, background=colors, min_reflectivity=st.floats(0, 1),
    min_transparency=st.floats(0, 1), max_recursion_depth=st.integers(0, 20)))
def test_random_materials_and_settings_round_trip_exactly(mats, scene_settings):
    scene = Scene(objects=[shape_at(np.eye(4), material=m) for m in mats], settings=scene_settings)
    back = round_trip(scene)
    assert [s.material for s in back.objects] == mats
    assert back.settings == scene_settings


def test_non_finite_numbers_are_refused():
    with pytest.raises(ValueError):
        write_sdl(Scene(objects=[shape_at(np.eye(4), material=Material(reflectivity=float("nan")))]))


# --- shapes ------------------------------------------------------------------------------------------------

def test_every_kind_round_trips():
    text = ("sphere cube square plane taperedCylinder 0.3 cylinder cone torus tetrahedron octahedron "
            "dodecahedron icosahedron buckyball diamond teapot")
    scene = parse_sdl(text)
    written = write_sdl(scene)
    assert "taperedCylinder 0.3" in written and "teapot" in written and "buckyball" in written
    assert_same_objects(parse_sdl(written).objects, scene.objects)


def test_csg_is_written_in_prefix_form():
    text = """diffuse 1 0 0 union intersection sphere translate 1 0 0 cube
              difference cone diffuse 0 1 0 union torus square plane"""
    scene = parse_sdl(text)
    written = write_sdl(scene)
    ops = [line.strip() for line in written.splitlines() if line.strip() in CSG.OPS]
    assert ops == ["union", "intersection", "difference", "union"]
    assert_same_objects(parse_sdl(written).objects, scene.objects)


def test_deep_csg_is_written_without_recursion():
    depth = 3000
    scene = parse_sdl("union " * depth + "sphere " + "cube " * depth)
    assert_same_objects(round_trip(scene).objects, scene.objects)


def test_groups_become_comments():
    scene = parse_sdl("def leg { cube } def table { use leg use leg sphere } use table")
    written = write_sdl(scene)
    assert "! group: table / leg" in written
    assert_same_objects(parse_sdl(written).objects, scene.objects)


def test_mesh_with_a_file_name_is_written_by_name(tmp_path):
    from tracer.meshio import write_3vn
    write_3vn(TRIANGLE, tmp_path / "tri.3vn")
    scene = parse_sdl("mesh tri.3vn", base_dir=tmp_path)
    assert "mesh tri.3vn" in write_sdl(scene)


def test_mesh_without_a_file_needs_save_sdl():
    with pytest.raises(ValueError):
        write_sdl(Scene(objects=[Shape("mesh", mesh=TRIANGLE)]))


def test_bad_file_names_are_refused():
    with pytest.raises(ValueError):
        write_sdl(Scene(objects=[Shape("mesh", mesh=TRIANGLE, mesh_file="my mesh.3vn")]))
    with pytest.raises(ValueError):
        write_sdl(Scene(pixmaps={1: "a{b}.bmp"}))


# --- save_sdl ----------------------------------------------------------------------------------------------

def test_save_and_load_round_trip(tmp_path):
    scene = parse_sdl("""light 1 2 3 1 1 1 globalAmbient .2 .2 .2 diffuse .3 .6 .9
                         rotate 33 1 2 3 translate 1 2 3 scale 1 -2 3 sphere union cube torus""")
    path = tmp_path / "out.sdl"
    save_sdl(scene, path)
    back = load(path)
    assert_same_objects(back.objects, scene.objects)
    assert back.lights == scene.lights and back.settings == scene.settings
    assert [p.name for p in tmp_path.iterdir()] == ["out.sdl"]  # no temporary files left


def test_save_writes_unnamed_meshes_beside_the_scene(tmp_path):
    other = MeshData(np.array([[0, 0, 0], [2, 0, 0], [0, 2, 0], [0, 0, 2]]), np.zeros((0, 3)),
                     [((0, 1, 2), ()), ((0, 1, 3), ())])
    scene = Scene(objects=[Shape("mesh", mesh=TRIANGLE), Shape("mesh", mesh=other),
                           Shape("mesh", matrix=transforms.translation(1, 0, 0), mesh=TRIANGLE)])
    save_sdl(scene, tmp_path / "my scene.sdl")
    files = sorted(p.name for p in tmp_path.iterdir())
    assert files == ["my scene.sdl", "my_scene_mesh1.3vn", "my_scene_mesh2.3vn"]  # one file per mesh
    back = load(tmp_path / "my scene.sdl")
    assert [s.mesh_file for s in back.objects] == ["my_scene_mesh1.3vn", "my_scene_mesh2.3vn",
                                                   "my_scene_mesh1.3vn"]
    assert np.array_equal(back.objects[0].mesh.vertices, TRIANGLE.vertices)
    assert back.objects[1].mesh.faces == [((0, 1, 2), (0, 0, 0)), ((0, 1, 3), (1, 1, 1))]
    assert np.array_equal(back.objects[2].matrix, transforms.translation(1, 0, 0))


def test_save_to_another_folder_keeps_file_names_working(tmp_path):
    source = tmp_path / "src"
    source.mkdir()
    from tracer.meshio import write_3vn
    write_3vn(TRIANGLE, source / "tri.3vn")
    (source / "scene.sdl").write_text("makePixmap 1 wood.bmp mesh tri.3vn")
    scene = load(source / "scene.sdl")
    target = tmp_path / "elsewhere" / "deeper"
    target.mkdir(parents=True)
    save_sdl(scene, target / "copy.sdl")
    back = load(target / "copy.sdl")
    assert os.path.samefile(back.pixmaps[1].replace("wood.bmp", ""), source)
    assert back.objects[0].mesh_file == os.path.join("..", "..", "src", "tri.3vn")
    assert back.objects[0].mesh.faces == TRIANGLE.faces


def test_failed_save_leaves_nothing_behind(tmp_path):
    path = tmp_path / "s.sdl"
    path.write_text("old contents")
    bad = Scene(objects=[Shape("mesh", mesh=TRIANGLE), shape_at(np.eye(4), material=Material(
        specular_exponent=float("inf")))])
    with pytest.raises(ValueError):
        save_sdl(bad, path)
    assert path.read_text() == "old contents"
    assert [p.name for p in tmp_path.iterdir()] == ["s.sdl"]


def test_failed_scene_write_removes_new_mesh_files(tmp_path, monkeypatch):
    def fail(path, text):
        raise OSError("disk full")

    monkeypatch.setattr(sdl_writer, "write_text_atomic", fail)
    with pytest.raises(OSError):
        save_sdl(Scene(objects=[Shape("mesh", mesh=TRIANGLE)]), tmp_path / "s.sdl")
    assert list(tmp_path.iterdir()) == []


def test_parsed_course_style_file_round_trips(tmp_path):
    text = """
    light -10 10 10 1 1 1  background .2 .2 .3  maxRecursionDepth 4
    def jackPart { push scale .2 .2 1 translate 0 0 -.5 cylinder pop push translate 0 0 .5 sphere pop }
    def jack { use jackPart push rotate 90 1 0 0 use jackPart pop push rotate 90 0 1 0 use jackPart pop }
    diffuse .8 .1 .1 specular .5 .5 .5 specularExponent 20 reflectivity .6
    push translate 1 1 0 rotate 30 1 1 1 use jack pop
    defaultMaterials transparency .7 speedOfLight .8
    difference push scale 2 2 .1 cube pop rotate 15 0 0 1 taperedCylinder .5
    """
    scene = parse_sdl(text)
    once = write_sdl(scene)
    back = parse_sdl(once)
    assert_same_objects(back.objects, scene.objects)
    assert back.settings == scene.settings and back.lights == scene.lights
    assert "! group: jack / jackPart" in once
    assert "e-17" not in once  # no rounding noise in rotation axes
    assert_same_objects(parse_sdl(write_sdl(back)).objects, scene.objects)  # a second round changes nothing


def test_names_survive_write_and_parse():
    names = ["Lamp post", "Ünïcode ✓ crate", None, "two\nlines"]
    scene = Scene(objects=[Shape("sphere", matrix=transforms.translation(i, 0, 0), name=name)
                           for i, name in enumerate(names)])
    scene.objects.append(CSG("union", Shape("cube", name="left one"), Shape("cone")))
    text = write_sdl(scene)
    assert "! name: Lamp post\n" in text
    again = parse_sdl(text)
    assert [s.name for s in again.shapes()] == ["Lamp post", "Ünïcode ✓ crate", None, "two lines", "left one", None]
    assert write_sdl(again) == write_sdl(parse_sdl(write_sdl(again)))  # and SDL -> SDL keeps them


def test_a_file_without_names_is_written_without_name_comments():
    text = write_sdl(parse_sdl("sphere\ncube\n"))
    assert "name:" not in text
    assert [s.name for s in parse_sdl(text).shapes()] == [None, None]
