"""Lights between SDL and Blender (addon/blender_lights.py, addon/pure/light_units.py, the importer): SDL's
``light`` stays an SDL light (no falloff, its exact colour) through import -> export -> import, the physical
lights become the Blender lights of the same meaning in Blender's units and come back as themselves, and
every light keeps its name ("Key Light" came back as "SDL light 3").  A light made in Blender is a physical
light in Blender's units."""
from __future__ import annotations

import math

import bpy
import numpy as np
import pytest

import tracer
from addon import engine
from blender_scripts.addon_env import fresh, import_sdl

SCENE = """\
! name: Key Light
light 3 4 5  1 0.9 0.8
! name: Bulb
sphereLight 0 5 0  2 2 2  0.5 8
! name: Stage Spot
spotLight -3 5 2  1 -1 0  1 0.5 0.25  40 0.2 0.1 8
! name: Sun
sunLight 0 -1 -1  0.5 0.5 0.5  2 8
! name: Panel
areaLight 0 6 0  0 -1 0  1 0 0  3 3 3  2 1 8
! name: Disk
ellipseLight 2 6 0  0 -1 0  0 0 1  1 1 1  1.5 1 8
sphere
"""


def _unit(v) -> np.ndarray:
    v = np.asarray(v, dtype=float)
    return v / np.linalg.norm(v)


def _same_lights(got, wanted) -> None:
    assert [(light.kind, light.name) for light in got] == [(light.kind, light.name) for light in wanted]
    for a, b in zip(got, wanted):
        assert a.color == pytest.approx(b.color, rel=1e-5), (a, b)
        if a.kind != "sun":
            assert a.position == pytest.approx(b.position, abs=1e-5), (a, b)
        if a.kind in ("spot", "sun", "area"):
            assert _unit(a.direction) == pytest.approx(_unit(b.direction), abs=1e-6), (a, b)
        assert a.shape == b.shape, (a, b)  # (a string: newer pytest refuses one inside approx)
        assert (a.radius, a.angle, a.spot_blend, a.samples) == pytest.approx(
            (b.radius, b.angle, b.spot_blend, b.samples), rel=1e-5), (a, b)
        assert a.spot_size == pytest.approx(b.spot_size, rel=1e-5) and a.size == pytest.approx(b.size, rel=1e-5)
        if a.kind == "area":
            assert _unit(a.axis) == pytest.approx(_unit(b.axis), abs=1e-6)


def test_lights_keep_their_kind_meaning_and_name_through_import_export_import(tmp_path):
    source = tmp_path / "lights.sdl"
    source.write_text(SCENE)
    wanted = tracer.load(str(source)).lights
    fresh()
    import_sdl(source)
    lights = {obj.name: obj.data for obj in bpy.data.objects if obj.type == "LIGHT"}
    assert {name: data.type for name, data in lights.items()} == {
        "Key Light": "POINT", "Bulb": "POINT", "Stage Spot": "SPOT", "Sun": "SUN", "Panel": "AREA", "Disk": "AREA"}
    assert lights["Bulb"].energy == pytest.approx(2.0 * 4 * math.pi ** 2, rel=1e-6)  # colour 2 = 79 W
    assert lights["Bulb"].shadow_soft_size == pytest.approx(0.5)
    built, _ = engine.build_scene(bpy.context.evaluated_depsgraph_get(), "EXPORT")
    out = tmp_path / "out.sdl"
    assert bpy.ops.export_scene.sdl(filepath=str(out)) == {"FINISHED"}
    exported = tracer.load(str(out)).lights
    _same_lights(exported, wanted)
    assert exported[0].kind == "point" and exported[0].color == wanted[0].color  # SDL's light, exactly
    fresh()
    import_sdl(out)
    assert bpy.ops.export_scene.sdl(filepath=str(tmp_path / "again.sdl")) == {"FINISHED"}
    _same_lights(tracer.load(str(tmp_path / "again.sdl")).lights, wanted)


def test_a_light_made_in_blender_is_in_blender_units_and_keeps_its_name(tmp_path):
    fresh()
    bpy.ops.mesh.primitive_cube_add()
    bpy.ops.object.light_add(type="POINT", location=(1.0, 2.0, 3.0))
    key = bpy.context.object
    key.name = "Key Light"
    key.data.energy, key.data.color, key.data.shadow_soft_size = 1000.0, (1.0, 0.5, 0.25), 0.0
    scene, _ = engine.build_scene(bpy.context.evaluated_depsgraph_get(), "RENDER")
    light = scene.lights[0]
    assert (light.kind, light.name, light.radius) == ("sphere", "Key Light", 0.0)
    assert light.color == pytest.approx(tuple(1000.0 * c / (4 * math.pi ** 2) for c in (1.0, 0.5, 0.25)))
    out = tmp_path / "made.sdl"
    assert bpy.ops.export_scene.sdl(filepath=str(out)) == {"FINISHED"}
    assert "! name: Key Light\nsphereLight" in out.read_text()
    fresh()
    import_sdl(out)
    back = bpy.data.objects["Key Light"].data
    assert back.type == "POINT" and back.energy == pytest.approx(1000.0, rel=1e-5)
    assert tuple(back.color) == pytest.approx((1.0, 0.5, 0.25))


def test_cycles_light_switches_become_the_lights_switches(tmp_path):
    """Cast Shadow (light data) and Ray Visibility (the object's Diffuse, Glossy, Transmission) switch the
    same off in the tracer; SDL has no words for them: an export writes the light, with a warning."""
    fresh()
    bpy.ops.mesh.primitive_cube_add()
    bpy.ops.object.light_add(type="AREA", location=(0.0, 0.0, 3.0))
    panel = bpy.context.object
    panel.name = "Panel"
    panel.visible_glossy = False
    bpy.ops.object.light_add(type="POINT", location=(1.0, 2.0, 3.0))
    bulb = bpy.context.object
    bulb.name = "Bulb"
    bulb.data.use_shadow = False
    bulb.visible_diffuse = False
    bulb.visible_transmission = False
    bpy.ops.object.light_add(type="SUN")
    bpy.context.object.name = "Sun"
    scene, _ = engine.build_scene(bpy.context.evaluated_depsgraph_get(), "RENDER")
    switches = {light.name: (light.cast_shadow, light.visible_diffuse, light.visible_glossy,
                             light.visible_transmission) for light in scene.lights}
    assert switches == {"Panel": (True, True, False, True), "Bulb": (False, False, True, False),
                        "Sun": (True, True, True, True)}
    out = tmp_path / "switched.sdl"
    assert bpy.ops.export_scene.sdl(filepath=str(out)) == {"FINISHED"}
    written = {light.name: light for light in tracer.load(str(out)).lights}
    assert set(written) == {"Panel", "Bulb", "Sun"}  # (every light written, as the light)
    assert all(light.cast_shadow and light.visible_glossy for light in written.values())
    _, warnings = engine.build_scene(bpy.context.evaluated_depsgraph_get(), "EXPORT")
    assert sorted(w.split(":")[0] for w in warnings if "Cast Shadow" in w) == ["Bulb", "Panel"]
