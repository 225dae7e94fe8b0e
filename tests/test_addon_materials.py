"""One material truth: the colour a user sees and edits (the Principled BSDF's Base Color, or the SDL
Material panel's Diffuse) is the colour traced and exported, whichever of the two was edited, and ticking or
unticking SDL Material overwrites neither."""
from __future__ import annotations

import shutil

import bpy
import numpy as np
import pytest
from bpy_extras.object_utils import world_to_camera_view

import tracer
from addon import props
from blender_scripts.addon_env import SCENES, fresh, import_sdl, render_rgba, set_resolution, shape_objects


def _red_sphere():
    obj = next(o for o in shape_objects() if o["sdl_kind"] == "sphere" and o.active_material.sdl.diffuse[0] > 0.5)
    return obj, obj.active_material


def _base(material):
    node = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    return node.inputs["Base Color"]


def _centre_colour(obj) -> np.ndarray:
    scene = bpy.context.scene
    rgba = render_rgba("SDL_RAYTRACER")
    p = world_to_camera_view(scene, scene.camera, obj.matrix_world.translation)
    height, width = rgba.shape[:2]
    return rgba[int((1.0 - p.y) * height), int(p.x * width), :3]


def test_an_edited_base_color_is_traced_exported_and_shown(tmp_path):
    fresh()
    import_sdl(SCENES / "lecture.sdl")
    set_resolution(80, 60)
    obj, material = _red_sphere()
    before = _centre_colour(obj)
    _base(material).default_value = (0.1, 0.2, 0.9, 1.0)  # the user makes the red sphere blue
    assert np.allclose(props.material_to_sdl(material).diffuse, (0.1, 0.2, 0.9), atol=1e-6)
    after = _centre_colour(obj)
    assert before[0] > before[2] and after[2] > after[0]  # red before, blue now
    bpy.context.view_layer.update()  # (the depsgraph handler shows the edit in the SDL Material panel)
    assert np.allclose(tuple(material.sdl.diffuse), (0.1, 0.2, 0.9), atol=1e-6)
    out = tmp_path / "edited.sdl"
    assert bpy.ops.export_scene.sdl(filepath=str(out)) == {"FINISHED"}
    diffuse = {s.material.diffuse for s in tracer.load(str(out)).shapes()}
    assert any(np.allclose(d, (0.1, 0.2, 0.9), atol=1e-6) for d in diffuse)


def test_ticking_sdl_material_overwrites_nothing():
    fresh()
    import_sdl(SCENES / "lecture.sdl")
    _, material = _red_sphere()
    _base(material).default_value = (0.3, 0.6, 0.2, 1.0)
    material.sdl.use_sdl = False  # (this used to write the SDL colour over the edit)
    assert np.allclose(tuple(_base(material).default_value)[:3], (0.3, 0.6, 0.2), atol=1e-6)
    material.sdl.use_sdl = True
    assert np.allclose(tuple(_base(material).default_value)[:3], (0.3, 0.6, 0.2), atol=1e-6)
    assert np.allclose(props.material_to_sdl(material).diffuse, (0.3, 0.6, 0.2), atol=1e-6)


def test_an_edit_in_the_sdl_panel_reaches_the_principled_bsdf_and_the_render():
    fresh()
    import_sdl(SCENES / "lecture.sdl")
    _, material = _red_sphere()
    before = props.material_to_sdl(material)
    material.sdl.diffuse = (0.25, 0.5, 0.75)
    assert np.allclose(tuple(_base(material).default_value)[:3], (0.25, 0.5, 0.75), atol=1e-6)
    now = props.material_to_sdl(material)
    assert np.allclose(now.diffuse, (0.25, 0.5, 0.75), atol=1e-6)
    assert (now.ambient, now.specular) == (before.ambient, before.specular)  # the exact SDL values kept


def test_materials_made_one_after_another_keep_nothing_of_the_one_before(tmp_path):
    """The importer makes each new material as a copy of the one made before it (a node tree is then not
    built anew): every material must still be exactly its own SDL material, its Principled inputs and viewport
    colour its own, and only a picture-textured material keeps a picture."""
    shutil.copy(SCENES / "images" / "bricks.png", tmp_path / "bricks.png")
    text = ("makePixmap 1 bricks.png\n"
            "texture 1 parameters 2 3 4 diffuse 0.9 0.1 0.1 specular 0.5 0.5 0.5 reflectivity 0.3 sphere\n"
            "defaultMaterials diffuse 0.1 0.8 0.2 speedOfLight 0.6 transparency 0.4 translate 3 0 0 cube\n"
            "defaultMaterials emissive 0.2 0.1 0 translate -3 0 0 cone\n"
            "defaultMaterials translate 0 3 0 torus\n")
    path = tmp_path / "three.sdl"
    path.write_text(text)
    fresh()
    import_sdl(path)
    wanted = [s.material for s in tracer.load(path).objects]
    made = {o["sdl_kind"]: o.active_material for o in shape_objects()}
    for shape, material in zip(tracer.load(path).objects, wanted):
        blender = made[shape.kind]
        assert props.material_to_sdl(blender) == material
        assert blender.sdl.image == (str(tmp_path / "bricks.png") if material.texture > 0 else "")
        assert np.allclose(tuple(_base(blender).default_value)[:3], material.diffuse, atol=1e-6)
        assert np.allclose(tuple(blender.diffuse_color)[:3], material.diffuse, atol=1e-6)
    assert len({m.name for m in made.values()}) == 4


def _principled_values(material) -> dict:
    node = next(n for n in material.node_tree.nodes if n.type == "BSDF_PRINCIPLED")
    return {s.name: (tuple(s.default_value) if hasattr(s.default_value, "__len__") else s.default_value)
            for s in node.inputs if hasattr(s, "default_value")}


def test_materials_imported_in_bulk_equal_materials_made_one_by_one(tmp_path, monkeypatch):
    """The importer writes each new material's Principled inputs all at once (props.PrincipledWriter), not
    input by input: every set of one input made Blender look through all the node trees in the file. Each
    material must hold what setting it up the ordinary way gives, in every input and viewport value, and no
    input is set one by one after the first material (counted, not timed)."""
    lines = []
    for i in range(40):
        lines.append(f"diffuse {i / 40:.3f} {1 - i / 40:.3f} 0.25 specular 0.{i % 10} 0.2 0.2 specularExponent {i + 1} "
                     f"reflectivity {i / 80:.4f} transparency {(i % 3) / 4} speedOfLight {1 - (i % 5) / 10} "
                     f"emissive 0 {(i % 4) / 8} 0 push translate {2 * i} 0 0 sphere pop")
    path = tmp_path / "many.sdl"
    path.write_text("\n".join(lines) + "\n")
    one_by_one = []
    real_set_input = props._set_input
    monkeypatch.setattr(props, "_set_input", lambda node, names, value: (one_by_one.append(names),
                                                                          real_set_input(node, names, value)))
    fresh()
    import_sdl(path)
    assert len(one_by_one) <= len(props.principled_inputs(bpy.data.materials[0].sdl))  # the first material's
    wanted = [s.material for s in tracer.load(path).objects]
    for obj, material in zip(shape_objects(), wanted):
        made = obj.active_material
        assert props.material_to_sdl(made) == material
        reference = bpy.data.materials.new("reference")
        reference.use_nodes = True
        props.set_material(reference, material)
        assert _principled_values(made) == _principled_values(reference), made.name
        for name in ("diffuse_color", "roughness", "metallic"):
            assert np.array_equal(np.array(getattr(made, name)), np.array(getattr(reference, name)))
        assert list(made[props.BASE_SHOWN]) == list(reference[props.BASE_SHOWN])
        bpy.data.materials.remove(reference)


def test_reading_and_importing_materials_and_worlds_uses_no_deprecated_switch(recwarn):
    """Blender 5.0 keeps use_nodes on for every material and world and warns that the switch goes in 6.0: the
    add-on reads nodes there without it (so it keeps working in 6.0); before 5.0 it still honours the switch."""
    fresh()
    import_sdl(SCENES / "lecture.sdl")
    made = bpy.data.materials.new("made in Blender")
    made.use_nodes = True  # (the test's own use of the switch is not what is checked)
    made.node_tree.nodes["Principled BSDF"].inputs["Metallic"].default_value = 1.0
    world = bpy.data.worlds.new("made in Blender")
    world.use_nodes = True
    recwarn.clear()
    import_sdl(SCENES / "lecture.sdl")
    material = props.blender_material(made, [])[0]
    settings = props.world_settings(world, 3)
    for imported in bpy.data.materials:
        props.blender_material(imported, [])
    assert material.reflectivity == 1.0 and material.fresnel == "metal"  # read from the nodes
    assert tuple(settings.background) == pytest.approx((0.05, 0.05, 0.05))  # the new world's Background node
    assert [str(w.message) for w in recwarn if "use_nodes" in str(w.message)] == []
