
import re

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tracer import transforms
from tracer.errors import SDLError
from tracer.model import (CSG, POLYHEDRON_KINDS, SHAPE_KINDS, Camera, Light, Material, MeshData, Settings,
                          Shape, SourceLocation)
from tracer.sdl import parser as sdl_parser
from tracer.sdl.parser import KEYWORDS, load, parse_sdl

TRIANGLE_3VN = "3 1 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 2 0 0 0\n"


def parse(text, **kwargs):
    kwargs.setdefault("file", "scene.sdl")
    return parse_sdl(text, **kwargs)


def error(text, **kwargs):
    with pytest.raises(SDLError) as info:
        parse(text, **kwargs)
    return info.value


def point(matrix, p):
    return transforms.transform_points(matrix, np.array(p, float))


@pytest.fixture
def fake_builtins(monkeypatch):
    """Stand-in meshes for the polyhedra and the teapot, which live in another module."""
    made = {}

    def fake(kind):
        made.setdefault(kind, MeshData(np.eye(3), np.zeros((0, 3)), [((0, 1, 2), ())], origin=f"fake:{kind}"))
        return made[kind]

    monkeypatch.setattr(sdl_parser, "builtin_mesh", fake)
    return made


# --- scene settings ----------------------------------------------------------------------------------------

def test_empty_file_gives_the_defaults():
    scene = parse("")
    assert scene.objects == [] and scene.lights == [] and scene.camera is None
    assert scene.settings == Settings() and scene.pixmaps == {} and scene.warnings == []


def test_settings_and_last_one_wins():
    scene = parse("""
        globalAmbient 0.2 0.3 0.4   background 1 1 1   background .5 .25 0
        minReflectivity 0.25  minTransparency 0.75  maxRecursionDepth 5  maxRecursionDepth 7
    """)
    s = scene.settings
    assert s.global_ambient == (0.2, 0.3, 0.4)
    assert s.background == (0.5, 0.25, 0.0)
    assert s.min_reflectivity == 0.25 and s.min_transparency == 0.75
    assert s.max_recursion_depth == 7 and isinstance(s.max_recursion_depth, int)


def test_lights_are_appended():
    scene = parse("light 1 2 3 1 1 1  light -4 5 6 .5 .5 .5")
    assert scene.lights == [Light((1.0, 2.0, 3.0), (1.0, 1.0, 1.0)), Light((-4.0, 5.0, 6.0), (0.5, 0.5, 0.5))]


def test_camera_extension():
    scene = parse("camera 0 1 10  0 0 0  0 1 0  30")
    assert scene.camera == Camera(eye=(0.0, 1.0, 10.0), look=(0.0, 0.0, 0.0), up=(0.0, 1.0, 0.0), view_angle=30.0)


@pytest.mark.parametrize("args, words", [("1 1 1  1 1 1  0 1 0  45", "same"),
                                         ("0 0 5  0 0 0  0 0 1  45", "up vector"),
                                         ("0 0 5  0 0 0  0 1 0  180", "view angle")])
def test_degenerate_camera_is_an_error(args, words):
    err = error("\n  camera " + args)
    assert (err.line, err.column, err.token) == (2, 3, "camera") and words in err.message


def test_make_pixmap_resolves_against_base_dir(tmp_path):
    scene = parse("makePixmap 3 wood.bmp makePixmap 0 ../img/sky.bmp", base_dir=tmp_path)
    assert scene.pixmaps == {3: str(tmp_path / "wood.bmp"), 0: str(tmp_path / "../img/sky.bmp")}
    assert parse("makePixmap 15 wood.bmp").pixmaps == {15: "wood.bmp"}


@pytest.mark.parametrize("index", ["16", "-1", "2.5"])
def test_make_pixmap_index_out_of_range(index):
    err = error(f"makePixmap {index} a.bmp")
    assert (err.line, err.column, err.token) == (1, 12, index) and "0..15" in str(err)


# --- material ----------------------------------------------------------------------------------------------

def test_every_material_keyword():
    scene = parse("""
        ambient 0.1 0.2 0.3  diffuse 0.4 0.5 0.6  specular 0.7 0.8 0.9  emissive 1 0 1
        specularExponent 50  reflectivity 0.3  transparency 0.6  speedOfLight 0.8
        specularFraction 0.25  surfaceRoughness 0.4  texture -2  parameters 3 1 2.5 3
        sphere""")
    assert scene.objects[0].material == Material(
        ambient=(0.1, 0.2, 0.3), diffuse=(0.4, 0.5, 0.6), specular=(0.7, 0.8, 0.9), emissive=(1.0, 0.0, 1.0),
        specular_exponent=50.0, reflectivity=0.3, transparency=0.6, speed_of_light=0.8,
        specular_fraction=0.25, surface_roughness=0.4, texture=-2, parameters=(1.0, 2.5, 3.0))
    assert isinstance(scene.objects[0].material.texture, int)


def test_each_shape_copies_the_current_material_and_default_materials_resets():
    scene = parse("diffuse 1 0 0 sphere diffuse 0 1 0 cube defaultMaterials square")
    red, green, plain = (s.material for s in scene.objects)
    assert red.diffuse == (1.0, 0.0, 0.0) and green.diffuse == (0.0, 1.0, 0.0)
    assert plain == Material()


def test_parameters_zero_clears_and_ten_is_allowed():
    scene = parse("parameters 10 1 2 3 4 5 6 7 8 9 10 cube parameters 0 cube")
    assert scene.objects[0].material.parameters == tuple(float(i) for i in range(1, 11))
    assert scene.objects[1].material.parameters == ()


def test_parameters_more_than_ten_is_an_error():
    err = error("parameters 11 1 2 3 4 5 6 7 8 9 10 11")
    assert (err.column, err.token) == (12, "11") and "at most 10" in err.message


def test_texture_must_be_whole():
    err = error("texture 1.5")
    assert (err.column, err.token) == (9, "1.5")


def test_texture_number_beyond_the_material_table_is_an_error():
    # A whole number too big for the tables' 32-bit texture column once reached compile as an OverflowError.
    err = error("texture 1e30 sphere")
    assert (err.column, err.token) == (9, "1e30") and "out of range" in err.message
    assert parse("texture -3 sphere").objects[0].material.texture == -3


# --- transforms --------------------------------------------------------------------------------------------

def test_translate_then_scale_gives_t_times_s():
    (sphere,) = parse("translate 2 4 9  scale 1 4 4  sphere").objects
    assert np.array_equal(sphere.matrix, [[1, 0, 0, 2], [0, 4, 0, 4], [0, 0, 4, 9], [0, 0, 0, 1]])
    # The sphere is scaled first, then moved: its top (0,0,1) lands at (2, 4, 13).
    assert np.allclose(point(sphere.matrix, [0, 0, 1]), [2, 4, 13])


def test_rotate_is_right_handed_in_degrees():
    (cube,) = parse("rotate 90 0 0 1 cube").objects
    assert np.allclose(point(cube.matrix, [1, 0, 0]), [0, 1, 0], atol=1e-15)
    (cube,) = parse("rotate 90 0 0 5 cube").objects  # the axis is normalised
    assert np.allclose(point(cube.matrix, [1, 0, 0]), [0, 1, 0], atol=1e-15)
    (cube,) = parse("rotate 120 1 1 1 cube").objects
    assert np.allclose(point(cube.matrix, [1, 0, 0]), [0, 1, 0])


def test_later_statements_act_on_the_shape_first():
    (a, b) = parse("push rotate 90 0 0 1 translate 1 0 0 cube pop  translate 1 0 0 rotate 90 0 0 1 cube").objects
    assert np.allclose(point(a.matrix, [0, 0, 0]), [0, 1, 0])  # moved along x, then turned onto y
    assert np.allclose(point(b.matrix, [0, 0, 0]), [1, 0, 0])  # turned in place, then moved


def test_push_pop_restore_the_transform_but_not_the_material():
    scene = parse("""translate 1 0 0 push scale 2 2 2 diffuse 1 0 0 sphere pop cube
                     push push translate 0 5 0 pop identityAffine square pop plane""")
    sphere, cube, square, plane = scene.objects
    assert np.array_equal(sphere.matrix, transforms.translation(1, 0, 0) @ transforms.scaling(2, 2, 2))
    assert np.array_equal(cube.matrix, transforms.translation(1, 0, 0))
    assert cube.material.diffuse == (1.0, 0.0, 0.0)  # pop does not restore the material
    assert np.array_equal(square.matrix, np.eye(4))  # identityAffine resets the top only ...
    assert np.array_equal(plane.matrix, transforms.translation(1, 0, 0))  # ... the entry below survives


def test_unbalanced_push_at_the_end_is_fine():
    scene = parse("push push sphere")
    assert len(scene.objects) == 1 and scene.warnings == []


def test_each_shape_has_its_own_matrix_copy():
    scene = parse("sphere translate 1 0 0 sphere")
    assert np.array_equal(scene.objects[0].matrix, np.eye(4))
    scene.objects[1].matrix[0, 0] = 9
    assert scene.objects[0].matrix[0, 0] == 1


# --- shapes ------------------------------------------------------------------------------------------------

def test_analytic_shapes(fake_builtins):
    scene = parse("sphere cube square plane taperedCylinder 0.25 cylinder cone torus")
    kinds = [s.kind for s in scene.objects]
    assert kinds == ["sphere", "cube", "square", "plane", "taperedCylinder", "cylinder", "cone", "torus"]
    tapered, cylinder, cone = scene.objects[4:7]
    assert tapered.parameters == (0.25,) and cylinder.parameters == cone.parameters == ()
    assert all(s.mesh is None for s in scene.objects)


def test_polyhedra_and_teapot_get_built_in_meshes(fake_builtins):
    text = " ".join(POLYHEDRON_KINDS) + " teapot icosahedron"
    scene = parse(text)
    assert [s.kind for s in scene.objects] == list(POLYHEDRON_KINDS) + ["teapot", "icosahedron"]
    for shape in scene.objects:
        assert shape.mesh is fake_builtins[shape.kind]
        assert shape.mesh_file is None


def test_real_built_in_meshes():
    scene = parse(" ".join(POLYHEDRON_KINDS) + " teapot")
    for shape in scene.objects:
        assert isinstance(shape.mesh, MeshData) and len(shape.mesh.faces) > 0


def test_every_shape_keyword_is_covered():
    assert set(SHAPE_KINDS) <= KEYWORDS


def test_mesh_file_relative_to_base_dir(tmp_path):
    (tmp_path / "meshes").mkdir()
    (tmp_path / "meshes" / "tri.3vn").write_text(TRIANGLE_3VN)
    scene = parse("mesh meshes/tri.3vn translate 1 0 0 mesh meshes/tri.3vn", base_dir=tmp_path)
    first, second = scene.objects
    assert first.kind == "mesh" and first.mesh_file == "meshes/tri.3vn"
    assert first.mesh.faces == [((0, 1, 2), (0, 0, 0))]
    assert second.mesh is first.mesh  # read once


def test_mesh_file_relative_to_cwd_without_base_dir(tmp_path, monkeypatch):
    (tmp_path / "tri.3vn").write_text(TRIANGLE_3VN)
    monkeypatch.chdir(tmp_path)
    (shape,) = parse("mesh tri.3vn").objects
    assert shape.mesh.vertices.shape == (3, 3)


def test_shape_source_locations():
    scene = parse("sphere\n  translate 1 2 3\n    cube", file="s.sdl")
    assert scene.objects[0].source == SourceLocation("s.sdl", 1, 1)
    assert scene.objects[1].source == SourceLocation("s.sdl", 3, 5)


# --- CSG ---------------------------------------------------------------------------------------------------

def test_csg_prefix_form_with_statements_before_children():
    scene = parse("""
        diffuse 1 0 0
        difference
            sphere
            translate 0 0 1 scale .5 .5 .5 diffuse 0 0 1 cylinder
        cube""")
    diff, cube = scene.objects
    assert isinstance(diff, CSG) and diff.op == "difference"
    assert diff.source == SourceLocation("scene.sdl", 3, 9)
    assert diff.left.kind == "sphere" and diff.left.material.diffuse == (1.0, 0.0, 0.0)
    assert diff.right.kind == "cylinder" and diff.right.material.diffuse == (0.0, 0.0, 1.0)
    assert np.array_equal(diff.right.matrix, transforms.translation(0, 0, 1) @ transforms.scaling(.5, .5, .5))
    # The state simply carries on past the boolean.
    assert cube.material.diffuse == (0.0, 0.0, 1.0)
    assert np.array_equal(cube.matrix, diff.right.matrix)


def test_csg_nesting():
    scene = parse("union intersection sphere cube difference cone union torus square plane")
    (outer, plane) = scene.objects
    assert outer.op == "union"
    assert outer.left.op == "intersection" and [s.kind for s in outer.left.leaves()] == ["sphere", "cube"]
    assert outer.right.op == "difference" and outer.right.left.kind == "cone"
    assert outer.right.right.op == "union" and [s.kind for s in outer.right.right.leaves()] == ["torus", "square"]
    assert plane.kind == "plane"


def test_deep_csg_nesting_does_not_recurse():
    depth = 5000
    scene = parse("union " * depth + "sphere " + "cube " * depth)
    node, count = scene.objects[0], 0
    while isinstance(node, CSG):
        assert node.right.kind == "cube"
        node, count = node.left, count + 1
    assert count == depth and node.kind == "sphere"


def test_csg_operand_from_a_macro():
    scene = parse("def hole { push scale .5 .5 2 cylinder pop } difference cube use hole")
    (diff,) = scene.objects
    assert diff.right.kind == "cylinder" and diff.right.groups == ("hole",) and diff.groups == ()


def test_csg_missing_operand():
    err = error("sphere\nunion\n  cube\n")
    assert (err.file, err.line, err.column) == ("scene.sdl", 2, 1)
    assert "'union' needs two objects, found 1" in err.message
    err = error("intersection")
    assert "found 0" in err.message


# --- macros ------------------------------------------------------------------------------------------------

def test_def_and_use_splice_tokens():
    scene = parse("def red { diffuse 1 0 0 } def ball { use red sphere } use ball translate 2 0 0 use ball")
    a, b = scene.objects
    assert a.material.diffuse == (1.0, 0.0, 0.0) and a.groups == ("ball",)
    assert np.array_equal(b.matrix, transforms.translation(2, 0, 0))


def test_def_alone_makes_nothing():
    assert parse("def thing { sphere cube }").objects == []


def test_macro_bodies_nest_braces():
    scene = parse("def outer { def inner { cube } sphere use inner } use outer")
    assert [s.kind for s in scene.objects] == ["sphere", "cube"]
    assert scene.objects[1].groups == ("outer", "inner")


def test_use_splices_even_partial_statements():
    scene = parse("def move { translate 1 } use move 2 3 sphere")
    assert np.array_equal(scene.objects[0].matrix, transforms.translation(1, 2, 3))
    assert scene.objects[0].groups == ()  # the sphere keyword came from the file, not the macro


def test_groups_are_outermost_first_and_end_with_the_macro():
    scene = parse("""
        def leg { push scale .1 .1 1 cube pop }
        def table { use leg translate 1 0 0 use leg cube }
        use table sphere""")
    leg1, leg2, top, sphere = scene.objects
    assert leg1.groups == leg2.groups == ("table", "leg")
    assert top.groups == ("table",) and sphere.groups == ()
    # The source of a spliced shape is its place in the macro body.
    assert leg1.source.line == 2 and leg1.source.column == 38


def test_macro_as_last_token_of_a_macro_keeps_both_groups():
    scene = parse("def a { sphere } def b { cube use a } use b")
    assert [s.groups for s in scene.objects] == [("b",), ("b", "a")]


def test_direct_recursion_is_an_error():
    err = error("def a {\n sphere use a\n}\nuse a")
    assert (err.line, err.column, err.token) == (2, 13, "a")
    assert "a -> a" in err.message


def test_indirect_recursion_names_the_chain():
    err = error("def a { use b } def b { cube use c } def c { use a } use a")
    assert "a -> b -> c -> a" in err.message and err.token == "a"


def test_using_a_macro_twice_in_a_row_is_not_recursion():
    scene = parse("def a { sphere } def b { use a use a } use b use b")
    assert len(scene.objects) == 4


def test_exponential_macros_are_stopped(monkeypatch):
    monkeypatch.setattr(sdl_parser, "MAX_SPLICED_TOKENS", 5000)  # small, so that use m8 tests "within it"
    text = "def m0 { sphere } " + " ".join(f"def m{i} {{ use m{i - 1} use m{i - 1} }}" for i in range(1, 40))
    assert len(parse(text + " use m8").objects) == 2 ** 8  # well within the budget
    err = error(text + " use m39")
    assert "more than the 5,000" in err.message
    assert "m39 -> m38 -> m37 -> ... 34 more ... -> m2 -> m1 -> m0" in err.message  # where the tokens come from


def test_redefinition_is_an_error():
    err = error("def a { sphere }\ndef   a { cube }")
    assert (err.line, err.column, err.token) == (2, 7, "a") and "already defined" in err.message


def test_undefined_use_suggests_a_close_name():
    err = error("def table { cube }\nuse tabel")
    assert (err.line, err.column, err.token) == (2, 5, "tabel") and "'table'" in err.message


def test_end_of_file_inside_a_def_body():
    err = error("sphere\ndef a { cube { }")
    assert (err.line, err.column, err.token) == (2, 1, None)
    assert "def a" in err.message and err.expected == "'}'"


def test_def_needs_a_brace():
    err = error("def a sphere }")
    assert (err.column, err.token) == (7, "sphere")


# --- errors: file, line, column, token ---------------------------------------------------------------------

def test_unknown_keyword_suggests_the_closest():
    err = error("sphere\n  sphre")
    assert (err.file, err.line, err.column, err.token) == ("scene.sdl", 2, 3, "sphre")
    assert "did you mean 'sphere'" in err.message
    assert "did you mean 'taperedCylinder'" in error("taperedcylinder 1").message  # case matters
    assert "did you mean" not in error("xyzzy").message


def test_bare_macro_name_hints_at_use():
    assert "use leg" in error("def leg { cube } leg").message


def test_bad_number():
    err = error("translate 1 x 3")
    assert (err.line, err.column, err.token) == (1, 13, "x")
    assert str(err) == ("scene.sdl:1:13: expected a number after 'translate' "
                        "(found 'x', expected 'translate dx dy dz')")


def test_missing_number_finds_the_next_keyword():
    err = error("translate 1 2\nsphere")
    assert (err.line, err.column, err.token) == (2, 1, "sphere")


@pytest.mark.parametrize("word", ["nan", "inf", "-inf", "1e999", "NaN"])
def test_nan_and_inf_are_not_numbers(word):
    err = error(f"scale 1 {word} 1")
    assert (err.column, err.token) == (9, word)


def test_end_of_file_inside_a_statement():
    err = error("sphere\nlight 1 2 3 1")
    assert (err.line, err.column, err.token) == (2, 1, None) and "end of file" in err.message
    assert "light x y z r g b" in err.expected


def test_unbalanced_close_brace():
    err = error("sphere }")
    assert (err.column, err.token) == (8, "}")


def test_open_brace_outside_def():
    err = error("{ sphere }")
    assert (err.column, err.token) == (1, "{")


def test_stray_number():
    err = error("translate 1 2 3 4 sphere")
    assert (err.column, err.token) == (17, "4")


def test_pop_on_empty_stack():
    err = error("push pop\npop")
    assert (err.line, err.column, err.token) == (2, 1, "pop")


def test_zero_rotation_axis():
    err = error("rotate 45 0 0 0 sphere")
    assert (err.column, err.token) == (11, "0 0 0") and "axis" in err.message


def test_singular_transform_only_matters_for_a_shape():
    assert parse("push scale 0 1 1 pop sphere").objects[0].kind == "sphere"
    err = error("scale 1 0 1\n cube")
    assert (err.line, err.column, err.token) == (2, 2, "cube") and "singular" in err.message


def test_an_overflowing_transform_is_named_as_such():
    err = error("scale 1e200 1 1 scale 1e200 1 1\nsphere")  # the product is inf: no inverse
    assert (err.line, err.token) == (2, "sphere") and "overflows" in err.message and "scale of 0" not in err.message


def test_missing_mesh_file(tmp_path):
    err = error("mesh\n  gone.3vn", base_dir=tmp_path)
    assert (err.line, err.column, err.token) == (2, 3, "gone.3vn") and "not found" in err.message


def test_bad_mesh_content_names_both_files(tmp_path):
    (tmp_path / "bad.3vn").write_text("3 1 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 1 9 0 0 0\n")
    err = error("mesh bad.3vn", base_dir=tmp_path)
    assert (err.line, err.column) == (1, 6)
    assert "bad.3vn:6:" in err.message and "out of range" in err.message


def test_max_recursion_depth_must_be_whole():
    err = error("maxRecursionDepth -1")
    assert err.token == "-1"


# --- lenient mode ------------------------------------------------------------------------------------------

MESSY = """! a typical course file
light 10 10 10 1 1 1
def pawn { push scale .3 .3 .3 mesh pawn.3vn pop }
diffuse 1 0 0
sphre
translate 1 0 0 sphere
use pawn
pop
cube
"""


def test_lenient_mode_warns_once_per_problem_and_reads_on(tmp_path):
    scene = parse(MESSY, base_dir=tmp_path, strict=False)
    assert len(scene.warnings) == 3
    typo, missing, pop = scene.warnings
    assert typo.startswith("scene.sdl:5:1: unknown keyword, did you mean 'sphere'?")
    assert missing.startswith("scene.sdl:3:37: mesh file not found")
    assert pop.startswith("scene.sdl:8:1: pop without a matching push")
    assert [s.kind for s in scene.objects] == ["sphere", "cube"]
    assert np.array_equal(scene.objects[1].matrix, transforms.translation(1, 0, 0))  # the extra pop ignored
    assert scene.objects[1].material.diffuse == (1.0, 0.0, 0.0)
    assert len(scene.lights) == 1


def test_lenient_warnings_match_strict_errors(tmp_path):
    scene = parse(MESSY, base_dir=tmp_path, strict=False)
    with pytest.raises(SDLError) as info:
        parse(MESSY, base_dir=tmp_path)
    assert str(info.value) == scene.warnings[0]


def test_lenient_bad_statement_gives_one_warning_and_skips_its_leftovers():
    scene = parse("translate 1 x 3 4 sphere", strict=False)
    assert len(scene.warnings) == 1
    assert np.array_equal(scene.objects[0].matrix, np.eye(4))  # the broken translate is dropped


def test_lenient_typo_inside_a_macro_is_reported_once():
    scene = parse("def m { sphre cube } use m use m", strict=False)
    assert len(scene.warnings) == 1 and len(scene.objects) == 2


def test_lenient_csg_missing_second_operand_degrades_to_first():
    scene = parse("diffuse 1 0 0 union sphere", strict=False)
    assert len(scene.warnings) == 1 and "needs two objects" in scene.warnings[0]
    (sphere,) = scene.objects
    assert isinstance(sphere, Shape) and sphere.kind == "sphere"


def test_lenient_nested_csg_missing_operands():
    # The cut-short difference degrades to its sphere, which completes the union.
    scene = parse("union cube difference sphere", strict=False)
    assert len(scene.warnings) == 1 and "'difference'" in scene.warnings[0]
    (union,) = scene.objects
    assert union.op == "union" and union.left.kind == "cube" and union.right.kind == "sphere"
    # Here neither boolean gets two operands: two warnings, innermost first, and the sphere is left.
    scene = parse("union difference sphere", strict=False)
    assert ["'difference'" in scene.warnings[0], "'union'" in scene.warnings[1]] == [True, True]
    assert [o.kind for o in scene.objects] == ["sphere"]


def test_lenient_dropped_operand_does_not_steal_the_next_object(tmp_path):
    scene = parse("union mesh gone.3vn sphere cube", base_dir=tmp_path, strict=False)
    assert len(scene.warnings) == 1
    assert [o.kind for o in scene.objects] == ["sphere", "cube"]


def test_lenient_parameters_over_ten_keeps_the_first_ten():
    scene = parse("parameters 12 1 2 3 4 5 6 7 8 9 10 11 12 sphere", strict=False)
    assert len(scene.warnings) == 1
    assert scene.objects[0].material.parameters == tuple(float(i) for i in range(1, 11))


def test_lenient_singular_shape_is_dropped():
    scene = parse("scale 0 0 0 sphere identityAffine cube", strict=False)
    assert len(scene.warnings) == 1 and [s.kind for s in scene.objects] == ["cube"]


def test_lenient_recursion_and_undefined_macro():
    scene = parse("def a { sphere use a } use a use b cube", strict=False)
    assert len(scene.warnings) == 2
    assert [s.kind for s in scene.objects] == ["sphere", "cube"]


def test_lenient_unterminated_def_and_stray_brace():
    scene = parse("} sphere def a { cube", strict=False)
    assert len(scene.warnings) == 2 and [s.kind for s in scene.objects] == ["sphere"]


keyword_or_junk = st.one_of(st.sampled_from(sorted(KEYWORDS)), st.sampled_from(["{", "}", "1", "-2.5", "0", "x",
                                                                                   "nan", "a", "b", "9"]))


@settings(max_examples=300, deadline=None)
@given(st.lists(keyword_or_junk, max_size=40))
def test_random_token_soup_never_crashes(words):
    text = " ".join(words)
    scene = parse(text, strict=False)  # lenient: never raises
    for shape in scene.shapes():
        assert shape.kind in SHAPE_KINDS
    try:
        parse(text)
    except SDLError:
        pass  # strict: only ever an SDLError


# --- load --------------------------------------------------------------------------------------------------

def test_load_reads_relative_to_the_file(tmp_path):
    (tmp_path / "tri.3vn").write_text(TRIANGLE_3VN)
    path = tmp_path / "scene.sdl"
    path.write_text("\ufeffmakePixmap 1 img.bmp\nmesh tri.3vn\n")
    scene = load(path)
    assert scene.source == path
    assert scene.pixmaps == {1: str(tmp_path / "img.bmp")}
    assert scene.objects[0].mesh_file == "tri.3vn"
    assert scene.objects[0].source == SourceLocation(str(path), 2, 1)


def test_load_names_the_file_in_errors(tmp_path):
    path = tmp_path / "bad.sdl"
    path.write_text("sphere\n\n  cube 3\n")
    with pytest.raises(SDLError) as info:
        load(path)
    assert str(info.value).startswith(f"{path}:3:8:")
    scene = load(path, strict=False)
    assert len(scene.warnings) == 1 and len(scene.objects) == 2


def test_load_missing_file(tmp_path):
    with pytest.raises(SDLError) as info:
        load(tmp_path / "nothing.sdl")
    assert "nothing.sdl" in str(info.value)


def test_name_comments_name_the_next_shape():
    scene = parse_sdl("! name: Lamp post\n"
                      "push translate 1 2 3 sphere pop\n"
                      "cube ! name: Ünïcode ✓ crate  \n"
                      "scale 2 2 2 difference cone\n"
                      "! not a name comment\n"
                      "torus\n")
    shapes = list(scene.shapes())
    assert [(s.kind, s.name) for s in shapes] == [("sphere", "Lamp post"), ("cube", None),
                                                  ("cone", "Ünïcode ✓ crate"), ("torus", None)]


def test_a_name_comment_stops_at_def_and_use():
    """A name before 'use' or 'def' names no shape there or later; one inside a def body names its shape
    wherever the macro is used."""
    scene = parse_sdl("def lamp { ! name: bulb\n sphere }\n"
                      "! name: lost\n use lamp\n"
                      "! name: lost too\n def other { cube }\n"
                      "cone use lamp\n")
    assert [(s.kind, s.name) for s in scene.shapes()] == [("sphere", "bulb"), ("cone", None), ("sphere", "bulb")]


def test_without_name_comments_shapes_have_no_names():
    scene = parse_sdl("! group: x\nsphere\n!name:\ncube\n")
    assert [s.name for s in scene.shapes()] == [None, None]


# --- big files: read a block of lines at a time ----------------------------------------------------------
# The lexer splits the text a block of lines at a time (lexer.BLOCK_CHARS) and the reader finds a token's
# line and column only when it records or reports it.  These check that places, names and messages deep in
# a file, and across block boundaries, are what they are in a small one.

def _sphere_lines(count: int) -> list[str]:
    return [f"diffuse 0.{k % 10}5 0.5 0.5 push translate {k} 0.25 -{k}.5 scale 0.5 0.5 0.5 sphere pop"
            for k in range(count)]


def test_places_and_names_deep_in_a_big_file():
    lines = _sphere_lines(30_000)  # about 2.3 MB: several blocks
    column = {k: lines[k].index("sphere") + 1 for k in (123, 20_000, 29_999)}
    lines[20_000] = "! name: Far away\n" + "\t  " + lines[20_000]  # indented: the column is counted, not assumed
    lines[29_998] = lines[29_998] + "   ! name: the last one"  # names the sphere on the next line
    scene = parse("\n".join(lines))
    spheres = scene.objects
    assert len(spheres) == 30_000
    assert spheres[123].source == SourceLocation("scene.sdl", 124, column[123])
    assert spheres[20_000].source == SourceLocation("scene.sdl", 20_002, column[20_000] + 3)
    assert spheres[29_999].source == SourceLocation("scene.sdl", 30_001, column[29_999])
    assert spheres[20_000].name == "Far away" and spheres[29_999].name == "the last one"
    assert [s.name for s in spheres].count(None) == 29_998
    assert spheres[29_999].material.diffuse == (0.95, 0.5, 0.5)
    assert np.array_equal(spheres[29_999].matrix, transforms.translation(29_999, 0.25, -29_999.5)
                          @ transforms.scaling(0.5, 0.5, 0.5))


@pytest.mark.parametrize("line, column, message", [
    ("translate 1 x 3 sphere", 13, "expected a number after 'translate' (found 'x', expected 'translate dx dy dz')"),
    ("  push pop pop", 12, "pop without a matching push (found 'pop')"),
    ("push scale 1 0 1 cube pop", 18, "singular transform for 'cube' (a scale of 0?) (found 'cube', expected a transform "
                             "with an inverse)"),
    ("use nothing", 5, "undefined macro (found 'nothing', expected a name given by an earlier def)"),
])
def test_errors_deep_in_a_big_file_name_their_line_and_column(line, column, message):
    lines = _sphere_lines(40_000)
    lines[33_333] = line
    with pytest.raises(SDLError) as info:
        parse("\n".join(lines))
    assert str(info.value) == f"scene.sdl:33334:{column}: {message}"
    scene = parse("\n".join(lines), strict=False)
    assert scene.warnings == [f"scene.sdl:33334:{column}: {message}"]


def test_a_macro_defined_early_places_its_shapes_at_its_body_when_used_late():
    lines = ["def lamp {", "  ! name: bulb", "  push scale 0.2 0.2 0.2 sphere pop", "  cube 7", "}"]
    lines += _sphere_lines(30_000) + ["use lamp"]
    scene = parse("\n".join(lines), strict=False)
    bulb, cube = scene.objects[-2:]
    assert (bulb.kind, bulb.name, bulb.groups) == ("sphere", "bulb", ("lamp",))
    assert bulb.source == SourceLocation("scene.sdl", 3, lines[2].index("sphere") + 1)
    assert cube.kind == "cube" and cube.source == SourceLocation("scene.sdl", 4, 3)
    assert scene.warnings == ["scene.sdl:4:8: a number where a keyword belongs (too many numbers?) "
                              "(found '7', expected a keyword)"]


def _outcome(text: str, strict: bool):
    """Everything a reader gives for ``text``: its error, or its objects (with places, names, groups,
    materials and matrices), lights, camera, settings and warnings."""
    try:
        scene = parse(text, strict=strict)
    except SDLError as error:
        return str(error)
    objects = []
    for obj in scene.objects:
        todo = [obj]
        while todo:
            node = todo.pop()
            if isinstance(node, CSG):
                objects.append((node.op, node.groups, node.source))
                todo += [node.right, node.left]
            else:
                objects.append((node.kind, node.matrix.tolist(), node.material, node.parameters, node.groups,
                                node.source, node.name))
    return objects, scene.lights, scene.camera, scene.settings, scene.warnings


statement_or_junk = st.one_of(
    st.sampled_from(sorted(KEYWORDS)),
    st.sampled_from(["{", "}", "1", "-2.5", "0", "x", "a", "b", "9", "\n", "\n", "\n", "\r\n", "\t", "! c\n",
                     "! name: n1\n", "! name: n 2\n", "def a {", "def b { sphere", "use a", "use b", "push",
                     "translate 1 2 3", "scale 2 2 2", "rotate 30 0 1 0", "diffuse 0.5 0.5 0", "sphere", "cube",
                     "a{b", "}{"]))


@settings(max_examples=200, deadline=None)
@given(st.lists(statement_or_junk, max_size=60), st.sampled_from([" ", "  ", "\n"]))
def test_the_block_size_changes_nothing(words, separator):
    """A block of one line at a time gives what one block for the whole text gives: the same objects,
    places, names, errors and warnings."""
    from tracer.sdl import lexer
    text = separator.join(words)
    whole = [_outcome(text, strict) for strict in (True, False)]
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(lexer, "BLOCK_CHARS", 1)
        patch.setattr(lexer, "_FAR", 1)  # and every token's place from its line's token starts
        assert [_outcome(text, strict) for strict in (True, False)] == whole


def test_a_whole_scene_on_one_line():
    """Places far along one long line, with uneven spaces: found from where each token starts."""
    words = []
    for k in range(3_000):
        words += ["push", "translate", str(k), "0", "0", "sphere", "pop"] + (["union"] if k % 7 == 0 else [])
    separators = [" ", "  ", "\t", " \r "]
    line = "".join(word + separators[k % 4] for k, word in enumerate(words)) + "sphere ! the end"
    scene = parse(line)
    starts = [m.start() + 1 for m, word in zip(re.finditer(r"\S+", line), words + ["sphere"])]
    placed = {obj.source.column: obj for obj in scene.shapes()}
    expected = {column for column, word in zip(starts, words + ["sphere"]) if word == "sphere"}
    assert set(placed) == expected and len(expected) == 3_001
    assert all(obj.source.line == 1 for obj in scene.shapes())
    unions = [obj for obj in scene.objects if isinstance(obj, CSG)]
    assert {u.source.column for u in unions} == {c for c, w in zip(starts, words) if w == "union"}
