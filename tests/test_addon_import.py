"""SDL import: every shape an object on a shared generic mesh at its exact SDL transform, materials,
lights, camera, world, CSG as Boolean modifiers, def/use groups, axis option, errors."""
from __future__ import annotations

import math
import os
import shutil
from types import SimpleNamespace

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view
from mathutils import Vector

import tracer
from addon import importer, meshes, props
from addon.pure import convert
from blender_scripts.addon_env import (SCENE_FILES, SCENES, effective_matrix, fresh, import_sdl, shape_objects,
                                       to_blender, world)


@pytest.fixture(autouse=True)
def _fresh():
    fresh()


def _counts() -> dict:
    return {name: len(getattr(bpy.data, name)) for name in
            ("objects", "meshes", "materials", "collections", "lights", "cameras", "worlds")}


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: p.stem)
def test_every_shape_at_its_sdl_transform(path):
    scene = tracer.load(str(path), strict=True)
    import_sdl(path)
    shapes, objs = scene.shapes(), shape_objects()
    assert [o["sdl_kind"] for o in objs] == [s.kind for s in shapes]
    for shape, obj in zip(shapes, objs):
        expected = to_blender(shape.matrix)
        # exact in the kept float64 values, and to float32 in what Blender shows
        np.testing.assert_allclose(np.array(list(obj["sdl_matrix"])).reshape(4, 4), expected, rtol=0, atol=1e-12)
        np.testing.assert_allclose(effective_matrix(obj), expected, rtol=0, atol=1e-5 * max(1, abs(expected).max()))
        material = props.material_to_sdl(obj.material_slots[0].material)
        assert material == shape.material  # every SDL value exactly (float64 kept beside the float32 props)


def test_meshes_shared_per_kind_and_parameter():
    import_sdl(SCENES / "shapes.sdl")
    import_sdl(SCENES / "lecture.sdl")  # a second file reuses the same mesh data
    by_kind: dict = {}
    for obj in shape_objects():
        key = (obj["sdl_kind"], obj.get("sdl_param"))
        by_kind.setdefault(key, set()).add(obj.data.name)
    assert all(len(names) == 1 for names in by_kind.values()), by_kind
    assert len(by_kind[("cylinder", None)]) == 1 and len(by_kind[("cone", None)]) == 1
    tapered = [o for o in shape_objects() if o["sdl_kind"] == "taperedCylinder"][0]
    assert tapered.data.name == "SDL taperedCylinder 0.5"
    # a generic sphere's mesh lies on the unit sphere, a cube's corners at +-1
    sphere = [o for o in shape_objects() if o["sdl_kind"] == "sphere"][0].data
    radii = np.array([v.co.length for v in sphere.vertices])
    np.testing.assert_allclose(radii, 1.0, atol=1e-6)
    assert len(sphere.polygons) >= 1024  # fine enough for silhouettes (see test_addon_overlay)


def test_materials_lights_camera_world():
    scene = tracer.load(str(SCENES / "lecture.sdl"))
    import_sdl(SCENES / "lecture.sdl")
    # a Principled BSDF close to the SDL material
    big = [o for o in shape_objects() if o["sdl_kind"] == "sphere"][-1]
    mat = big.material_slots[0].material
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    np.testing.assert_allclose(tuple(bsdf.inputs["Base Color"].default_value)[:3], (0.85, 0.2, 0.15), atol=1e-6)
    assert mat.sdl.use_sdl and mat.sdl.specular_exponent == pytest.approx(80)
    # lights: point lights at the SDL positions, colours exact
    lights = sorted((o for o in bpy.data.objects if o.type == "LIGHT"), key=lambda o: o["sdl_order"])
    assert [o.data.type for o in lights] == ["POINT", "POINT"]
    for light, obj in zip(scene.lights, lights):
        np.testing.assert_allclose(obj.matrix_world.translation, to_blender(np.eye(4))[:3, :3] @ light.position,
                                   atol=1e-5)
        assert props.light_color(obj.data) == light.color
    # the file's camera is the scene camera: the look-at point projects to the frame's centre, up is up
    cam = bpy.context.scene.camera
    assert cam is not None and cam.data.sensor_fit == "VERTICAL"
    assert math.degrees(cam.data.angle_y) == pytest.approx(38, abs=1e-4)
    look = Vector(to_blender(np.eye(4))[:3, :3] @ scene.camera.look)
    centre = world_to_camera_view(bpy.context.scene, cam, look)
    assert centre.x == pytest.approx(0.5, abs=1e-6) and centre.y == pytest.approx(0.5, abs=1e-6)
    np.testing.assert_allclose(world(cam)[:3, 3], to_blender(np.eye(4))[:3, :3] @ scene.camera.eye, atol=1e-5)
    # background and global ambient on the world
    w = bpy.context.scene.world
    assert props.world_settings(w, 3).background == scene.settings.background
    assert props.world_settings(w, 3).global_ambient == scene.settings.global_ambient
    np.testing.assert_allclose(tuple(w.color), scene.settings.background, atol=1e-6)


def test_framing_camera_when_the_file_has_none(tmp_path):
    path = tmp_path / "nocam.sdl"
    path.write_text("light 5 5 5 1 1 1\npush translate 10 0 0 sphere pop\npush translate 10 3 0 cube pop\n")
    import_sdl(path)
    cam = bpy.context.scene.camera
    assert cam is not None and cam["sdl_framed"]
    for obj in shape_objects():  # both objects in the frame
        p = world_to_camera_view(bpy.context.scene, cam, obj.matrix_world.translation)
        assert 0.05 < p.x < 0.95 and 0.05 < p.y < 0.95 and p.z > 0


def test_default_axes_are_upright_and_the_option_changes_them():
    import_sdl(SCENES / "lecture.sdl")
    pillar = [o for o in shape_objects() if o["sdl_kind"] == "cylinder"][0]
    # SDL's up (y) is Blender's up (z): the pillar, 2.5 units tall along SDL y, stands along Blender z
    np.testing.assert_allclose(world(pillar)[:3, 2], (0, 0, 2.5), atol=1e-6)
    fresh()
    import_sdl(SCENES / "lecture.sdl", axis_forward="Y", axis_up="Z")  # no conversion
    pillar = [o for o in shape_objects() if o["sdl_kind"] == "cylinder"][0]
    np.testing.assert_allclose(world(pillar)[:3, 2], (0, 2.5, 0), atol=1e-6)


def test_csg_as_boolean_modifiers():
    import_sdl(SCENES / "csg.sdl")
    with_booleans = [o for o in shape_objects() if o.modifiers]
    ops = sorted(m.operation for o in with_booleans for m in o.modifiers)
    assert ops == ["DIFFERENCE", "DIFFERENCE", "INTERSECT", "UNION"]
    for obj in with_booleans:
        for m in obj.modifiers:
            assert m.type == "BOOLEAN" and m.object is not None and m.object.hide_render
    # the preview shows the result: the union's evaluated mesh has more faces than the sphere alone
    union = next(o for o in with_booleans if o.modifiers[0].operation == "UNION")
    evaluated = union.evaluated_get(bpy.context.evaluated_depsgraph_get())
    assert len(evaluated.data.polygons) != len(union.data.polygons)


def test_def_use_parts_grouped_by_name():
    import_sdl(SCENES / "jack.sdl")
    names = {c.name for c in bpy.data.collections}
    assert {"jack", "arm"} <= names
    arm = bpy.data.collections["arm"]
    assert all(o["sdl_kind"] in ("cylinder", "sphere") for o in arm.all_objects)
    assert len(bpy.data.collections["jack"].all_objects) >= 9


def test_sheared_transform_kept(tmp_path):
    path = tmp_path / "shear.sdl"
    path.write_text("push translate 1 2 3 rotate 30 0 0 1 scale 1 3 0.5 rotate 40 1 1 0 cube pop\n"
                    "push rotate 20 0 1 0 scale 2 1 1 rotate 45 0 0 1 taperedCylinder 0.3 pop\n")
    scene = tracer.load(str(path))
    import_sdl(path)
    for shape, obj in zip(scene.shapes(), shape_objects()):
        np.testing.assert_allclose(effective_matrix(obj), to_blender(shape.matrix), atol=2e-6)


def test_one_undo_step_and_ui_reports():
    op = bpy.types.IMPORT_SCENE_OT_sdl
    assert "UNDO" in op.bl_options  # one operator call is one undo step (no window here to undo in)
    assert hasattr(bpy.types, "IO_FH_sdl") and bpy.types.IO_FH_sdl.bl_file_extensions == ".sdl;.dat"


def test_unreadable_file_leaves_the_scene_untouched(tmp_path):
    import_sdl(SCENES / "csg.sdl")
    before, camera, world_before = _counts(), bpy.context.scene.camera, bpy.context.scene.world
    bad = tmp_path / "bad.sdl"
    bad.write_text("sphere\nlight 1 2 3 1 1 1\ncube\nmesh missing.3vn\ntranslate 1 2\n")
    with pytest.raises(RuntimeError, match=r"bad\.sdl.*4"):
        bpy.ops.import_scene.sdl(filepath=str(bad), strict=True)
    with pytest.raises(RuntimeError, match="Cannot import"):
        bpy.ops.import_scene.sdl(filepath=str(tmp_path / "does_not_exist.sdl"))
    assert _counts() == before
    assert bpy.context.scene.camera == camera and bpy.context.scene.world == world_before


@pytest.mark.parametrize("strict", [False, True], ids=["lenient", "strict"])
def test_a_folder_or_fifo_is_one_clean_error(tmp_path, capfd, strict):
    import_sdl(SCENES / "csg.sdl")
    before, camera, world_before = _counts(), bpy.context.scene.camera, bpy.context.scene.world
    folder = tmp_path / "dir.sdl"
    folder.mkdir()
    fifo = tmp_path / "pipe.sdl"
    os.mkfifo(fifo)
    capfd.readouterr()
    for path, what in ((folder, "folder"), (fifo, "FIFO")):
        with pytest.raises(RuntimeError, match=rf"Cannot import {path.name}: .*{what}"):
            bpy.ops.import_scene.sdl(filepath=str(path), strict=strict)
    assert "Traceback" not in capfd.readouterr().err
    assert _counts() == before
    assert bpy.context.scene.camera == camera and bpy.context.scene.world == world_before


def test_import_syncs_each_material_once(tmp_path, monkeypatch):
    # A sync per SDL property set (about ten a material) made imports quadratic in the number of materials.
    synced = []
    real = props.apply_principled
    monkeypatch.setattr(props, "apply_principled", lambda material, *a, **k: (synced.append(material.name),
                                                                              real(material, *a, **k))[1])
    many = tmp_path / "many.sdl"
    many.write_text("".join(f"diffuse {i / 10} 0.5 0.25 specular 0.3 0.3 0.3 exponent {i + 2} reflectivity 0.{i}\n"
                            f"push translate {3 * i} 0 0 sphere pop\n" for i in range(6)))
    import_sdl(many)
    materials = {o.material_slots[0].material.name for o in shape_objects()}
    assert len(materials) == 6
    assert sorted(synced) == sorted(materials)  # each imported material synced exactly once
    # and each still shows its SDL values; a later edit in the UI still syncs at once
    mat = bpy.data.materials[sorted(materials)[-1]]
    bsdf = next(n for n in mat.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    np.testing.assert_allclose(tuple(bsdf.inputs["Base Color"].default_value)[:3], (0.5, 0.5, 0.25), atol=1e-6)
    synced.clear()
    mat.sdl.diffuse = (0.1, 0.2, 0.3)
    assert synced == [mat.name]
    np.testing.assert_allclose(tuple(bsdf.inputs["Base Color"].default_value)[:3], (0.1, 0.2, 0.3), atol=1e-6)


def test_lenient_import_reports_problems(tmp_path):
    messy = tmp_path / "messy.sdl"
    messy.write_text("sphere\nfrobnicate 1 2\npush translate 3 0 0 cube pop\n")
    result = importer.import_sdl(bpy.context, str(messy))
    assert [o["sdl_kind"] for o in result.objects] == ["sphere", "cube"]
    assert len(result.warnings) == 1 and "frobnicate" in result.warnings[0]


def test_lenient_import_refuses_a_file_with_nothing_readable(tmp_path):
    import_sdl(SCENES / "csg.sdl")
    before, camera, world_before = _counts(), bpy.context.scene.camera, bpy.context.scene.world
    binary = tmp_path / "photo.sdl"
    binary.write_bytes(bytes(range(256)) * 4)
    other_format = tmp_path / "notes.sdl"
    other_format.write_text("frobnicate 1 2\nhello world\n")
    for path in (binary, other_format):
        with pytest.raises(RuntimeError, match=rf"Cannot import {path.name}: nothing in the file could be read"):
            bpy.ops.import_scene.sdl(filepath=str(path))  # the default, lenient import
    assert _counts() == before
    assert bpy.context.scene.camera == camera and bpy.context.scene.world == world_before
    # a file with something readable beside its problems still imports what it can
    lit = tmp_path / "lit.sdl"
    lit.write_text("frobnicate 1 2\nlight 1 2 3 1 1 1\n")
    assert bpy.ops.import_scene.sdl(filepath=str(lit)) == {"FINISHED"}
    assert _counts()["lights"] == before["lights"] + 1


def test_failure_half_way_removes_what_was_made(monkeypatch):
    before = _counts()

    def broken(self, light, index):
        raise RuntimeError("simulated failure")

    monkeypatch.setattr(importer.Importer, "_light", broken)
    with pytest.raises(RuntimeError, match="simulated failure"):
        bpy.ops.import_scene.sdl(filepath=str(SCENES / "lecture.sdl"))
    assert _counts() == before


def test_a_failure_in_a_later_file_removes_the_earlier_ones(monkeypatch, tmp_path):
    """Several files are one import: when the second cannot be built, the first is removed again too (the
    operator is cancelled, so there would be no undo step for it)."""
    (tmp_path / "a.sdl").write_text("maxRecursionDepth 7\nsphere\n")
    (tmp_path / "b.sdl").write_text("light 1 2 3 1 1 1\ncube\n")
    bpy.context.scene.sdl_render.max_recursion_depth = 5
    before, camera, world_before = _counts(), bpy.context.scene.camera, bpy.context.scene.world

    def broken(self, light, index):
        raise RuntimeError("simulated failure")

    monkeypatch.setattr(importer.Importer, "_light", broken)
    with pytest.raises(RuntimeError, match="simulated failure"):
        bpy.ops.import_scene.sdl(directory=str(tmp_path), files=[{"name": "a.sdl"}, {"name": "b.sdl"}])
    assert _counts() == before
    assert bpy.context.scene.camera == camera and bpy.context.scene.world == world_before
    assert bpy.context.scene.sdl_render.max_recursion_depth == 5


def test_a_failed_import_leaves_the_scene_settings_as_they_were(monkeypatch, tmp_path):
    path = tmp_path / "deep.sdl"
    path.write_text("maxRecursionDepth 9\nmakePixmap 1 tex.png\nsphere\n")
    scene = bpy.context.scene
    scene.sdl_render.max_recursion_depth = 5
    keys = set(scene.keys())

    def broken(matrix):
        raise RuntimeError("simulated failure")

    monkeypatch.setattr(importer, "flat", broken)  # fails after the scene settings were set
    with pytest.raises(RuntimeError, match="simulated failure"):
        bpy.ops.import_scene.sdl(filepath=str(path))
    assert scene.sdl_render.max_recursion_depth == 5
    assert set(scene.keys()) == keys  # no sdl_pixmaps left behind


def test_import_without_a_view_layer(tmp_path):
    path = tmp_path / "one.sdl"
    path.write_text("sphere\n")
    context = SimpleNamespace(scene=bpy.context.scene, view_layer=None)
    result = importer.Importer(context, convert.axis_matrix()).run(importer.read_scene(str(path)), str(path))
    assert [o["sdl_kind"] for o in result.objects] == ["sphere"]


def test_shared_meshes_need_their_matrix_property(tmp_path):
    path = tmp_path / "one.sdl"
    path.write_text("sphere\n")
    import_sdl(path)
    first = shape_objects()[0].data
    del first[meshes.MATRIX]
    import_sdl(path)  # the mesh without its matrix is not shared (and does not stop the import)
    assert shape_objects()[1].data != first


def test_exact_mesh_files_kept_once_per_path(tmp_path):
    shutil.copy(SCENES / "meshes" / "pawn.3vn", tmp_path / "pawn.3vn")
    path = tmp_path / "pawn.sdl"
    path.write_text("mesh pawn.3vn\n")
    import_sdl(path)
    mesh = shape_objects()[0].data
    info = meshes.generic_info(mesh)
    mesh_file = str(tmp_path / "pawn.3vn")
    for step in range(3):  # the file changes (its time does): read again, the older copy dropped
        os.utime(mesh_file, (1_000_000 + step, 1_000_000 + step))
        assert meshes.exact_mesh_data(info, mesh) is not None
    assert sum(mesh_file in str(key) for key in meshes._exact_files) == 1


class _Layout:
    def __init__(self):
        self.labels = []

    def label(self, text="", icon="NONE"):
        self.labels.append(text)


def _shape_panel_text(obj) -> str:
    from addon import ui

    layout = _Layout()
    ui.SDL_PT_object.draw(SimpleNamespace(layout=layout), SimpleNamespace(object=obj))
    return layout.labels[0]


def test_shape_panel_tells_the_truth_without_hashing_every_redraw(monkeypatch):
    import_sdl(SCENES / "shapes.sdl")
    sphere = [o for o in shape_objects() if o["sdl_kind"] == "sphere"][0]
    assert _shape_panel_text(sphere) == "Generic sphere: traced exactly"
    hashed = []
    real_hash = meshes.mesh_hash
    monkeypatch.setattr(meshes, "mesh_hash", lambda mesh: hashed.append(mesh.name) or real_hash(mesh))
    for _ in range(3):  # redraws of an unchanged mesh hash nothing
        assert _shape_panel_text(sphere) == "Generic sphere: traced exactly"
    assert hashed == []
    # a modifier other than a Boolean makes the engine trace the object as a mesh
    subsurf = sphere.modifiers.new("smooth", "SUBSURF")
    assert "traced as a mesh" in _shape_panel_text(sphere)
    subsurf.show_render = False
    assert _shape_panel_text(sphere) == "Generic sphere: traced exactly"
    sphere.modifiers.remove(subsurf)
    # an edit of the mesh shows at once
    sphere.data.vertices[0].co.x += 0.1
    bpy.context.view_layer.update()
    assert _shape_panel_text(sphere) == "Edited generic shape: traced as a mesh"


def test_add_shape_reuses_one_material_and_undoes_a_failure(monkeypatch):
    bpy.ops.object.sdl_add_shape(kind="sphere")
    bpy.ops.object.sdl_add_shape(kind="cube")
    added = shape_objects()
    assert len(added) == 2 and len(bpy.data.materials) == 1  # one default SDL material, shared
    assert added[0].material_slots[0].material == added[1].material_slots[0].material
    bpy.data.materials.remove(added[0].material_slots[0].material)  # so that the next call makes one
    before = _counts()

    def broken(matrix):
        raise RuntimeError("simulated failure")

    monkeypatch.setattr(importer, "flat", broken)
    with pytest.raises(RuntimeError, match="simulated failure"):
        bpy.ops.object.sdl_add_shape(kind="cone")
    assert _counts() == before  # neither the object nor the default material it made is left


def test_a_scene_read_as_a_shape_table_imports_as_its_list(monkeypatch):
    """The fast SDL reader hands over a ShapeTable: importing it gives what the list of Shapes gives."""
    from tracer.model import ShapeTable
    from tracer.sdl import parser

    path = SCENES / "shapes.sdl"
    import_sdl(path)

    def made():
        return [(o.name, o["sdl_kind"], list(o["sdl_matrix"]), o.get("sdl_source"), o.active_material.name,
                 props.material_to_sdl(o.active_material)) for o in shape_objects()]

    expected = made()
    fresh()
    real_load = parser.load

    def load_as_table(*args, **kwargs):
        scene = real_load(*args, **kwargs)
        scene.objects = ShapeTable.of_shapes(scene.objects)
        return scene

    monkeypatch.setattr(parser, "load", load_as_table)
    import_sdl(path)
    assert made() == expected


def test_objects_and_materials_get_the_names_blender_would_give(tmp_path):
    """The importer works out Blender's names (naming.py) to make its objects and materials in the order of
    their names: they must be the names Blender itself gives when the objects are made one by one in the
    file's order, past 999 of one name, beside names the file already has."""
    lines = ["! name: sphere.002\nsphere", "! name: Ball\nsphere", "! name: ball\ncube", "! name: Ballon d'or\ncube"]
    lines += [f"diffuse 0.5 0.{i % 3} 0.5 push translate {i} 0 0 sphere pop" for i in range(1010)]
    lines += ["! name: sphere.002\nsphere", "! name: Ball\ncube"]
    path = tmp_path / "names.sdl"
    path.write_text("\n".join(lines) + "\n")
    fresh()
    existing_mesh = bpy.data.meshes.new("m")
    for name in ("sphere", "sphere.001", "sphere.005", "Ball"):
        bpy.data.objects.new(name, existing_mesh)
    bpy.data.materials.new("SDL 0.5 0.1 0.5")
    import_sdl(path)
    got = [o.name for o in shape_objects()]
    got_materials = [o.active_material.name for o in shape_objects()]
    # Blender, asked for each name in the file's order
    fresh()
    existing_mesh = bpy.data.meshes.new("m")
    for name in ("sphere", "sphere.001", "sphere.005", "Ball"):
        bpy.data.objects.new(name, existing_mesh)
    bpy.data.materials.new("SDL 0.5 0.1 0.5")
    scene = tracer.load(str(path))
    expected = [bpy.data.objects.new(s.name or s.kind, existing_mesh).name for s in scene.shapes()]
    by_value: dict = {}
    for s in scene.shapes():
        if s.material not in by_value:
            d = s.material.diffuse
            by_value[s.material] = bpy.data.materials.new(f"SDL {d[0]:g} {d[1]:g} {d[2]:g}").name
    assert got == expected
    assert got_materials == [by_value[s.material] for s in scene.shapes()]
    assert "sphere.1000" in got


def test_datablocks_sorted_as_naming_sort_key_says():
    from addon.pure import naming

    fresh()
    names = ["b", "B2", "a", "sphere.1000", "sphere.999", "sphere", "Zeta", "zeta.001", "é", "e", "_x", "~", "A b",
             "ab", "a.b", "10", "9"]
    for name in names:
        bpy.data.materials.new(name)
    assert [m.name for m in bpy.data.materials] == sorted(names, key=naming.sort_key)


def test_closing_an_import_half_way_removes_what_it_made(tmp_path):
    """Esc in Blender's window closes the import's steps (operators.py): what was made goes again."""
    path = tmp_path / "many.sdl"
    path.write_text("".join(f"diffuse 0.{i % 9} 0.5 0.5 push translate {i} 0 0 sphere pop\n" for i in range(1500)))
    before, camera, world_before = _counts(), bpy.context.scene.camera, bpy.context.scene.world
    imp = importer.Importer(bpy.context, convert.axis_matrix())
    steps = imp.steps(importer.read_scene(str(path)), str(path), hidden_while_made=True)
    for _ in range(4):  # (the plan, then materials and objects a STEP at a time)
        next(steps)
    assert _counts()["objects"] > before["objects"]
    steps.close()
    assert _counts() == before
    assert bpy.context.scene.camera == camera and bpy.context.scene.world == world_before


def test_an_import_kept_out_of_the_view_layer_while_made_ends_in_it(tmp_path, monkeypatch):
    monkeypatch.setattr(importer, "STEP", 1)
    path = tmp_path / "two.sdl"
    path.write_text("sphere\npush translate 3 0 0 cube pop\n")
    imp = importer.Importer(bpy.context, convert.axis_matrix())
    seen = []
    for _ in imp.steps(importer.read_scene(str(path)), str(path), hidden_while_made=True):
        layer = importer._layer_collection(bpy.context.view_layer, imp.result.collection)
        seen.append(layer is not None and layer.exclude)
    assert True in seen and seen[-1] is False
    assert all(o.visible_get() for o in imp.result.objects)


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: p.stem)
def test_the_transforms_kept_at_import_are_what_blender_shows(path):
    """The importer keeps what Blender shows of each transform (the snapshot the exact SDL values are kept
    against) without evaluating the scene: it must be, bit for bit, the evaluated world matrix."""
    import_sdl(path)
    bpy.context.view_layer.update()
    for obj in shape_objects():
        assert list(obj["sdl_matrix_shown"]) == world(obj).ravel().tolist(), obj.name
    camera = bpy.context.scene.camera
    assert list(camera["sdl_camera_shown"])[:16] == world(camera).ravel().tolist()
    for light in (o for o in bpy.data.objects if o.type == "LIGHT"):
        assert list(light["sdl_position_shown"]) == list(light.matrix_world.translation)
