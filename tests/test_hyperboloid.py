"""The hyperboloid of one sheet (``hyperboloid S``), the SDL extension with a parameter added by following
docs/contributing.md's "Adding a shape" once: its hits lie on the surface with outward normals and
alternating entering flags (up to four), both backends agree to the bit, and both SDL readers, the SDL
writer, USD, texture mapping, the renderer and the Blender add-on know it, waist included, from its registry
entry alone.  (tests/test_native.py also compares its C and NumPy hits and texture colours, as for every
analytic kind.)"""
from __future__ import annotations

import math

import numpy as np
import pytest

import tracer
from tracer import native, shapes
from helpers import Camera, Light, assert_closed_and_outward, ray_hits, rotation, scaling, scene_of, shape, translation
from tracer.compile import compile_scene
from tracer.intersect.hyperboloid import hyperboloid_mesh, hyperboloid_uv, intersect_hyperboloid
from tracer.render import render
from tracer.sdl import fastread
from tracer.sdl.writer import write_sdl
from tracer.usd import load_usd, save_usd

WAISTS = (0.5, 0.0, 1.0, 1.4)


def hyperboloid(waist: float, matrix=None, **material):
    s = shape("hyperboloid", matrix, **material)
    s.parameters = (waist,)
    return s


def _inside(points: np.ndarray, waist: float) -> np.ndarray:
    x, y, z = points.T
    return (x * x + y * y - (1.0 - waist * waist) * z * z <= waist * waist) & (np.abs(z) <= 1.0)


def _random_lines(count: int, seed: int):
    rng = np.random.default_rng(seed)
    starts = rng.normal(size=(count, 3))
    starts = 4.0 * starts / np.linalg.norm(starts, axis=1, keepdims=True)
    targets = rng.uniform(-1.3, 1.3, (count, 3))
    directions = targets - starts
    steep = rng.random(count) < 0.3  # lines near the axis's direction: through the waist's hole and back
    directions[steep] = rng.normal(0, 0.15, (steep.sum(), 3)) + (0, 0, 1)
    return np.where(steep[:, None], targets - 4.0 * directions, starts), directions


@pytest.mark.parametrize("waist", WAISTS)
def test_hits_lie_on_the_surface_alternate_and_normals_point_out(waist):
    origins, directions = _random_lines(4000, seed=int(waist * 10))
    hits = intersect_hyperboloid(origins, directions, waist)
    found = np.isfinite(hits.t)
    assert found[:, 0].sum() > 2000  # most lines aim at the shape
    # intervals in, out, in, out: a closed solid entered and left in turn, in order
    assert np.array_equal(found[:, 0], found[:, 1]) and np.array_equal(found[:, 2], found[:, 3])
    assert np.all(found[:, 0] | ~found[:, 2])
    assert np.array_equal(hits.entering, found & (np.arange(4) % 2 == 0))
    for j in range(3):  # in order along the line
        both = found[:, j] & found[:, j + 1]
        assert np.all(hits.t[both, j + 1] >= hits.t[both, j])
    if 0.0 < waist < 1.0:
        assert found[:, 2].sum() > 20  # through the solid twice: the hourglass's two ends
    rows, slots = np.nonzero(found)
    p = origins[rows] + hits.t[rows, slots, None] * directions[rows]
    part = hits.part[rows, slots]
    x, y, z = p.T
    k = 1.0 - waist * waist
    wall, caps = part == 0, part > 0
    assert wall.any() and caps.any()
    assert np.max(np.abs((x * x + y * y - k * z * z - waist * waist)[wall])) < 1e-12
    assert np.all(np.abs(z[wall]) <= 1 + 1e-12)
    assert np.max(np.abs(z[caps] - np.where(part[caps] == 2, 1.0, -1.0))) < 1e-12
    assert np.all((x * x + y * y)[caps] <= 1 + 1e-12)
    # the wall's normal is the exact gradient's direction; the caps' are -z and +z
    n = hits.normal[rows, slots]
    gradient = np.stack([x, y, -k * z], axis=1)
    assert np.allclose(np.cross(n[wall], gradient[wall]), 0.0, atol=1e-12)
    assert np.array_equal(n[caps], np.where((part[caps] == 2)[:, None], (0.0, 0.0, 1.0), (0.0, 0.0, -1.0)))
    # outward (after the renderer's agreement with the crossing): a step along the normal leaves the solid,
    # one against it enters, away from the rims and the apex
    n = np.where(hits.entering[rows, slots, None] == (np.einsum("ij,ij->i", n, directions[rows]) < 0)[:, None], n, -n)
    n = n / np.linalg.norm(n, axis=1, keepdims=True)
    clear = (np.abs(np.abs(z) - 1.0) > 1e-3) & (np.linalg.norm(p, axis=1) > 1e-3)
    assert not np.any(_inside(p + 1e-6 * n, waist)[clear])
    assert np.all(_inside(p - 1e-6 * n, waist)[clear])


def test_known_hits_on_both_backends(backend):
    scene = scene_of(hyperboloid(0.5))
    # Down the axis: in through the top cap, out through the bottom one.
    assert ray_hits(scene, (0, 0, 5), (0, 0, -1), backend) == [(4.0, True), (6.0, False)]
    # Across the waist: the wall at x = -1/2 and 1/2.
    assert ray_hits(scene, (-5, 0, 0), (1, 0, 0), backend) == [(4.5, True), (5.5, False)]
    # Up a line at radius 3/4, outside the waist: in at the bottom cap, out of the wall where
    # 9/16 = 1/4 + 3/4 z^2, in again above the waist, out at the top cap.
    z = math.sqrt((0.75 ** 2 - 0.25) / 0.75)
    got = ray_hits(scene, (0.75, 0, -5), (0, 0, 1), backend)
    assert [e for _, e in got] == [True, False, True, False]
    assert [t for t, _ in got] == pytest.approx([4.0, 5 - z, 5 + z, 6.0], abs=1e-12)
    # Above the top, beside the wall: nothing.
    assert ray_hits(scene, (-5, 0, 1.5), (1, 0, 0), backend) == []
    assert ray_hits(scene, (1.5, 0, -5), (0, 0, 1), backend) == []
    # The waist is the parameter: S = 1 is the cylinder of radius 1.
    assert ray_hits(scene_of(hyperboloid(1.0)), (-5, 0, 0.3), (1, 0, 0), backend) == [(4.0, True), (6.0, False)]


def test_c_hits_equal_numpy_hits_bit_for_bit_on_hard_lines():
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    from test_native import _core, assert_same_hits

    through = [((0, 0, 5), (0, 0, -1)), ((0.75, 0, -5), (0, 0, 1)),  # down the axis; twice through
               ((-5, 0.3, 0), (1, 0, 0)), ((-3, 0.2, 3), (1, 0, -1)),  # across the waist; in through a cap
               ((0.2, 0.1, 5), (1e-9, 0, -1)), ((0.3, 0.3, 0.5), (0, 1, 0))]  # nearly vertical; from inside
    # Lines that only touch the surface (or, for S = 0, run along it): whether they hit rests on the last bit
    # of the generic line, so both backends must get the same one: the identity matrix.
    touching = [((1, 0, -5), (0, 0, 1)), ((-5, 0, 1), (1, 0, 0)),  # along the rim; along the top cap's plane
                ((-5, 0.5, 0), (1, 0, 0)), ((0.5, -5, 0), (0, 1, 0)),  # tangent at the waist (S = 0.5)
                ((-3, 0, -3), (1, 0, 1)), ((0, 0, 0), (1, 0, 1))]  # along the double cone (S = 0); its apex
    matrix = translation(0.3, -1.0, 2.0) @ rotation(35, 1, 2, 0) @ scaling(1.5, 0.7, 2.0)
    for waist in WAISTS:
        compiled, core = _core(scene_of(hyperboloid(waist)))
        for o, d in through + touching:  # the identity: both backends trace the same generic line, bit for bit
            o, d = np.asarray(o, float), np.asarray(d, float)
            want, got = compiled.objects[0].intersect(o[None], d[None]), core.object_hits(0, o, d)
            finite = np.isfinite(want.t[0])
            assert want.t[0][finite].tobytes() == got.t[0].tobytes(), (waist, o, d)
            assert np.array_equal(want.entering[0][finite], got.entering[0])
            assert want.normal[0][finite].tobytes() == got.normal[0].tobytes()
            assert np.array_equal(want.part[0][finite], got.part[0])
        compiled, core = _core(scene_of(hyperboloid(waist, matrix)))
        for o, d in through[1:] if waist == 0.0 else through:  # (the axis meets the double cone at its apex)
            o, d = np.asarray(o, float), np.asarray(d, float)
            assert_same_hits(compiled, core, matrix[:3, :3] @ o + matrix[:3, 3], matrix[:3, :3] @ d)


def test_both_sdl_readers_read_it_and_the_writer_writes_it_back():
    text = "translate 1 2 3 ! name: glass\nhyperboloid 0.25 hyperboloid 1.5"
    slow = tracer.parse_sdl(text)
    fast = fastread.read(text)
    if native.load_error is None:
        assert fast is not None  # the C reader reads the keyword with its number, from the registry
        assert [(s.kind, s.parameters, s.name) for s in fast.objects] == \
            [(s.kind, s.parameters, s.name) for s in slow.objects]
    assert [(s.kind, s.parameters) for s in slow.shapes()] == [("hyperboloid", (0.25,)), ("hyperboloid", (1.5,))]
    written = write_sdl(slow)
    assert "hyperboloid 0.25" in written and "hyperboloid 1.5" in written
    again = tracer.parse_sdl(written)
    assert [(s.kind, s.parameters) for s in again.shapes()] == [("hyperboloid", (0.25,)), ("hyperboloid", (1.5,))]
    assert np.array_equal(again.shapes()[0].matrix, slow.shapes()[0].matrix)
    with pytest.raises(tracer.SDLError, match="expected 'hyperboloid S'"):
        tracer.parse_sdl("hyperboloid sphere")


def test_usd_round_trip_keeps_the_exact_shape_and_its_waist(tmp_path):
    scene = scene_of(hyperboloid(0.3, translation(1, 2, 3) @ scaling(2, 2, 1)))
    path = tmp_path / "h.usda"
    save_usd(scene, path)
    back = load_usd(path)
    assert [(s.kind, s.parameters) for s in back.shapes()] == [("hyperboloid", (0.3,))]
    assert np.allclose(back.shapes()[0].matrix, scene.shapes()[0].matrix, atol=1e-12)
    text = path.read_text()
    assert '"hyperboloid"' in text and "sdl:waistRadius = 0.3" in text


@pytest.mark.parametrize("waist", WAISTS)
def test_tessellation_is_closed_outward_and_on_the_surface(waist):
    data = hyperboloid_mesh(waist)
    v = data.vertices
    k = 1.0 - waist * waist
    wall = np.abs(np.abs(v[:, 2]) - 1.0) > 0  # (the caps' rims are on the wall too)
    assert np.max(np.abs((v[:, 0] ** 2 + v[:, 1] ** 2 - k * v[:, 2] ** 2 - waist * waist)[wall])) < 1e-15
    assert_closed_and_outward(data)
    rows = np.zeros((1, shapes.MAX_PARAMETERS))
    rows[0, 0] = waist
    box = shapes.KINDS["hyperboloid"].function("bounds")(rows)[0]
    assert np.all((v >= box.min(axis=0) - 1e-15) & (v <= box.max(axis=0) + 1e-15))


def test_the_mapping_runs_up_the_wall_from_the_bottom():
    points = np.array([[1.0, 0.0, -1.0], [0.0, 0.5, 0.0], [1.0, 0.0, 1.0], [0.2, -0.4, 1.0]])
    u, v, wrap_u, wrap_v = hyperboloid_uv(points, np.array([0, 0, 0, 2]))
    assert v.tolist() == [0.0, 0.5, 1.0, 0.3] and u.tolist()[:2] == [0.0, 0.25] and u[3] == 0.6
    assert (wrap_u, wrap_v) == (True, False)


def test_blender_adds_imports_and_exports_it_with_its_waist(tmp_path):
    bpy = pytest.importorskip("bpy")
    from addon import exporter, importer, operators
    from addon.pure import convert
    from blender_scripts.addon_env import fresh, shape_objects

    assert "hyperboloid" in [item[0] for item in operators.SHAPE_ITEMS]  # in the Add menu
    fresh()
    bpy.ops.object.sdl_add_shape(kind="hyperboloid", waist=0.375)  # (a float32 property: 0.375 exactly)
    [obj] = shape_objects()
    assert obj["sdl_kind"] == "hyperboloid" and obj["sdl_param"] == pytest.approx(0.375)
    drawn = np.array([v.co for v in obj.data.vertices])
    assert len(obj.data.polygons) == len(hyperboloid_mesh(0.375).faces)
    assert np.allclose(drawn, hyperboloid_mesh(0.375).vertices, atol=1e-6)  # float32 in Blender
    path = tmp_path / "added.sdl"
    exporter.export_sdl(bpy.context, str(path), convert.axis_matrix("-Z", "Y"), use_selection=False)
    assert [(s.kind, s.parameters) for s in tracer.load(str(path)).shapes()] == [("hyperboloid", (0.375,))]
    # imported: an exact generic shape again, its mesh named by its waist
    fresh()
    path.write_text("hyperboloid 0.5 translate 3 0 0 hyperboloid 0.5")
    importer.import_sdl(bpy.context, str(path))
    objects = shape_objects()
    assert [o["sdl_param"] for o in objects] == [0.5, 0.5] and objects[0].data is objects[1].data
    assert objects[0].data.name == "SDL hyperboloid 0.5"


def test_textured_render_is_the_same_on_both_backends():
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    glass = hyperboloid(0.4, rotation(-70, 1, 0, 0) @ scaling(1.5, 1.5, 1.5), texture=-1, parameters=(0.25,),
                        diffuse=(0.9, 0.5, 0.2))
    scene = scene_of(glass, lights=[Light((4, 6, 8), (1, 1, 1))], camera=Camera((0, 1, 6), (0, 0, 0), (0, 1, 0), 45))
    assert "shape:hyperboloid" in compile_scene(scene).effects
    c = render(scene, 64, 48, backend="c")
    n = render(scene, 64, 48, backend="numpy")
    assert c.backend == "c" and n.backend == "numpy"
    diff = np.abs(c.image.astype(float) - n.image.astype(float))
    assert diff.max() <= 1.0 / 255.0 + 1e-12
    covered = np.ptp(c.image.reshape(-1, c.image.shape[-1]), axis=0).max()
    assert covered > 0.2  # the shape is in view: not an empty image


@pytest.mark.parametrize("value", ["nan", "inf", "-inf"])
def test_a_usd_waist_that_is_not_a_number_is_refused_naming_the_prim(tmp_path, value):
    """SDL's reader refuses `hyperboloid nan`; a stage's sdl:waistRadius (or any kind's parameter) of nan or
    inf is refused too, one error naming the file and prim, rather than a shape that silently draws nothing."""
    from tracer.errors import TracerError
    path = tmp_path / "h.usda"
    save_usd(scene_of(hyperboloid(0.3, translation(1, 2, 3))), path)
    path.write_text(path.read_text().replace("sdl:waistRadius = 0.3", f"sdl:waistRadius = {value}"))
    with pytest.raises(TracerError, match="not a finite number") as err:
        load_usd(path)
    assert "h.usda" in str(err.value) and "hyperboloid" in str(err.value)
    assert load_usd(path, strict=False).shapes() == []
