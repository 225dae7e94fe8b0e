"""SDL export: objects back to SDL exactly (any affine matrix, shear included), other geometry as .3vn
meshes beside the file; import -> export -> import gives the same matrices and materials; atomic writes."""
from __future__ import annotations

import os

import bpy
import numpy as np
import pytest

import tracer
from blender_scripts.addon_env import SCENE_FILES, SCENES, fresh, import_sdl, shape_objects


@pytest.fixture(autouse=True)
def _fresh():
    fresh()


def export(path, **kwargs):
    result = bpy.ops.export_scene.sdl(filepath=str(path), **kwargs)
    assert result == {"FINISHED"}, result
    return tracer.load(str(path), strict=True)


def _structure(obj):
    """A scene object as nested tuples: ('csg', op, left, right) or ('shape', kind, parameters)."""
    if isinstance(obj, tracer.CSG):
        return ("csg", obj.op, _structure(obj.left), _structure(obj.right))
    return ("shape", obj.kind, obj.parameters)


def assert_same_scene(a, b, atol=1e-6):
    assert [_structure(o) for o in a.objects] == [_structure(o) for o in b.objects]
    for sa, sb in zip(a.shapes(), b.shapes()):
        np.testing.assert_allclose(sb.matrix, sa.matrix, rtol=0, atol=atol * max(1.0, np.abs(sa.matrix).max()))
        assert sb.material == sa.material
        if sa.mesh is not None:
            np.testing.assert_allclose(sb.mesh.vertices, sa.mesh.vertices, atol=1e-9)
    assert len(a.lights) == len(b.lights)
    for la, lb in zip(a.lights, b.lights):
        np.testing.assert_allclose(lb.position, la.position, atol=1e-9)
        assert lb.color == la.color
    assert b.settings == a.settings
    if a.camera is not None:
        np.testing.assert_allclose(b.camera.eye, a.camera.eye, atol=1e-9)
        np.testing.assert_allclose(b.camera.look, a.camera.look, atol=1e-9)
        assert b.camera.view_angle == pytest.approx(a.camera.view_angle, abs=1e-9)


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: p.stem)
def test_round_trip_through_blender(path, tmp_path):
    original = tracer.load(str(path), strict=True)
    import_sdl(path)
    before = {o.name: np.array(o.matrix_world) for o in shape_objects()}
    exported = export(tmp_path / "out.sdl")
    assert_same_scene(original, exported)
    # and into Blender again: the same world matrices and materials
    import_sdl(tmp_path / "out.sdl")
    first = [o for o in shape_objects() if o.name in before]
    second = [o for o in shape_objects() if o.name not in before]
    assert len(second) == len(first)
    for a, b in zip(first, second):
        np.testing.assert_allclose(np.array(b.matrix_world), np.array(a.matrix_world), atol=1e-6)
        np.testing.assert_allclose(list(b["sdl_matrix"]), list(a["sdl_matrix"]), atol=1e-6)
        assert b.material_slots[0].material.sdl.diffuse[:] == a.material_slots[0].material.sdl.diffuse[:]


def test_sheared_and_edited_transforms(tmp_path):
    src = tmp_path / "shear.sdl"
    src.write_text("light 1 2 3 1 1 1\n"
                   "push translate 1 2 3 rotate 30 0 0 1 scale 1 3 0.5 rotate 40 1 1 0 cube pop\n"
                   "push rotate 20 0 1 0 scale 2 1 1 rotate 45 0 0 1 taperedCylinder 0.3 pop\n"
                   "push translate 0 5 0 sphere pop\n")
    original = tracer.load(str(src))
    import_sdl(src)
    exported = export(tmp_path / "a.sdl")
    for sa, sb in zip(original.shapes(), exported.shapes()):
        np.testing.assert_allclose(sb.matrix, sa.matrix, atol=1e-9)
    # the user turns the sphere under a parent scaled unevenly, which shears it: export writes what
    # Blender now shows
    sphere = [o for o in shape_objects() if o["sdl_kind"] == "sphere"][0]
    parent = bpy.data.objects.new("shearer", None)
    bpy.context.scene.collection.objects.link(parent)
    parent.scale = (2.0, 1.0, 1.0)
    sphere.parent = parent
    sphere.rotation_euler = (0.0, 0.0, 0.7)
    bpy.context.view_layer.update()
    blender_world = np.array(sphere.matrix_world, dtype=np.float64)
    exported = export(tmp_path / "b.sdl")
    moved = exported.shapes()[2].matrix
    to_sdl = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=float)  # Blender -> SDL
    np.testing.assert_allclose(moved, to_sdl @ blender_world, atol=1e-6)  # generic -> Blender -> SDL world
    assert abs(moved[:3, :3].T @ moved[:3, :3] - np.diag(np.diag(moved[:3, :3].T @ moved[:3, :3]))).max() > 0.1


def test_other_objects_become_3vn_meshes_beside_the_file(tmp_path):
    bpy.ops.mesh.primitive_monkey_add(location=(1, 2, 3))
    monkey = bpy.context.object
    mesh = monkey.data
    folder = tmp_path / "out dir"
    folder.mkdir()
    exported = export(folder / "scene.sdl")
    files = sorted(os.listdir(folder))
    assert files == ["scene.sdl", "scene_Suzanne.3vn"]
    (shape,) = exported.shapes()
    assert shape.kind == "mesh" and shape.mesh_file == "scene_Suzanne.3vn"
    assert len(shape.mesh.vertices) == len(mesh.vertices) and len(shape.mesh.faces) == len(mesh.polygons)
    # the mesh in world space is where Blender has it (SDL axes: Blender (x, y, z) is SDL (x, z, -y))
    world = (shape.matrix @ np.c_[shape.mesh.vertices, np.ones(len(shape.mesh.vertices))].T).T[:, :3]
    blender = np.array([monkey.matrix_world @ v.co for v in mesh.vertices])
    np.testing.assert_allclose(world, blender[:, [0, 2, 1]] * (1, 1, -1), atol=1e-5)


def test_mesh_files_keep_their_names(tmp_path):
    src = tmp_path / "pawn.sdl"
    src.write_text(f"push scale 0.5 0.5 0.5 mesh {os.path.relpath(SCENES / 'meshes' / 'pawn.3vn', tmp_path)} pop\n")
    original = tracer.load(str(src))
    import_sdl(src)
    out = tmp_path / "sub"
    out.mkdir()
    exported = export(out / "again.sdl")
    assert os.listdir(out) == ["again.sdl"]  # the unedited mesh still names pawn.3vn
    assert exported.shapes()[0].mesh_file.endswith("pawn.3vn")
    assert_same_scene(original, exported)


def test_hidden_objects_skipped_and_selection_option(tmp_path):
    import_sdl(SCENES / "shapes.sdl")
    objs = [o for o in shape_objects()]
    objs[0].hide_render = True
    assert len(export(tmp_path / "a.sdl").shapes()) == len(objs) - 1
    for o in bpy.data.objects:
        o.select_set(False)
    objs[1].select_set(True)
    objs[2].select_set(True)
    assert len(export(tmp_path / "b.sdl", use_selection=True).shapes()) == 2


def test_instances_of_a_hidden_object_are_exported_as_rendered(tmp_path):
    """Hair particles of a cone hidden from the render: the render shows the twelve cones, so does the export
    (the cone itself not)."""
    bpy.ops.mesh.primitive_grid_add(x_subdivisions=4, y_subdivisions=4, size=4)
    grid = bpy.context.object
    bpy.ops.mesh.primitive_cone_add(radius1=0.3, depth=0.6, location=(30, 0, 0))
    cone = bpy.context.object
    cone.hide_render = True
    settings = grid.modifiers.new("hair", "PARTICLE_SYSTEM").particle_system.settings
    settings.type, settings.count, settings.render_type, settings.instance_object = "HAIR", 12, "OBJECT", cone
    grid.show_instancer_for_render = False
    shapes = export(tmp_path / "hair.sdl").shapes()
    cones = [s for s in shapes if len(s.mesh.vertices) == len(cone.data.vertices)]
    assert len(cones) == 12
    assert all(np.abs(s.matrix[:3, 3]).max() < 3 for s in cones)  # (on the grid, not where the cone is)


def test_failed_export_writes_nothing(tmp_path, capsys):
    import_sdl(SCENES / "lecture.sdl")
    target = tmp_path / "keep.sdl"
    target.write_text("sphere\n")
    with pytest.raises(RuntimeError, match="Cannot export"):
        bpy.ops.export_scene.sdl(filepath=str(tmp_path / "missing" / "x.sdl"))
    # a mesh is written beside the scene first; when the scene file then cannot be written (its name is
    # taken by a folder), the mesh written for it is removed again and nothing else is left
    bpy.ops.mesh.primitive_monkey_add()
    capsys.readouterr()
    with pytest.raises(RuntimeError, match="Cannot export .*folder .* does not exist"):  # the mesh's folder
        bpy.ops.export_scene.sdl(filepath=str(tmp_path / "missing" / "x.sdl"))
    assert "Traceback" not in capsys.readouterr().err  # a user's mistake: the reason, in Blender's UI only
    (tmp_path / "blocked.sdl").mkdir()
    with pytest.raises(RuntimeError, match="Cannot export"):
        bpy.ops.export_scene.sdl(filepath=str(tmp_path / "blocked.sdl"))
    assert target.read_text() == "sphere\n"
    assert sorted(os.listdir(tmp_path)) == ["blocked.sdl", "keep.sdl"]
    assert os.listdir(tmp_path / "blocked.sdl") == []
    # a NaN transform is skipped with a warning, not written
    obj = shape_objects()[1]
    obj["sdl_matrix"] = [float("nan")] * 16
    obj["sdl_matrix_shown"] = [float(v) for row in obj.matrix_world for v in row]
    scene = export(target)
    assert len(scene.shapes()) == len(shape_objects())  # the NaN one out, the monkey in


def test_an_edited_camera_is_written_as_blender_shows_it(tmp_path):
    import math

    import_sdl(SCENES / "lecture.sdl")
    cam = bpy.context.scene.camera
    cam.location = (4.0, -6.0, 3.0)
    cam.rotation_euler = (math.radians(70.0), 0.0, math.radians(30.0))
    cam.data.lens = 42.0
    bpy.context.view_layer.update()
    exported = export(tmp_path / "cam.sdl").camera
    to_sdl = np.array([[1, 0, 0], [0, 0, 1], [0, -1, 0]], dtype=float)  # Blender -> SDL
    m = np.array(cam.matrix_world, dtype=np.float64)
    np.testing.assert_allclose(exported.eye, to_sdl @ m[:3, 3], atol=1e-6)
    np.testing.assert_allclose(np.subtract(exported.look, exported.eye), to_sdl @ -m[:3, 2], atol=1e-6)
    np.testing.assert_allclose(exported.up, to_sdl @ m[:3, 1], atol=1e-6)
    assert exported.view_angle == pytest.approx(math.degrees(cam.data.angle_y), abs=1e-4)


def test_each_imported_file_keeps_its_own_images(tmp_path):
    """Two files whose ``makePixmap 1`` names different images: exported, each cube names its own image."""
    from blender_scripts.addon_env import two_files_with_their_own_pixmap_1

    paths = two_files_with_their_own_pixmap_1(tmp_path)
    for path in paths:
        import_sdl(path)
    exported = export(tmp_path / "out.sdl")
    images = [os.path.realpath(exported.pixmaps[s.material.texture]) for s in exported.shapes()]
    assert images == [os.path.realpath(p.parent / "tex.png") for p in paths]
    assert tracer.load(str(paths[0])).shapes()[0].material == exported.shapes()[0].material


def test_exported_meshes_come_back_with_their_object_names(tmp_path):
    """A Blender mesh is written to <scene>_<object name>.3vn; the importer names the object after it."""
    fresh()
    bpy.ops.mesh.primitive_monkey_add()
    bpy.context.object.name = "Suzanne"
    bpy.ops.mesh.primitive_cube_add(location=(3, 0, 0))
    bpy.context.object.name = "Crate box"  # (a space cannot be in an SDL file name: written as _)
    out = tmp_path / "zoo.sdl"
    assert bpy.ops.export_scene.sdl(filepath=str(out)) == {"FINISHED"}
    assert sorted(p.name for p in tmp_path.glob("*.3vn")) == ["zoo_Crate_box.3vn", "zoo_Suzanne.3vn"]
    fresh()
    import_sdl(out)
    # the file name loses the space; the ``! name:`` comment keeps it
    assert sorted(o.name for o in bpy.data.objects if o.type == "MESH") == ["Crate box", "Suzanne"]


def test_object_names_survive_export_and_import(tmp_path):
    """Generic shapes, a boolean's operands and a Blender mesh keep their names (spaces, non-ASCII) through
    SDL: the exporter writes a ``! name:`` comment before each shape."""
    src = tmp_path / "shapes.sdl"
    src.write_text("sphere\ntranslate 3 0 0 cone\ntranslate 6 0 0 torus\n"
                   "translate 0 5 0 difference cube scale 0.5 0.5 2 cylinder\n")
    import_sdl(src)
    new_names = iter(["Lamp post", "Ünïcode ✓ sphère", "Bagel 1", "Box", "Hole"])
    for obj in shape_objects():
        obj.name = next(new_names)
    bpy.ops.mesh.primitive_monkey_add(location=(0, -4, 0))
    bpy.context.object.name = "Monkey é"
    names = sorted(o.name for o in bpy.data.objects if o.type == "MESH")
    out = tmp_path / "named.sdl"
    exported = export(out)
    assert sorted(s.name for s in exported.shapes()) == names
    fresh()
    import_sdl(out)
    assert sorted(o.name for o in bpy.data.objects if o.type == "MESH") == names


def test_fresnel_materials_survive_import_and_export(tmp_path):
    """The SDL Material keeps `fresnel` and `fresnelTint` (a copper metal, a dielectric glass): the engine
    traces them and export writes them, as the file had them (they used to come back as `constant`)."""
    source = tmp_path / "fresnel.sdl"
    source.write_text("camera 0 2 8  0 1 0  0 1 0  40\nlight 4 6 4 1 1 1\n"
                      "push diffuse 0.05 0.05 0.05 reflectivity 1 fresnel metal fresnelTint 0.95 0.64 0.54\n"
                      "  translate -1.5 1 0 sphere pop\n"
                      "push diffuse 0 0 0 reflectivity 1 transparency 1 speedOfLight 0.69 fresnel dielectric\n"
                      "  translate 1.5 1 0 sphere pop\n")
    original = tracer.load(str(source), strict=True)
    assert {s.material.fresnel for s in original.shapes()} == {"metal", "dielectric"}
    import_sdl(source)
    from addon import props
    traced = sorted((props.material_to_sdl(o.active_material) for o in shape_objects()), key=lambda m: m.fresnel)
    assert traced == sorted((s.material for s in original.shapes()), key=lambda m: m.fresnel)
    assert_same_scene(original, export(tmp_path / "out.sdl"))
