"""Blender's own USD importer (bpy.ops.wm.usd_import) reads the USD files we write with the world matrices our
SDL importer (the add-on's bpy.ops.import_scene.sdl) gives the same scene.

We write ``upAxis = "Y"`` (SDL's world is y-up); Blender's USD importer turns a y-up stage into its z-up
world with a quarter turn about x, (x, y, z) -> (x, -z, y), and the add-on's SDL importer turns SDL's world
the same way, so the two give the same matrices.  Blender makes meshes of USD's implicit prims centred on
their origin, so a USD cylinder or cone object sits half a unit further up its axis than the add-on's,
whose meshes run from z = 0 to 1 as SDL's do (docs/usd.md): ``usd_world = sdl_world @ translate(0, 0, 0.5)``;
the vertices of the two meshes are then checked to lie on the same surface.

bpy and usd-core are both in requirements-dev.txt: without either these tests fail rather than skip.
"""
from __future__ import annotations

import math
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
from pxr import Usd, UsdGeom  # usd-core (also bundled in bpy, but not as pxr)

import tracer
from tracer.model import CSG
from tracer.transforms import translation
from tracer.usd import save_usd
from tracer.usd.writer import CENTRED, camera_frame

ROOT = Path(__file__).parent.parent
SCENES = sorted((ROOT / "scenes").glob("*.sdl"))
#: SDL (y-up) to Blender (z-up): what both importers apply.
Y_UP_TO_Z_UP = np.array([[1.0, 0, 0, 0], [0, 0, -1, 0], [0, 1, 0, 0], [0, 0, 0, 1]])
#: Blender keeps object matrices in float32.
TOLERANCE = 2e-5


def fresh_file():
    bpy.ops.wm.read_factory_settings(use_empty=True)


def world(obj) -> np.ndarray:
    return np.array([list(row) for row in obj.matrix_world], dtype=np.float64)


def close(a, b) -> bool:
    return float(np.max(np.abs(a - b))) <= TOLERANCE * max(1.0, float(np.max(np.abs(b))))


def prim_names(scene) -> list[str]:
    """The name the USD writer gives each shape, in scene order (one counter per SDL keyword)."""
    counts: dict[str, int] = {}
    names = []
    todo = list(reversed(scene.objects))
    while todo:  # the writer's order: depth first, left operand first; booleans count under their op
        obj = todo.pop()
        key = obj.op if isinstance(obj, CSG) else obj.kind
        counts[key] = counts.get(key, 0) + 1
        if isinstance(obj, CSG):
            todo += [obj.right, obj.left]
        else:
            names.append(f"{key}_{counts[key] - 1}")
    return names


def usd_import(scene, folder: Path) -> dict:
    path = folder / "scene.usda"
    save_usd(scene, path)
    fresh_file()
    assert bpy.ops.wm.usd_import(filepath=str(path)) == {"FINISHED"}
    return {obj.name: obj for obj in bpy.data.objects}


def expected_usd_world(shape) -> np.ndarray:
    offset = CENTRED if shape.kind in ("cylinder", "cone") else np.eye(4)
    return Y_UP_TO_Z_UP @ shape.matrix @ offset


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_blender_usd_import_places_every_object_light_and_camera(path, tmp_path):
    """Needs no add-on: Blender's USD importer against the matrices the scene itself holds."""
    scene = tracer.load(path)
    objects = usd_import(scene, tmp_path)
    for name, shape in zip(prim_names(scene), scene.shapes()):
        obj = objects[name]
        assert obj.type == "MESH", name
        assert close(world(obj), expected_usd_world(shape)), (name, world(obj), expected_usd_world(shape))
    lights = sorted((o for o in objects.values() if o.type == "LIGHT"), key=lambda o: o.name)
    assert len(lights) == len(scene.lights)
    for obj, light in zip(lights, scene.lights):
        assert close(world(obj)[:3, 3], (Y_UP_TO_Z_UP @ [*light.position, 1.0])[:3])
    cameras = [o for o in objects.values() if o.type == "CAMERA"]
    assert len(cameras) == (scene.camera is not None)
    if scene.camera is not None:
        assert close(world(cameras[0]), Y_UP_TO_Z_UP @ camera_frame(scene.camera))


@pytest.fixture(scope="module")
def sdl_importer():
    """The add-on's SDL importer (``import addon; addon.register()``), unregistered afterwards: with the
    add-on still registered at exit, the bpy module's interpreter shutdown hangs (bpy 4.5)."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))
    import addon

    addon.register()
    yield bpy.ops.import_scene.sdl
    addon.unregister()


def generic_points(obj, shape) -> np.ndarray:
    """The object's mesh vertices in the shape's generic coordinates: Blender's world back through the axis
    turn and the SDL matrix."""
    points = np.array([v.co for v in obj.data.vertices], dtype=np.float64).reshape(-1, 3)
    to_generic = np.linalg.inv(Y_UP_TO_Z_UP @ shape.matrix) @ world(obj)
    return points @ to_generic[:3, :3].T + to_generic[:3, 3]


def on_generic_surface(kind: str, p: np.ndarray) -> np.ndarray:
    """How far each generic point is off the shape's generic surface (for the implicit prims)."""
    x, y, z = p.T
    r = np.hypot(x, y)
    if kind == "sphere":
        return np.abs(np.linalg.norm(p, axis=1) - 1.0)
    if kind == "cube":
        return np.abs(np.max(np.abs(p), axis=1) - 1.0)
    if kind == "plane":
        return np.abs(z)
    top = 1.0 if kind == "cylinder" else 0.0  # radius at z = 1
    wall = np.abs(r - (1.0 + (top - 1.0) * z))
    caps = np.where(np.isclose(z, 0.0, atol=1e-5) | np.isclose(z, 1.0, atol=1e-5), 0.0, np.inf)
    inside_z = np.where((z > -1e-5) & (z < 1 + 1e-5), 0.0, np.inf)
    return np.minimum(wall, caps) + inside_z


@pytest.mark.parametrize("path", SCENES, ids=[p.stem for p in SCENES])
def test_blender_usd_import_matches_the_sdl_importer(path, tmp_path, sdl_importer):
    importer = sdl_importer
    scene = tracer.load(path)
    fresh_file()
    assert importer(filepath=str(path)) == {"FINISHED"}
    from_sdl = [o for o in bpy.data.objects if "sdl_kind" in o.keys()]
    from_sdl.sort(key=lambda o: o.get("sdl_order", 0))
    sdl_worlds = [(o["sdl_kind"], world(o)) for o in from_sdl]
    sdl_lights = sorted(tuple(round(v, 4) for v in o.matrix_world.translation)
                        for o in bpy.data.objects if o.type == "LIGHT")
    sdl_cameras = [(world(o), math.degrees(o.data.angle_y)) for o in bpy.data.objects if o.type == "CAMERA"]

    objects = usd_import(scene, tmp_path)
    shapes = list(scene.shapes())
    assert [kind for kind, _ in sdl_worlds] == [s.kind for s in shapes]
    for (kind, sdl_world), name, shape in zip(sdl_worlds, prim_names(scene), shapes):
        offset = CENTRED if kind in ("cylinder", "cone") else np.eye(4)
        assert close(world(objects[name]), sdl_world @ offset), (name, world(objects[name]), sdl_world)
        if kind in ("sphere", "cube", "cylinder", "cone", "plane"):  # Blender's own mesh of the USD prim
            off = on_generic_surface(kind, generic_points(objects[name], shape))
            assert float(np.max(off)) < 1e-4, (name, float(np.max(off)))
    usd_lights = sorted(tuple(round(v, 4) for v in o.matrix_world.translation)
                        for o in objects.values() if o.type == "LIGHT")
    assert usd_lights == sdl_lights
    usd_cameras = [o for o in objects.values() if o.type == "CAMERA"]
    assert len(usd_cameras) == len(sdl_cameras)
    for usd_camera, (sdl_world, sdl_angle) in zip(usd_cameras, sdl_cameras):
        assert close(world(usd_camera), sdl_world)
        # the same vertical view angle (at 4:3 the two frame the same picture: docs/usd.md)
        assert math.degrees(usd_camera.data.angle_y) == pytest.approx(sdl_angle, abs=1e-4)
        assert math.degrees(usd_camera.data.angle_y) == pytest.approx(scene.camera.view_angle, abs=1e-4)


def test_offset_of_centred_prims_is_half_a_unit_up_the_axis():
    assert np.array_equal(CENTRED, translation(0, 0, 0.5))


def test_the_up_axis_turn_is_really_applied(tmp_path):
    """The comparison above is not a tautology: a sphere SDL puts at y = 5 stands 5 units *up* in Blender
    (its z), and a stage that says it is z-up would not be turned."""
    scene = tracer.parse_sdl("translate 1 5 -2 sphere")
    objects = usd_import(scene, tmp_path)
    assert np.allclose(world(objects["sphere_0"])[:3, 3], (1, 2, 5))
    stage = Usd.Stage.Open(str(tmp_path / "scene.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    stage.GetRootLayer().Save()
    fresh_file()
    assert bpy.ops.wm.usd_import(filepath=str(tmp_path / "scene.usda")) == {"FINISHED"}
    assert np.allclose(world(bpy.data.objects["sphere_0"])[:3, 3], (1, 5, -2))
