"""The paraboloid, the SDL extension added by following docs/contributing.md's "Adding a shape" once: its
hits lie on the surface with outward normals, both backends agree, and SDL, USD, texture mapping, the
renderer and the Blender add-on's meshes all know it from its registry entry alone.
(tests/test_native.py also compares its C and NumPy hits and texture colours, as for every analytic kind.)"""
from __future__ import annotations

import numpy as np
import pytest

import tracer
from tracer import native
from helpers import Camera, Light, assert_closed_and_outward, ray_hits, rotation, scaling, scene_of, shape, translation
from tracer.compile import compile_scene
from tracer.intersect.paraboloid import intersect_paraboloid, paraboloid_mesh
from tracer.render import render
from tracer.sdl.writer import write_sdl
from tracer.usd import load_usd, save_usd


def _inside(points: np.ndarray) -> np.ndarray:
    x, y, z = points.T
    return (x * x + y * y <= z) & (z <= 1.0)


def _random_lines(count: int, seed: int):
    rng = np.random.default_rng(seed)
    starts = rng.normal(size=(count, 3))
    starts = 4.0 * starts / np.linalg.norm(starts, axis=1, keepdims=True)
    targets = rng.uniform(-1.2, 1.2, (count, 3)) * (1, 1, 0.6) + (0, 0, 0.5)
    return starts, targets - starts


def test_hits_lie_on_the_surface_and_normals_point_out():
    origins, directions = _random_lines(4000, seed=1)
    hits = intersect_paraboloid(origins, directions)
    found = np.isfinite(hits.t)
    assert found.sum() > 2000  # most lines aim at the shape
    assert np.all(found[:, 0] == found[:, 1])  # a closed solid: entry and exit together
    assert np.all(hits.entering[:, 0][found[:, 0]]) and not np.any(hits.entering[:, 1])
    rows, slots = np.nonzero(found)
    p = origins[rows] + hits.t[rows, slots, None] * directions[rows]
    part = hits.part[rows, slots]
    wall, cap = part == 0, part == 1
    assert wall.any() and cap.any()
    x, y, z = p.T
    assert np.max(np.abs((x * x + y * y - z)[wall])) < 1e-12
    assert np.all((z[wall] >= -1e-12) & (z[wall] <= 1 + 1e-12))
    assert np.max(np.abs(z[cap] - 1.0)) < 1e-12 and np.all((x * x + y * y)[cap] <= 1 + 1e-12)
    # Outward: a step along the normal leaves the solid, a step against it enters (away from the rim).
    n = hits.normal[rows, slots]
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    clear = np.abs(z - 1.0) > 1e-3
    assert not np.any(_inside(p + 1e-6 * n)[clear])
    assert np.all(_inside(p - 1e-6 * n)[clear & (z > 1e-3)])


def test_known_hits_on_both_backends(backend):
    scene = scene_of(shape("paraboloid"))
    # Down the axis: in through the cap at z = 1, out at the apex.
    assert ray_hits(scene, (0, 0, 5), (0, 0, -1), backend) == [(4.0, True), (5.0, False)]
    # Across at z = 1/4: the wall at x = -1/2 and 1/2.
    assert ray_hits(scene, (-5, 0, 0.25), (1, 0, 0), backend) == [(4.5, True), (5.5, False)]
    # Up a line parallel to the axis at radius 1/2: the wall at z = 1/4, the cap at z = 1.
    assert ray_hits(scene, (0.5, 0, -2), (0, 0, 1), backend) == [(2.25, True), (3.0, False)]
    # Above the cap, and beside the wall: nothing.
    assert ray_hits(scene, (-5, 0, 1.5), (1, 0, 0), backend) == []
    assert ray_hits(scene, (1.5, 0, -5), (0, 0, 1), backend) == []


def test_c_hits_equal_numpy_hits_on_hard_lines():
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    from test_native import _core, assert_same_hits

    through = [((0, 0, 5), (0, 0, -1)), ((0, 0, -5), (0, 0, 1)),  # through the apex, both ways
               ((-5, 0.5, 0.25), (1, 0, 0)), ((-3, 0, 3), (1, 0, -1)),  # a side; in through the cap
               ((0.2, 0.1, 5), (1e-9, 0, -1)), ((0.3, 0.3, 0.5), (0, 1, 0))]  # nearly vertical; from inside
    # Lines that only touch the surface: their one double hit exists or not by the last bit of the generic
    # ray, so both backends must get the same generic ray: the identity matrix.
    touching = [((1, 0, -5), (0, 0, 1)), ((-5, 0, 1), (1, 0, 0)),  # along the rim; along the cap's plane
                ((-5, 0, 0), (1, 0, 0))]  # tangent at the apex
    matrix = translation(0.3, -1.0, 2.0) @ rotation(35, 1, 2, 0) @ scaling(1.5, 0.7, 2.0)
    for m, lines in ((np.eye(4), through + touching), (matrix, through)):
        compiled, core = _core(scene_of(shape("paraboloid", m)))
        for o, d in lines:
            o, d = np.asarray(o, float), np.asarray(d, float)
            assert_same_hits(compiled, core, m[:3, :3] @ o + m[:3, 3], m[:3, :3] @ d)


def test_sdl_keyword_round_trips():
    scene = tracer.parse_sdl("translate 1 2 3 paraboloid")
    assert [s.kind for s in scene.shapes()] == ["paraboloid"]
    again = tracer.parse_sdl(write_sdl(scene))
    assert [s.kind for s in again.shapes()] == ["paraboloid"]
    assert np.array_equal(again.shapes()[0].matrix, scene.shapes()[0].matrix)


def test_usd_round_trip_keeps_the_exact_shape(tmp_path):
    scene = scene_of(shape("paraboloid", translation(1, 2, 3) @ scaling(2, 2, 1)))
    path = tmp_path / "p.usda"
    save_usd(scene, path)
    back = load_usd(path)
    assert [s.kind for s in back.shapes()] == ["paraboloid"]
    assert np.allclose(back.shapes()[0].matrix, scene.shapes()[0].matrix, atol=1e-12)
    assert "paraboloid" in path.read_text()


def test_tessellation_is_closed_outward_and_on_the_surface():
    data = paraboloid_mesh()
    v = data.vertices
    assert np.max(np.abs(v[:, 0] ** 2 + v[:, 1] ** 2 - v[:, 2])) < 1e-15
    assert_closed_and_outward(data)


def test_blender_adds_exports_and_draws_it_from_the_registry(tmp_path):
    bpy = pytest.importorskip("bpy")
    from addon import exporter, operators
    from addon.pure import convert
    from blender_scripts.addon_env import fresh, shape_objects

    assert "paraboloid" in [item[0] for item in operators.SHAPE_ITEMS]  # in the Add menu
    fresh()
    bpy.ops.object.sdl_add_shape(kind="paraboloid")
    [obj] = shape_objects()
    assert obj["sdl_kind"] == "paraboloid"
    drawn = np.array([v.co for v in obj.data.vertices])
    assert len(obj.data.polygons) == len(paraboloid_mesh().faces)
    assert np.allclose(drawn, paraboloid_mesh().vertices, atol=1e-6)  # float32 in Blender
    path = tmp_path / "added.sdl"
    exporter.export_sdl(bpy.context, str(path), convert.axis_matrix("-Z", "Y"), use_selection=False)
    assert [s.kind for s in tracer.load(str(path)).shapes()] == ["paraboloid"]


def test_textured_render_is_the_same_on_both_backends():
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    para = shape("paraboloid", rotation(-70, 1, 0, 0) @ scaling(1.5, 1.5, 2.0), texture=-1, parameters=(0.25,),
                 diffuse=(0.9, 0.5, 0.2))
    scene = scene_of(para, lights=[Light((4, 6, 8), (1, 1, 1))],
                     camera=Camera((0, 1, 6), (0, 0.5, 0), (0, 1, 0), 45))
    assert "shape:paraboloid" in compile_scene(scene).effects
    c = render(scene, 64, 48, backend="c")
    n = render(scene, 64, 48, backend="numpy")
    assert c.backend == "c" and n.backend == "numpy"
    diff = np.abs(c.image.astype(float) - n.image.astype(float))
    assert diff.max() <= 1.0 / 255.0 + 1e-12
    covered = np.ptp(c.image.reshape(-1, c.image.shape[-1]), axis=0).max()
    assert covered > 0.2  # the shape is in view: not an empty image
