"""The physical lights of Blender scenes (docs/tracer.md, "Lights"): each against its formula on both backends
(falloff, Blender's spot cone, sun, area light irradiance, soft-shadow penumbrae against the analytic share of
a disk behind an edge), C = NumPy bit for bit, shadow rays counted, and the SDL statements both ways with
names."""
from __future__ import annotations

import dataclasses
import math
import os
from pathlib import Path

import numpy as np
import pytest

import tracer
from helpers import Light, scaled, scene_of, shape
from tracer.backend import make_tracer
from tracer.compile import compile_scene
from tracer.errors import SceneError, SDLError
from tracer.model import Camera
from tracer.sdl.parser import parse_sdl
from tracer.sdl.writer import save_sdl
from tracer.transforms import rotation, scaling, translation

#: Under make sanitize (ASan's runtime preloaded) usd-core cannot be loaded: its C++ exceptions abort.
needs_usd = pytest.mark.skipif("libasan" in os.environ.get("LD_PRELOAD", ""),
                               reason="under make sanitize: usd-core's C++ exceptions abort with ASan's runtime")
SCENES = Path(__file__).resolve().parent.parent / "scenes"
WHITE = dict(ambient=(0.0, 0.0, 0.0), diffuse=(1.0, 1.0, 1.0))


def floor(**material):
    """The plane y = 0 as a big square facing +y."""
    return shape("square", translation(0, 0, 0) @ rotation(-90, 1, 0, 0) @ scaling(50, 50, 1),
                 **{**WHITE, **material})


def shade_down(backend, scene, xs, zs=(0.0,), height=5.0):
    """Colours of rays shot straight down at floor points (x, 0, z) for x in xs, z in zs: (len(zs), len(xs), 3);
    and the tracer (for its ray counts)."""
    compiled = compile_scene(scene)
    t = make_tracer(compiled, backend, threads=1)
    x, z = np.meshgrid(np.asarray(xs, float), np.asarray(zs, float))
    origins = np.stack([x.ravel(), np.full(x.size, height), z.ravel()], axis=1)
    directions = np.tile([0.0, -1.0, 0.0], (x.size, 1))
    return t.camera_rays(origins, directions).reshape(len(zs), len(xs), 3), t


def lit(*lights, objects=(), **settings):
    return scene_of(floor(), *objects, lights=list(lights), background=(0.0, 0.0, 0.0),
                    global_ambient=(0.0, 0.0, 0.0), **settings)


# ------------------------------------------------------------------------------------------------ formulas


def test_sphere_light_falls_off_as_inverse_square(backend):
    xs = np.linspace(-4, 4, 17)
    colour, t = shade_down(backend, lit(Light((0.5, 2.0, 0.0), (3.0, 2.0, 1.0), kind="sphere")), xs)
    r2 = (xs - 0.5) ** 2 + 4.0
    expected = np.outer(2.0 / np.sqrt(r2) / r2, (3.0, 2.0, 1.0))  # colour * cos / r^2
    np.testing.assert_allclose(colour[0], expected, rtol=1e-12)
    assert t.counts.shadow == len(xs)  # one feeler per point: no radius, no soft shadow


def test_sdl_point_light_keeps_no_falloff(backend):
    xs = np.linspace(-4, 4, 9)
    colour, _ = shade_down(backend, lit(Light((0.0, 2.0, 0.0), (1.0, 1.0, 1.0))), xs)
    np.testing.assert_allclose(colour[0, :, 0], 2.0 / np.sqrt(xs ** 2 + 4.0), rtol=1e-12)


def blender_spot(cos_alpha, size_degrees, blend):
    """Blender (Cycles 4.x)'s spot attenuation: smoothstep of (cos a - cos(size/2)) / ((1 - cos(size/2)) blend)."""
    cos_half = math.cos(math.radians(size_degrees) / 2)
    if cos_alpha <= cos_half:
        return 0.0
    if blend == 0:
        return 1.0
    t = min(1.0, (cos_alpha - cos_half) / ((1 - cos_half) * blend))
    return t * t * (3 - 2 * t)


@pytest.mark.parametrize("size, blend", [(60.0, 0.3), (90.0, 1.0), (45.0, 0.0)])
def test_spot_cone_is_blenders_smoothstep(backend, size, blend):
    height = 3.0
    xs = np.linspace(0.0, 3.0, 61)
    spot = Light((0.0, height, 0.0), (1.0, 1.0, 1.0), kind="spot", direction=(0.0, -2.0, 0.0), spot_size=size,
                 spot_blend=blend)
    colour, t = shade_down(backend, lit(spot), xs)
    r2 = xs ** 2 + height ** 2
    cos = height / np.sqrt(r2)
    expected = np.array([blender_spot(c, size, blend) for c in cos]) * cos / r2
    np.testing.assert_allclose(colour[0, :, 0], expected, rtol=1e-9, atol=1e-15)
    assert t.counts.shadow == int(np.count_nonzero(expected > 0))  # no feelers outside the cone


def test_sun_lights_by_the_cosine_without_falloff(backend):
    sun = Light((0.0, 0.0, 0.0), (0.5, 0.5, 0.5), kind="sun", direction=(1.0, -2.0, 0.0))
    colour, _ = shade_down(backend, lit(sun), np.linspace(-10, 10, 5))
    np.testing.assert_allclose(colour[0, :, 0], 0.5 * 2.0 / math.sqrt(5.0), rtol=1e-12)


def corner_integral(a, b, h):
    """The integral of cos cos / r^2 over a rectangle [0, a] x [0, b] parallel to the receiver at height h,
    with a corner over the receiving point (pi times the point-to-rectangle form factor)."""
    A, B = a / h, b / h
    return 0.5 * (A / math.hypot(1, A) * math.atan(B / math.hypot(1, A))
                  + B / math.hypot(1, B) * math.atan(A / math.hypot(1, B)))


def test_area_light_irradiance_matches_the_form_factor(backend):
    width, height, above = 2.0, 1.0, 1.5
    area = Light((0.0, above, 0.0), (1.0, 1.0, 1.0), kind="area", direction=(0, -1, 0), axis=(1, 0, 0),
                 size=(width, height), samples=256)
    colour, t = shade_down(backend, lit(area), [0.0])
    expected = 4 * corner_integral(width / 2, height / 2, above)
    assert colour[0, 0, 0] == pytest.approx(expected, rel=2e-3)
    assert t.counts.shadow == 256
    # one-sided: from behind it gives nothing
    back = Light((0.0, above, 0.0), (1.0, 1.0, 1.0), kind="area", direction=(0, 1, 0), size=(width, height))
    assert shade_down(backend, lit(back), [0.0])[0].max() == 0.0


def test_ellipse_light_of_small_size_is_a_point_light_of_its_area(backend):
    d = 0.02
    disk = Light((0.0, 3.0, 0.0), (1.0, 1.0, 1.0), kind="area", shape="ellipse", direction=(0, -1, 0),
                 size=(d, d), samples=16)
    colour, _ = shade_down(backend, lit(disk), [0.0, 1.0])
    area = math.pi * d * d / 4
    expected = area * np.array([1 / 9, (3 / math.sqrt(10)) ** 2 / 10])  # cos_x cos_l / r^2
    np.testing.assert_allclose(colour[0, :, 0], expected, rtol=1e-3)  # (its finite size: ~(d/r)^2)


#: Cycles' direct light (bpy 4.5: Cycles, 256 samples, no bounces, Standard view, a white Diffuse BSDF floor 2
#: units below each light, the linear value straight below it), as docs/tracer.md gives them.
CYCLES_BELOW = [("point 100 W", 0.6332, dict(kind="sphere", color=100 / (4 * math.pi ** 2))),
                ("point 100 W radius 0.5", 0.5960, dict(kind="sphere", radius=0.5, color=100 / (4 * math.pi ** 2))),
                ("point 100 W radius 1", 0.5066, dict(kind="sphere", radius=1.0, color=100 / (4 * math.pi ** 2))),
                ("point 100 W radius 1.5", 0.4053, dict(kind="sphere", radius=1.5, color=100 / (4 * math.pi ** 2))),
                ("sun 1", 0.3183, dict(kind="sun", color=1 / math.pi)),
                ("area 100 W 0.1 square", 2.5308, dict(kind="area", size=(0.1, 0.1), color=100 / (math.pi ** 2 * 0.01))),
                ("area 100 W 1 square", 2.3386, dict(kind="area", size=(1.0, 1.0), color=100 / math.pi ** 2))]


@pytest.mark.parametrize("what, cycles, light", CYCLES_BELOW, ids=[c[0] for c in CYCLES_BELOW])
def test_blender_lights_in_the_documented_units_light_as_cycles_does(backend, what, cycles, light):
    light = dict(light)  # (the parameters are shared by both backends' runs)
    grey = light.pop("color")
    light = Light((0.0, 2.0, 0.0), (grey, grey, grey), direction=(0.0, -1.0, 0.0), samples=256, **light)
    colour, _ = shade_down(backend, lit(light), [0.0])
    assert colour[0, 0, 0] == pytest.approx(cycles, rel=2e-3)


#: Cycles' 100 W spot 2 units above the floor pointing down (as above), at floor points seen at angle alpha from
#: its axis: (alpha, spot size, blend, value).
CYCLES_SPOT = [(25.0, 60.0, 0.5, 0.30631), (20.0, 60.0, 0.5, 0.52545), (28.0, 60.0, 0.5, 0.06956),
               (10.0, 45.0, 0.0, 0.60482)]


@pytest.mark.parametrize("alpha, size, blend, cycles", CYCLES_SPOT)
def test_spot_lights_as_cycles_does(backend, alpha, size, blend, cycles):
    spot = Light((0.0, 2.0, 0.0), (100 / (4 * math.pi ** 2),) * 3, kind="spot", direction=(0.0, -1.0, 0.0),
                 spot_size=size, spot_blend=blend)
    colour, _ = shade_down(backend, lit(spot), [2.0 * math.tan(math.radians(alpha))])
    assert colour[0, 0, 0] == pytest.approx(cycles, rel=3e-3)  # (Cycles averaged a pixel 0.0025 wide)


# ------------------------------------------------------------------------------------------------ penumbrae


def segment_share(a, radius):
    """The share of a disk of ``radius`` beyond the chord at distance ``a`` from its centre (a < 0: more than
    half)."""
    a = max(-radius, min(radius, a))
    return (radius * radius * math.acos(a / radius) - a * math.sqrt(radius * radius - a * a)) / (math.pi * radius ** 2)


def edge_blocker(height):
    """A thin sheet at ``height`` covering x < 0 (its edge along z at x = 0)."""
    return shape("square", translation(-20, height, 0) @ rotation(-90, 1, 0, 0) @ scaling(20, 20, 1), **WHITE)


def visible_along(backend, light, xs, height_of_edge, samples_at=None):
    scene = lit(light, objects=[edge_blocker(height_of_edge)])
    bare = lit(light)
    zs = np.linspace(-1.0, 1.0, 41)
    shaded, t = shade_down(backend, scene, xs, zs, height=height_of_edge - 0.01)
    full, _ = shade_down(backend, bare, xs, zs, height=height_of_edge - 0.01)
    return (shaded[..., 0] / full[..., 0]).mean(axis=0), t


def test_sun_penumbra_is_the_share_of_its_disk_past_the_edge(backend):
    angle, h = 6.0, 1.0
    sun = Light((0, 0, 0), (1.0, 1.0, 1.0), kind="sun", direction=(0, -1, 0), angle=angle, samples=32)
    xs = np.linspace(-0.08, 0.08, 17)
    share, t = visible_along(backend, sun, xs, h)
    radius = math.tan(math.radians(angle / 2))  # the sun's disk seen through the edge, at unit height
    expected = np.array([1 - segment_share(x / h, radius) for x in xs])
    np.testing.assert_allclose(share, expected, atol=0.03)
    assert share[0] == 0.0 and share[-1] == 1.0
    assert t.counts.shadow == 32 * 41 * len(xs)


def test_sphere_light_penumbra(backend):
    light_height, edge, radius = 4.0, 1.0, 0.5
    light = Light((0, light_height, 0), (1.0, 1.0, 1.0), kind="sphere", radius=radius, samples=32)
    xs = np.linspace(-0.25, 0.25, 11)
    share, _ = visible_along(backend, light, xs, edge)
    # a floor point at x sees the light's disk cut by the edge's line at u = -x (H - h) / h
    expected = np.array([1 - segment_share(x * (light_height - edge) / edge, radius) for x in xs])
    np.testing.assert_allclose(share, expected, atol=0.04)


def test_area_light_penumbra(backend):
    light_height, edge, side = 4.0, 1.0, 1.0
    area = Light((0, light_height, 0), (1.0, 1.0, 1.0), kind="area", direction=(0, -1, 0), size=(side, side),
                 samples=64)
    xs = np.linspace(-0.2, 0.2, 9)
    share, _ = visible_along(backend, area, xs, edge)
    # the strip of the square (seen from nearly below) past the edge's line, weighted nearly evenly
    cut = np.clip(0.5 - xs * (light_height - edge) / edge / side, 0.0, 1.0)
    np.testing.assert_allclose(share, 1.0 - cut, atol=0.04)


# ------------------------------------------------------------------------------------------------ backends


def showcase():
    return parse_sdl("""background 0 0 0 globalAmbient 0.05 0.05 0.05
camera 0 5 7  0 0.5 0  0 1 0 50
sphereLight -2 3 1 6 6 6 0.4 8
spotLight 2 4 0 -0.3 -1 0 8 8 8 50 0.3 0.2 6
sunLight 1 -2 -1 0.3 0.3 0.25 5 5
areaLight 0 3.5 -2 0 -1 0.3 1 0 0 3 3 3 1.5 0.8 9
ellipseLight -2 2 -2 0.5 -1 0.5 1 0 0 2 1 1 1 0.6 4
light 0 6 6 0.2 0.2 0.2
ambient 0.2 0.2 0.2 diffuse 0.8 0.7 0.6 specular 0.5 0.5 0.5 specularExponent 30
push translate 0 1 0 sphere pop
push translate -1.5 0.5 1 scale 0.5 0.5 0.5 cube pop
push rotate -90 1 0 0 scale 10 10 1 square pop
reflectivity 0.8 push translate 1.5 0.6 1.2 scale 0.6 0.6 0.6 sphere pop
""")


def test_c_and_numpy_agree_bit_for_bit_with_every_light():
    from tracer import native
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    scene = showcase()
    c = tracer.render(scene, 80, 60, backend="c")
    n = tracer.render(scene, 80, 60, backend="numpy")
    assert np.array_equal(c.image, n.image)
    assert c.rays.as_dict() == n.rays.as_dict() and c.rays.skipped() == n.rays.skipped()
    assert {"physical-lights", "soft-shadows", "seen-lights"} <= set(c.stats()["effects"])


def test_renders_are_reproducible_and_tile_independent(backend):
    scene = showcase()
    w, h = scaled(backend, 64, 48)
    one = tracer.render(scene, w, h, backend=backend)
    tiled = tracer.render(scene, w, h, backend=backend, block_size=4, progressive=True)
    assert np.array_equal(one.image, tiled.image)


def test_only_scenes_with_physical_lights_pay_for_them():
    effects = compile_scene(lit(Light((0, 3, 0), (1, 1, 1)))).effects
    assert not effects & {"physical-lights", "soft-shadows"}
    hard = compile_scene(lit(Light((0, 3, 0), (1, 1, 1), kind="sphere", samples=16))).effects
    assert "physical-lights" in hard and "soft-shadows" not in hard  # (no radius: one feeler, samples unused)


# ------------------------------------------------------------------------------------------------ seen lights

MIRROR = dict(ambient=(0.0, 0.0, 0.0), diffuse=(0.0, 0.0, 0.0), specular=(0.0, 0.0, 0.0), reflectivity=1.0)
GLOW = (0.1, 0.2, 0.05)


def overhead_panel(direction=(0, -1, 0)):
    """A 2 x 1 area light 1.5 above a mirror floor, facing down."""
    return Light((0.0, 1.5, 0.0), GLOW, kind="area", direction=direction, axis=(1, 0, 0), size=(2.0, 1.0),
                 samples=4)


def test_a_mirror_shows_an_area_light_as_cycles_does(backend):
    """A ray reflected up from the mirror meets the panel's front: it sees pi times the light's colour (its
    radiance; a white diffuse surface under a sky of it would look the same), only where the panel is."""
    scene = scene_of(floor(**MIRROR), lights=[overhead_panel()], background=(0.0, 0.0, 0.0),
                     global_ambient=(0.0, 0.0, 0.0))
    colour, t = shade_down(backend, scene, [-0.9, 0.0, 0.9, 1.1], zs=(0.0, 0.45, 0.55))
    panel = np.pi * np.array(GLOW)
    for row, z in enumerate((0.0, 0.45, 0.55)):
        for column, x in enumerate((-0.9, 0.0, 0.9, 1.1)):
            expected = panel if abs(x) <= 1.0 and abs(z) <= 0.5 else np.zeros(3)
            np.testing.assert_array_equal(colour[row, column], expected, err_msg=f"x {x} z {z}")


def test_the_camera_and_the_back_of_a_panel_do_not_see_it(backend):
    scene = scene_of(floor(**MIRROR), lights=[overhead_panel()], background=(0.0, 0.0, 0.0),
                     global_ambient=(0.0, 0.0, 0.0))
    t = make_tracer(compile_scene(scene), backend, threads=1)
    looking_up = t.camera_rays(np.array([[0.0, 0.5, 0.0]]), np.array([[0.0, 1.0, 0.0]]))
    assert looking_up.max() == 0.0  # (Cycles' area lights are not seen by the camera)
    upside_down = scene_of(floor(**MIRROR), lights=[overhead_panel(direction=(0, 1, 0))],
                           background=(0.0, 0.0, 0.0), global_ambient=(0.0, 0.0, 0.0))
    colour, _ = shade_down(backend, upside_down, [0.0])
    assert colour.max() == 0.0  # (its back is not seen, as it does not light that way)


def test_an_object_in_front_of_the_panel_hides_it(backend):
    ball = shape("sphere", translation(0, 1.0, 0) @ scaling(0.2, 0.2, 0.2), ambient=(0, 0, 0), diffuse=(0, 0, 0),
                 specular=(0, 0, 0))
    scene = scene_of(floor(**MIRROR), ball, lights=[overhead_panel()], background=(0.0, 0.0, 0.0),
                     global_ambient=(0.0, 0.0, 0.0))
    colour, _ = shade_down(backend, scene, [0.0, 0.5], height=0.5)
    np.testing.assert_array_equal(colour[0, 0], np.zeros(3))  # (the ball, black, is nearer)
    np.testing.assert_array_equal(colour[0, 1], np.pi * np.array(GLOW))


def test_only_scenes_that_can_see_an_area_light_pay_for_it():
    assert "seen-lights" not in compile_scene(lit(overhead_panel())).effects  # (nothing reflects)
    assert "seen-lights" not in compile_scene(scene_of(floor(**MIRROR), lights=[Light((0, 3, 0), (1, 1, 1))])).effects
    assert "seen-lights" in compile_scene(scene_of(floor(**MIRROR), lights=[overhead_panel()])).effects


# ------------------------------------------------------------------------------------------------ switches
# (Cycles' per-light switches: Cast Shadow, Ray Visibility's Diffuse, Glossy, Transmission; docs/tracer.md)

SWITCHES = ("cast_shadow", "visible_diffuse", "visible_glossy", "visible_transmission")


def shade_rays(backend, scene, origins, directions):
    """Colours of camera rays (N, 3), and the tracer (for its ray counts)."""
    t = make_tracer(compile_scene(scene), backend, threads=1)
    return t.camera_rays(np.asarray(origins, float), np.asarray(directions, float)), t


def switched(light, *off):
    """The light with the switches ``off`` off."""
    return dataclasses.replace(light, **{name: False for name in off})


def switch_showcase(*lights):
    """A mirror floor, a glass ball under an area light, a diffuse cube, a shiny ball, a Cook-Torrance ball;
    lit by ``lights`` (default: the area light, an SDL point light and a soft sphere light)."""
    glass = dict(ambient=(0, 0, 0), diffuse=(0, 0, 0), reflectivity=1.0, transparency=1.0, speed_of_light=1 / 1.5,
                 fresnel="dielectric")
    objects = [floor(ambient=(0.1, 0.1, 0.1), diffuse=(0.3, 0.3, 0.3), reflectivity=0.6),
               shape("sphere", translation(0.2, 0.9, 0.2) @ scaling(0.6, 0.6, 0.6), **glass),
               shape("cube", translation(1.6, 0.5, -1.0) @ scaling(0.5, 0.5, 0.5), diffuse=(0.8, 0.5, 0.3)),
               shape("sphere", translation(1.3, 0.6, 1.4) @ scaling(0.6, 0.6, 0.6), diffuse=(0.2, 0.2, 0.6),
                     specular=(0.8, 0.8, 0.8), specular_exponent=40.0),
               shape("sphere", translation(-1.5, 0.6, 1.2) @ scaling(0.6, 0.6, 0.6), diffuse=(0.5, 0.2, 0.2),
                     specular=(0.6, 0.6, 0.6), specular_fraction=0.7, surface_roughness=0.3)]
    lights = lights or (Light((0.0, 2.8, 0.0), (2.0, 2.0, 2.0), kind="area", direction=(0, -1, 0), axis=(1, 0, 0),
                              size=(2.0, 1.5), samples=4),
                        Light((-3.0, 5.0, 4.0), (0.4, 0.4, 0.4)),
                        Light((3.0, 4.0, 3.0), (12.0, 12.0, 12.0), kind="sphere", radius=0.3, samples=4))
    return scene_of(*objects, lights=list(lights), camera=Camera((0.0, 3.0, 6.0), (0.0, 0.5, 0.0), view_angle=50.0),
                    background=(0.1, 0.1, 0.2), global_ambient=(0.05, 0.05, 0.05))


CASES = [(name,) for name in SWITCHES] + [("visible_diffuse", "visible_glossy"), ("mixed",)]


@pytest.mark.parametrize("off", CASES, ids=["+".join(case) for case in CASES])
def test_switched_off_lights_trace_alike_on_both_backends(off):
    from tracer import native
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    lights = switch_showcase().lights
    if off == ("mixed",):  # (each light another switch off)
        lights = [switched(lights[0], "visible_glossy", "cast_shadow"), switched(lights[1], "visible_diffuse"),
                  switched(lights[2], "cast_shadow", "visible_glossy")]
    else:
        lights = [switched(light, *off) for light in lights]
    scene = switch_showcase(*lights)
    c = tracer.render(scene, 64, 48, backend="c")
    n = tracer.render(scene, 64, 48, backend="numpy")
    assert np.array_equal(c.image, n.image)
    assert c.rays.as_dict() == n.rays.as_dict() and c.rays.skipped() == n.rays.skipped()
    effects = set(c.stats()["effects"])
    if off == ("cast_shadow",):  # (no light casts shadows: neither shadows nor switches to read)
        assert not effects & {"shadows", "light-switches"}
    else:
        assert "light-switches" in effects
    default = tracer.render(switch_showcase(), 64, 48, backend="c")
    assert not np.array_equal(c.image, default.image)  # (the switch changes the picture)
    dark = {"visible_diffuse", "visible_glossy"} <= set(off)  # (lights that add nothing send no feelers)
    assert (c.rays.shadow == 0) == ("cast_shadow" in off or dark)


def occluded_floor(light, xs, with_occluder=True, backend="numpy"):
    """Rays down at the floor under a light 3 above it, from below a black ball that stands in the way of the
    light at x = 0."""
    ball = shape("sphere", translation(0, 2.0, 0) @ scaling(0.4, 0.4, 0.4), ambient=(0, 0, 0), diffuse=(0, 0, 0))
    scene = lit(light, objects=[ball] if with_occluder else [])
    return shade_down(backend, scene, xs, height=1.0)


LIGHTS_ABOVE = {
    "point": Light((0.0, 3.0, 0.0), (1.0, 1.0, 1.0)),
    "sphere": Light((0.0, 3.0, 0.0), (9.0, 9.0, 9.0), kind="sphere", radius=0.2, samples=8),
    "spot": Light((0.0, 3.0, 0.0), (9.0, 9.0, 9.0), kind="spot", direction=(0, -1, 0), spot_size=120.0),
    "sun": Light((0.0, 0.0, 0.0), (1.0, 1.0, 1.0), kind="sun", direction=(0, -1, 0), angle=2.0, samples=8),
    "area": Light((0.0, 3.0, 0.0), (16.0, 16.0, 16.0), kind="area", direction=(0, -1, 0), size=(0.5, 0.5),
                  samples=8),
}


@pytest.mark.parametrize("kind", sorted(LIGHTS_ABOVE))
def test_a_light_that_casts_no_shadow_lights_a_point_behind_an_occluder(backend, kind):
    xs = [0.0, 0.05, 1.5]
    light = LIGHTS_ABOVE[kind]
    shadowed, t = occluded_floor(light, xs, backend=backend)
    assert shadowed[0, 0].max() == 0.0 and t.counts.shadow > 0  # (in the ball's shadow)
    free, t = occluded_floor(switched(light, "cast_shadow"), xs, backend=backend)
    clear, _ = occluded_floor(light, xs, with_occluder=False, backend=backend)
    assert free[0, 0].min() > 0.0
    np.testing.assert_array_equal(free, clear)  # (lit as if nothing were in the way)
    assert t.counts.shadow == 0


def test_only_the_lights_that_cast_shadows_send_feelers(backend):
    xs = np.linspace(-1, 1, 5)
    both = lit(switched(Light((0, 3, 0), (1, 1, 1)), "cast_shadow"), Light((1, 3, 0), (1, 1, 1)))
    _, t = shade_down(backend, both, xs)
    assert t.counts.shadow == len(xs)  # (the second light's only)
    assert {"shadows", "light-switches"} <= compile_scene(both).effects
    none = lit(*(switched(Light((x, 3, 0), (1, 1, 1)), "cast_shadow") for x in (0, 1)))
    colour, t = shade_down(backend, none, xs)
    assert t.counts.shadow == 0 and colour.min() > 0.0
    assert "shadows" not in compile_scene(none).effects  # (the scene pays nothing for shadows)
    assert "light-switches" not in compile_scene(none).effects  # (nor for reading switches that change nothing)


@pytest.mark.parametrize("kind", ["point", "sphere", "area"])
def test_a_light_left_out_of_diffuse_leaves_a_diffuse_surface_black(backend, kind):
    xs = np.linspace(-1, 1, 5)
    light = LIGHTS_ABOVE[kind]
    colour, _ = shade_down(backend, lit(light), xs)
    assert colour.min() > 0.0
    colour, t = shade_down(backend, lit(switched(light, "visible_diffuse")), xs)
    assert colour.max() == 0.0
    assert t.counts.shadow == 0 and t.counts.skipped_dark_material == len(xs)  # (no feeler for nothing)
    # beside another light it changes nothing of that one's light
    other = Light((0.5, 2.0, 0.0), (0.5, 0.5, 0.5))
    with_other, _ = shade_down(backend, lit(switched(light, "visible_diffuse"), other), xs)
    np.testing.assert_array_equal(with_other, shade_down(backend, lit(other), xs)[0])


SHINY = dict(ambient=(0.0, 0.0, 0.0), diffuse=(0.4, 0.4, 0.4), specular=(0.9, 0.9, 0.9), specular_exponent=30.0)
COOK_TORRANCE = dict(SHINY, specular_fraction=0.6, surface_roughness=0.2)


@pytest.mark.parametrize("kind", ["point", "sphere", "area"])
@pytest.mark.parametrize("material", [SHINY, COOK_TORRANCE], ids=["blinn", "cook-torrance"])
def test_a_light_left_out_of_glossy_leaves_no_highlight(backend, kind, material):
    xs = np.linspace(-0.5, 0.5, 5)
    light = LIGHTS_ABOVE[kind]
    shiny = scene_of(floor(**material), lights=[light], background=(0, 0, 0), global_ambient=(0, 0, 0))
    highlit, _ = shade_down(backend, shiny, xs)
    matte = scene_of(floor(**{**material, "specular": (0.0, 0.0, 0.0), "specular_fraction": 0.0}), lights=[light],
                     background=(0, 0, 0), global_ambient=(0, 0, 0))
    diffuse_only, _ = shade_down(backend, matte, xs)
    assert (highlit[0, 2] > diffuse_only[0, 2] + 0.1).all()  # (the highlight right under the light)
    shiny.lights = [switched(light, "visible_glossy")]
    np.testing.assert_array_equal(shade_down(backend, shiny, xs)[0], diffuse_only)
    # and the highlight alone where the light is left out of diffuse
    shiny.lights = [switched(light, "visible_diffuse")]
    glossy_only, _ = shade_down(backend, shiny, xs)
    assert (glossy_only[0, 2] > 0.1).all() and (glossy_only < highlit).all()


EMBER = (0.3, 0.2, 0.1)


def panel_under_a_ceiling(*off):
    """The mirror floor under overhead_panel (its switches ``off`` off), under an emissive ceiling 2.5 up."""
    ceiling = shape("square", translation(0, 2.5, 0) @ rotation(90, 1, 0, 0) @ scaling(50, 50, 1),
                    ambient=(0, 0, 0), diffuse=(0, 0, 0), emissive=EMBER)
    return scene_of(floor(**MIRROR), ceiling, lights=[switched(overhead_panel(), *off)], background=(0.0, 0.0, 0.0),
                    global_ambient=(0.0, 0.0, 0.0))


def test_a_light_left_out_of_glossy_is_not_seen_in_a_mirror(backend):
    xs, zs = [-0.9, 0.0, 0.9, 1.1], [0.0, 0.45, 0.55]
    panel = np.pi * np.array(GLOW)
    seen, _ = shade_down(backend, panel_under_a_ceiling(), xs, zs=zs, height=1.0)
    for row, z in enumerate(zs):
        for column, x in enumerate(xs):
            expected = panel if abs(x) <= 1.0 and abs(z) <= 0.5 else np.array(EMBER)
            np.testing.assert_array_equal(seen[row, column], expected, err_msg=f"x {x} z {z}")
    unseen, _ = shade_down(backend, panel_under_a_ceiling("visible_glossy"), xs, zs=zs, height=1.0)
    np.testing.assert_array_equal(unseen, np.broadcast_to(EMBER, unseen.shape))  # (the ceiling behind it)
    # (a mirror ray is no transmission ray)
    still, _ = shade_down(backend, panel_under_a_ceiling("visible_transmission"), xs, zs=zs, height=1.0)
    np.testing.assert_array_equal(still, seen)


def glass_slab_under_the_panel(*off):
    """A clear slab (transparency 1, the speed of light outside it: rays go straight through) between the floor
    and overhead_panel (its switches ``off`` off)."""
    slab = shape("cube", translation(0, 0.8, 0) @ scaling(3.0, 0.1, 3.0), ambient=(0, 0, 0), diffuse=(0, 0, 0),
                 transparency=1.0)
    return scene_of(slab, lights=[switched(overhead_panel(), *off)], background=BACKDROP,
                    global_ambient=(0.0, 0.0, 0.0))


BACKDROP = (0.05, 0.1, 0.15)


def test_a_light_left_out_of_transmission_is_not_seen_through_glass(backend):
    origins = [(x, 0.2, z) for x in (0.0, 0.9, 1.2) for z in (0.0, 0.4)]
    up = np.tile([0.0, 1.0, 0.0], (len(origins), 1))
    under = np.array([abs(x) <= 1.0 and abs(z) <= 0.5 for x, _, z in origins])
    seen, t = shade_rays(backend, glass_slab_under_the_panel(), origins, up)
    assert t.counts.refraction == 2 * len(origins)
    np.testing.assert_array_equal(seen[under], np.broadcast_to(np.pi * np.array(GLOW), seen[under].shape))
    np.testing.assert_array_equal(seen[~under], np.broadcast_to(BACKDROP, seen[~under].shape))
    unseen, _ = shade_rays(backend, glass_slab_under_the_panel("visible_transmission"), origins, up)
    np.testing.assert_array_equal(unseen, np.broadcast_to(BACKDROP, unseen.shape))
    still, _ = shade_rays(backend, glass_slab_under_the_panel("visible_glossy"), origins, up)
    np.testing.assert_array_equal(still, seen)  # (a refracted ray is no glossy ray)


def test_only_scenes_that_switch_something_off_read_the_switches():
    mirror_floor = floor(**{**MIRROR, "diffuse": (0.5, 0.5, 0.5)})
    bulb = Light((0, 3, 0), (1, 1, 1))
    assert "light-switches" not in compile_scene(scene_of(mirror_floor, lights=[overhead_panel(), bulb])).effects
    for off in SWITCHES:
        effects = compile_scene(scene_of(mirror_floor, lights=[switched(overhead_panel(), off), bulb])).effects
        # (a mirror alone has no refracted rays: the transmission switch changes nothing there)
        assert ("light-switches" in effects) == (off != "visible_transmission"), off
    wholly_off = compile_scene(lit(switched(Light((0, 3, 0), (1, 1, 1)), "visible_diffuse", "visible_glossy")))
    assert not wholly_off.effects & {"lighting", "shadows", "light-switches"}
    unseen = compile_scene(scene_of(floor(**MIRROR), lights=[switched(overhead_panel(), "visible_glossy")]))
    assert "seen-lights" not in unseen.effects  # (nothing in the scene can see it)


def test_editing_lights_to_switched_ones_renders_as_from_scratch(backend):
    from tracer.edit import EditableScene
    scene = switch_showcase()
    editable = EditableScene(scene)
    w, h = scaled(backend, 48, 36)
    tracer.render(editable.compiled, w, h, backend=backend)
    lights = [switched(light, off) for light, off in zip(scene.lights, ("visible_glossy", "cast_shadow",
                                                                         "visible_diffuse"))]
    editable.set_lights(lights)
    edited = tracer.render(editable.compiled, w, h, backend=backend)
    expected = tracer.render(switch_showcase(*lights), w, h, backend=backend)
    assert np.array_equal(edited.image, expected.image)
    assert edited.rays.as_dict() == expected.rays.as_dict()


# ------------------------------------------------------------------------------- seen sphere, spot and sun lights
# (docs/tracer.md, "Seen lights": Cycles' mirrors and glass show a point light's sphere and the sun's disk)

BULB = (0.3, 0.2, 0.1)
BULB_AT, BULB_RADIUS = (0.4, 3.0, -0.2), 0.5


def bulb(**fields):
    """A sphere light of radius 0.5 three units above the mirror floor."""
    return Light(**{"position": BULB_AT, "color": BULB, "kind": "sphere", "radius": BULB_RADIUS, "samples": 4,
                    **fields})


def over_a_mirror(*lights, objects=(), background=BACKDROP):
    return scene_of(floor(**MIRROR), *objects, lights=list(lights), background=background,
                    global_ambient=(0.0, 0.0, 0.0))


def seen_showcase(hidden=None):
    """A mirror floor and a glass ball (no highlights) under a sphere light, a spot light of some radius and a
    sun of 10 degrees, each seen in the floor and in the ball from the camera; light number ``hidden`` with
    visible_glossy and visible_transmission off."""
    ground = shape("square", rotation(-90, 1, 0, 0) @ scaling(20, 20, 1), ambient=(0.05, 0.05, 0.05),
                   diffuse=(0.2, 0.2, 0.2), specular=(0, 0, 0), reflectivity=0.7)
    glass = shape("sphere", translation(0.6, 0.7, 0.5) @ scaling(0.7, 0.7, 0.7), ambient=(0, 0, 0),
                  diffuse=(0, 0, 0), specular=(0, 0, 0), reflectivity=1.0, transparency=1.0, speed_of_light=1 / 1.5,
                  fresnel="dielectric")
    lights = [Light((-1.6, 2.2, -1.5), (2.0, 1.8, 1.5), kind="sphere", radius=0.4, samples=4),
              Light((1.8, 2.0, -1.0), (3.0, 3.0, 2.0), kind="spot", radius=0.3, direction=(-0.3, -1.0, 0.4),
                    spot_size=80.0, spot_blend=0.4, samples=4),
              Light((0, 0, 0), (0.4, 0.35, 0.3), kind="sun", direction=(0.15, -0.3, 1.0), angle=10.0, samples=4)]
    if hidden is not None:
        lights[hidden] = switched(lights[hidden], "visible_glossy", "visible_transmission")
    return scene_of(ground, glass, lights=lights, camera=Camera((0.0, 2.0, 6.0), (0.0, 0.6, 0.0), view_angle=50.0),
                    background=(0.02, 0.03, 0.05), global_ambient=(0.05, 0.05, 0.05))


def test_c_and_numpy_agree_bit_for_bit_where_spheres_spots_and_suns_are_seen():
    from tracer import native
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    c = tracer.render(seen_showcase(), 96, 72, backend="c")
    n = tracer.render(seen_showcase(), 96, 72, backend="numpy")
    assert np.array_equal(c.image, n.image)
    assert c.rays.as_dict() == n.rays.as_dict() and c.rays.skipped() == n.rays.skipped()
    assert {"seen-lights", "reflection", "refraction"} <= set(c.stats()["effects"])
    for index in range(3):  # (each light is seen: hidden from mirrors and glass, the picture changes)
        hidden = seen_showcase(hidden=index)
        c_hidden = tracer.render(hidden, 96, 72, backend="c")
        assert not np.array_equal(c_hidden.image, c.image), index
        assert np.array_equal(c_hidden.image, tracer.render(hidden, 96, 72, backend="numpy").image), index


def test_a_mirror_shows_a_sphere_light_as_a_disk_of_colour_over_radius_squared(backend):
    """Rays straight down at the mirror floor come back straight up: those from floor points within the
    light's radius of the point under its centre meet its sphere and see colour / r^2 (its radiance in the
    tracer's units), the others the background; the camera rays, which pass beside it, see nothing of it."""
    grid = np.linspace(-1.0, 1.0, 41) * 1.6 * BULB_RADIUS
    xs, zs = BULB_AT[0] + grid, BULB_AT[2] + grid[::4]
    colour, t = shade_down(backend, over_a_mirror(bulb()), xs, zs=zs, height=1.0)
    off_centre = np.hypot(*np.meshgrid(xs - BULB_AT[0], zs - BULB_AT[2]))
    assert np.abs(off_centre - BULB_RADIUS).min() > 1e-6  # (no point on the disk's rim)
    inside = off_centre < BULB_RADIUS
    assert 0.2 < inside.mean() < 0.6
    np.testing.assert_array_equal(colour[inside], np.broadcast_to(np.array(BULB) / BULB_RADIUS ** 2, colour[inside].shape))
    np.testing.assert_array_equal(colour[~inside], np.broadcast_to(BACKDROP, colour[~inside].shape))
    assert t.counts.reflection == inside.size
    # the units: the radiance seen, over the disk of its radius facing a point below it at distance x (Cycles'
    # sphere light), is the irradiance pi E there, E what the light gives a white diffuse floor at that point
    below, _ = shade_down(backend, lit(bulb()), [BULB_AT[0]], zs=[BULB_AT[2]], height=1.0)
    x2 = BULB_AT[1] ** 2
    np.testing.assert_allclose(colour[inside][0] * np.pi * BULB_RADIUS ** 2 / (x2 + BULB_RADIUS ** 2),
                               np.pi * below[0, 0], rtol=1e-12)


def test_a_mirror_shows_the_sphere_of_an_oblique_light_where_geometry_says(backend):
    """Rays from one eye fanned over the mirror floor: a reflected ray sees the light exactly where the mirror
    image of the eye's ray (from the eye's image below the floor) passes within the radius of the centre."""
    eye = np.array([-1.5, 1.2, 1.0])
    aims = np.stack(np.meshgrid(np.linspace(-1.4, -0.5, 40), [0.0], np.linspace(0.3, 1.0, 40)), -1).reshape(-1, 3)
    directions = aims - eye
    colour, _ = shade_rays(backend, over_a_mirror(bulb()), np.tile(eye, (len(aims), 1)), directions)
    image = eye * np.array([1.0, -1.0, 1.0])  # the eye's mirror image: the reflected ray is its line through aim
    to_centre = np.asarray(BULB_AT) - image
    unit = (aims - image) / np.linalg.norm(aims - image, axis=1, keepdims=True)
    miss = np.linalg.norm(to_centre - (unit @ to_centre)[:, None] * unit, axis=1)
    assert np.abs(miss - BULB_RADIUS).min() > 1e-6
    inside = miss < BULB_RADIUS
    assert inside.sum() > 50 and (~inside).sum() > 50
    np.testing.assert_array_equal(colour[inside], np.broadcast_to(np.array(BULB) / BULB_RADIUS ** 2, colour[inside].shape))
    np.testing.assert_array_equal(colour[~inside], np.broadcast_to(BACKDROP, colour[~inside].shape))


def test_a_spot_lights_sphere_is_seen_only_within_its_cone(backend):
    xs = BULB_AT[0] + np.array([-0.3, 0.0, 0.3])
    down = bulb(kind="spot", direction=(0, -1, 0), spot_size=60.0)
    colour, _ = shade_down(backend, over_a_mirror(down), xs, zs=[BULB_AT[2]], height=1.0)
    np.testing.assert_array_equal(colour[0], np.broadcast_to(np.array(BULB) / BULB_RADIUS ** 2, (3, 3)))
    for away in [(1, 0, 0), (0, 1, 0), (0.0, -1.0, 1.2)]:  # (the floor below it outside the cone: 90, 180, 50 degrees)
        colour, _ = shade_down(backend, over_a_mirror(bulb(kind="spot", direction=away, spot_size=60.0)), xs,
                               zs=[BULB_AT[2]], height=1.0)
        np.testing.assert_array_equal(colour[0], np.broadcast_to(BACKDROP, (3, 3)))  # (and what is behind it shows)
    # within the blend: times the factor of the direction from the light to the mirror point, as it lights it
    tilted = bulb(kind="spot", direction=(0.0, -1.0, 0.5), spot_size=70.0, spot_blend=0.8)
    colour, _ = shade_down(backend, over_a_mirror(tilted), xs, zs=[BULB_AT[2]], height=1.0)
    axis = np.array([0.0, -1.0, 0.5]) / math.sqrt(1.25)
    for column, x in enumerate(xs):
        out = np.array([x, 0.0, BULB_AT[2]]) - np.asarray(BULB_AT)
        factor = blender_spot(float(out @ axis) / np.linalg.norm(out), 70.0, 0.8)
        assert 0.0 < factor < 1.0
        np.testing.assert_allclose(colour[0, column], np.array(BULB) / BULB_RADIUS ** 2 * factor, rtol=1e-12)


SUN_ANGLE = 10.0
SKY = (0.4, 0.5, 0.6)


def sun_over_a_mirror(angle=SUN_ANGLE, *others, tilt=(0.0, -1.0, 0.0), **fields):
    sun = Light((0, 0, 0), SKY, kind="sun", direction=tilt, angle=angle, samples=4, **fields)
    return over_a_mirror(sun, *others)


def fan_down(degrees, height=1.0):
    """Rays from (0, height, 0) down at the floor, each ``degrees`` from straight down (about the z axis): the
    mirror sends each back up as many degrees from straight up."""
    theta = np.radians(np.asarray(degrees, float))
    directions = np.stack([np.sin(theta), -np.cos(theta), np.zeros_like(theta)], axis=1)
    return np.tile([0.0, height, 0.0], (len(theta), 1)), directions


def test_a_mirror_shows_the_suns_disk_with_its_radiance_and_angular_size(backend):
    """A ray that escapes within angle / 2 of the direction to the sun sees colour / (2 (1 - cos(angle / 2))):
    the irradiance pi colour with which the sun lights a white surface facing it, over the solid angle of its
    disk, 2 pi (1 - cos(angle / 2)); beyond, the background."""
    degrees = np.array([0.0, 1.0, 3.0, 4.9, 4.999, 5.001, 5.1, 7.0, 20.0, -4.99, -5.01])
    colour, t = shade_rays(backend, sun_over_a_mirror(), *fan_down(degrees))
    inside = np.abs(degrees) < SUN_ANGLE / 2
    radiance = np.array(SKY) / (2.0 * (1.0 - math.cos(math.radians(SUN_ANGLE / 2))))
    np.testing.assert_allclose(colour[inside], np.broadcast_to(radiance, colour[inside].shape), rtol=1e-12)
    np.testing.assert_array_equal(colour[~inside], np.broadcast_to(BACKDROP, colour[~inside].shape))
    # the units: radiance x solid angle is the irradiance pi E, E what the sun gives a white floor facing it
    below, _ = shade_down(backend, lit(sun_over_a_mirror().lights[0]), [0.0])
    solid_angle = 2 * np.pi * (1.0 - math.cos(math.radians(SUN_ANGLE / 2)))
    np.testing.assert_allclose(colour[0] * solid_angle, np.pi * below[0, 0], rtol=1e-12)
    # a tilted sun: the disk moves with it
    tilted, _ = shade_rays(backend, sun_over_a_mirror(tilt=(-math.sin(0.5), -math.cos(0.5), 0.0)),
                           *fan_down(np.degrees(0.5) + degrees))
    np.testing.assert_array_equal(tilted[inside].min(axis=0) > BACKDROP, [True] * 3)
    np.testing.assert_array_equal(tilted[~inside], np.broadcast_to(BACKDROP, tilted[~inside].shape))


def test_the_sun_is_behind_everything_a_ray_meets(backend):
    origins, directions = fan_down([0.0, 2.0])
    ceiling = shape("square", translation(0, 2.5, 0) @ rotation(90, 1, 0, 0) @ scaling(50, 50, 1),
                    ambient=(0, 0, 0), diffuse=(0, 0, 0), emissive=EMBER)
    sun = Light((0, 0, 0), SKY, kind="sun", direction=(0, -1, 0), angle=SUN_ANGLE)
    colour, _ = shade_rays(backend, over_a_mirror(sun, objects=[ceiling]), origins, directions)
    np.testing.assert_array_equal(colour, np.broadcast_to(EMBER, colour.shape))  # (a surface: not the sky)
    for lights in ([sun, bulb(position=(0.0, 3.0, 0.0))], [bulb(position=(0.0, 3.0, 0.0)), sun]):
        colour, _ = shade_rays(backend, over_a_mirror(*lights), origins[:1], directions[:1])
        np.testing.assert_array_equal(colour[0], np.array(BULB) / BULB_RADIUS ** 2)  # (the sphere, in either order)


def test_the_nearest_seen_light_is_the_one_seen(backend):
    lower_panel = Light((0.4, 2.0, -0.2), GLOW, kind="area", direction=(0, -1, 0), size=(0.4, 0.4), samples=4)
    higher_panel = dataclasses.replace(lower_panel, position=(0.4, 4.0, -0.2))
    for panel, expected in ((lower_panel, np.pi * np.array(GLOW)), (higher_panel, np.array(BULB) / BULB_RADIUS ** 2)):
        for lights in ([panel, bulb()], [bulb(), panel]):
            colour, _ = shade_down(backend, over_a_mirror(*lights), [BULB_AT[0]], zs=[BULB_AT[2]], height=1.0)
            np.testing.assert_array_equal(colour[0, 0], expected)
    ball = shape("sphere", translation(*BULB_AT) @ translation(0, -1.0, 0) @ scaling(0.2, 0.2, 0.2),
                 ambient=(0, 0, 0), diffuse=(0, 0, 0), emissive=EMBER)
    colour, _ = shade_down(backend, over_a_mirror(bulb(), objects=[ball]), [BULB_AT[0], BULB_AT[0] + 0.35],
                           zs=[BULB_AT[2]], height=0.5)
    np.testing.assert_array_equal(colour[0, 0], EMBER)  # (an object in front of it hides it)
    np.testing.assert_array_equal(colour[0, 1], np.array(BULB) / BULB_RADIUS ** 2)


def test_camera_rays_never_see_a_sphere_a_spot_or_the_sun(backend):
    lights = [bulb(), bulb(kind="spot", position=(-2.0, 3.0, 0.0), direction=(0, -1, 0), spot_size=90.0),
              Light((0, 0, 0), SKY, kind="sun", direction=(0, -1, 0), angle=SUN_ANGLE)]
    scene = over_a_mirror(*lights)
    assert "seen-lights" in compile_scene(scene).effects
    origins = np.array([[0.4, 1.0, -0.2], [-2.0, 1.0, 0.0], [5.0, 1.0, 5.0], [0.4, 3.0, -0.2]])
    colour, _ = shade_rays(backend, scene, origins, np.tile([0.0, 1.0, 0.0], (4, 1)))  # (up at each, one inside)
    np.testing.assert_array_equal(colour, np.broadcast_to(BACKDROP, colour.shape))


SEEN_KINDS = {"sphere": bulb(), "spot": bulb(kind="spot", direction=(0, -1, 0), spot_size=60.0),
              "sun": Light((0, 0, 0), SKY, kind="sun", direction=(0, -1, 0), angle=SUN_ANGLE, samples=4)}


@pytest.mark.parametrize("kind", sorted(SEEN_KINDS))
def test_a_sphere_spot_or_sun_left_out_of_glossy_is_not_seen_in_a_mirror(backend, kind):
    at = ([BULB_AT[0]], [BULB_AT[2]])
    light = SEEN_KINDS[kind]
    seen, _ = shade_down(backend, over_a_mirror(light), *at, height=1.0)
    assert (seen > np.array(BACKDROP) + 0.1).all()
    unseen, _ = shade_down(backend, over_a_mirror(switched(light, "visible_glossy")), *at, height=1.0)
    np.testing.assert_array_equal(unseen[0, 0], BACKDROP)
    still, _ = shade_down(backend, over_a_mirror(switched(light, "visible_transmission")), *at, height=1.0)
    np.testing.assert_array_equal(still, seen)  # (a mirror ray is no transmission ray)


@pytest.mark.parametrize("kind", sorted(SEEN_KINDS))
def test_a_sphere_spot_or_sun_left_out_of_transmission_is_not_seen_through_glass(backend, kind):
    slab = shape("cube", translation(0, 0.8, 0) @ scaling(3.0, 0.1, 3.0), ambient=(0, 0, 0), diffuse=(0, 0, 0),
                 transparency=1.0)
    origins, up = np.array([[BULB_AT[0], 0.2, BULB_AT[2]]]), np.array([[0.0, 1.0, 0.0]])
    light = SEEN_KINDS[kind]

    def through(*off):
        return shade_rays(backend, scene_of(slab, lights=[switched(light, *off)], background=BACKDROP,
                                            global_ambient=(0.0, 0.0, 0.0)), origins, up)[0]

    seen = through()
    assert (seen > np.array(BACKDROP) + 0.1).all()
    np.testing.assert_array_equal(through("visible_transmission"), [BACKDROP])
    np.testing.assert_array_equal(through("visible_glossy"), seen)  # (a refracted ray is no glossy ray)


def test_lights_without_an_extent_are_never_seen_and_cost_nothing(backend):
    """A sphere or spot of radius 0, a sun of angle 0 and SDL's point light: rays reflected straight at them see
    the background, and the effect is not live (a scene of them, or of SDL's lights, pays nothing)."""
    point_lights = [bulb(radius=0.0, samples=1), bulb(kind="spot", radius=0.0, samples=1, direction=(0, -1, 0)),
                    Light(BULB_AT, BULB)]
    for light in point_lights + [Light((0, 0, 0), SKY, kind="sun", direction=(0, -1, 0))]:
        scene = over_a_mirror(light)
        assert "seen-lights" not in compile_scene(scene).effects, light
        colour, _ = shade_down(backend, scene, [BULB_AT[0]], zs=[BULB_AT[2]], height=1.0)
        np.testing.assert_array_equal(colour[0, 0], BACKDROP)
    for name in ("glass", "lecture", "textures"):  # (SDL's lights alone: their pictures stay as they were)
        assert "seen-lights" not in compile_scene(tracer.load(SCENES / f"{name}.sdl")).effects, name


def test_only_scenes_that_can_see_a_sphere_or_sun_pay_for_it():
    for light in SEEN_KINDS.values():
        assert "seen-lights" not in compile_scene(lit(light)).effects  # (nothing reflects or transmits)
        assert "seen-lights" in compile_scene(over_a_mirror(light)).effects
        assert "light-switches" not in compile_scene(over_a_mirror(light)).effects
        hidden = compile_scene(over_a_mirror(switched(light, "visible_glossy"))).effects
        assert "seen-lights" not in hidden  # (the mirror cannot see it)
        other = SEEN_KINDS["sphere"] if light.kind == "sun" else SEEN_KINDS["sun"]
        reads = compile_scene(over_a_mirror(switched(light, "visible_glossy"), other)).effects
        assert {"seen-lights", "light-switches"} <= reads  # (the switch hides one of two seen lights)


def test_model_refuses_switches_that_are_not_booleans():
    for name in SWITCHES:
        with pytest.raises(SceneError, match=name):
            Light((0, 0, 0), (1, 1, 1), **{name: 0})
    assert all(getattr(Light((0, 0, 0), (1, 1, 1)), name) for name in SWITCHES)  # (on by default)


def test_sdl_writes_a_switched_light_as_the_light(tmp_path):
    scene = parse_sdl(SDL_LIGHTS)
    scene.lights = [switched(light, *SWITCHES) for light in scene.lights]
    save_sdl(scene, tmp_path / "switched.sdl")
    again = tracer.load(tmp_path / "switched.sdl").lights
    assert again == parse_sdl(SDL_LIGHTS).lights  # (SDL has no words for the switches: on again)


@needs_usd
def test_usd_writes_a_switched_light_as_the_light(tmp_path):
    from tracer.usd import load_usd, save_usd
    scene = parse_sdl(SDL_LIGHTS)
    scene.lights = [switched(light, *SWITCHES) for light in scene.lights]
    save_usd(scene, tmp_path / "switched.usda")
    assert load_usd(tmp_path / "switched.usda").lights == parse_sdl(SDL_LIGHTS).lights  # (no words there either)


# ------------------------------------------------------------------------------------------------ SDL


SDL_LIGHTS = """! name: Key Light
light 1 2 3 1 1 1
! name: Fill
sphereLight 0 4 0 10 10 10 0.25 16
spotLight 0 5 0 0 -1 0 5 5 5 60 0.2 0.1 4
! name: Sun
sunLight 1 -2 -1 0.5 0.5 0.4 0.53 8
areaLight 0 3 0 0 -1 0 1 0 0 2 2 2 1 0.5 9
ellipseLight 0 3 0 0 -1 0 1 1 0 2 2 2 1 1 9
! name: ball
sphere
"""


def test_sdl_light_statements_read_as_documented():
    scene = parse_sdl(SDL_LIGHTS)
    key, fill, spot, sun, area, disk = scene.lights
    assert key == Light((1.0, 2.0, 3.0), (1.0, 1.0, 1.0), name="Key Light")
    assert fill == Light((0.0, 4.0, 0.0), (10.0, 10.0, 10.0), kind="sphere", name="Fill", radius=0.25, samples=16)
    assert (spot.kind, spot.direction, spot.spot_size, spot.spot_blend, spot.radius, spot.samples) == (
        "spot", (0.0, -1.0, 0.0), 60.0, 0.2, 0.1, 4)
    assert (sun.kind, sun.name, sun.direction, sun.angle) == ("sun", "Sun", (1.0, -2.0, -1.0), 0.53)
    assert (area.shape, area.size, area.axis, disk.shape) == ("rectangle", (1.0, 0.5), (1.0, 0.0, 0.0), "ellipse")
    assert scene.shapes()[0].name == "ball"  # a name comment still names the shape after the lights


def test_sdl_round_trip_keeps_every_light_and_its_name(tmp_path):
    scene = parse_sdl(SDL_LIGHTS)
    save_sdl(scene, tmp_path / "lights.sdl")
    again = tracer.load(tmp_path / "lights.sdl")
    assert again.lights == scene.lights
    assert [s.name for s in again.shapes()] == ["ball"]


@pytest.mark.parametrize("text, message", [
    ("sphereLight 0 0 0 1 1 1 -1 1", "radius must not be negative"),
    ("sphereLight 0 0 0 1 1 1 0 0", "samples must be a whole number"),
    ("sphereLight 0 0 0 1 1 1 0 2.5", "samples must be a whole number"),
    ("sunLight 0 0 0 1 1 1 1 1", "direction is zero"),
    ("sunLight 0 -1 0 1 1 1 180 1", "angle"),
    ("spotLight 0 0 0 0 0 1 1 1 1 0 0 0 1", "spot size"),
    ("spotLight 0 0 0 0 0 1 1 1 1 40 1.5 0 1", "blend"),
    ("areaLight 0 0 0 0 0 1 0 0 2 1 1 1 1 1 1", "axis"),
    ("areaLight 0 0 0 0 0 1 1 0 0 1 1 1 0 1 1", "width and height"),
    ("sphereLight 0 0 0 1 1 1", "end of file"),
])
def test_bad_light_statements_are_one_error_naming_the_place(text, message):
    with pytest.raises(SDLError) as err:
        parse_sdl("camera 0 0 5 0 0 0 0 1 0 40\n" + text, strict=True)
    assert message in str(err.value) and ":2:" in str(err.value)


def test_lenient_reading_skips_a_bad_light_with_a_warning():
    scene = parse_sdl("sphereLight 0 0 0 1 1 1 -1 1\nlight 0 1 0 1 1 1\nsphere", strict=False)
    assert len(scene.lights) == 1 and len(scene.warnings) == 1


def test_model_refuses_unknown_kinds_and_sample_counts():
    with pytest.raises(SceneError):
        Light((0, 0, 0), (1, 1, 1), kind="laser")
    with pytest.raises(SceneError):
        Light((0, 0, 0), (1, 1, 1), kind="area", shape="star")
    with pytest.raises(SceneError):
        Light((0, 0, 0), (1, 1, 1), samples=0)


def test_the_c_reader_leaves_named_lights_to_the_python_reader():
    from tracer.sdl import fastread
    if not fastread.available():
        pytest.skip("C core not available")
    text = "! name: Key\nlight 0 1 0 1 1 1\n" + "sphere\n" * 10
    declined = fastread.scan(text)
    assert isinstance(declined, fastread.Declined) and declined.reason == "namedLight"
    assert parse_sdl(text * 1000).lights[0].name == "Key"


def test_editing_lights_in_place_renders_as_from_scratch(backend):
    from tracer.edit import EditableScene
    scene = showcase()
    lights = list(scene.lights)
    scene.lights = lights[-1:]  # SDL's point light alone: no physical lights yet
    editable = EditableScene(scene)
    w, h = scaled(backend, 48, 36)
    tracer.render(editable.compiled, w, h, backend=backend)
    editable.set_lights(lights[:3])
    edited = tracer.render(editable.compiled, w, h, backend=backend)
    fresh = showcase()
    fresh.lights = lights[:3]
    expected = tracer.render(fresh, w, h, backend=backend)
    assert np.array_equal(edited.image, expected.image)
    assert edited.rays.as_dict() == expected.rays.as_dict()


# ------------------------------------------------------------------------------------------------ USD


@needs_usd
def test_usd_round_trip_keeps_every_light_exactly_and_its_name(tmp_path):
    from tracer.usd import load_usd, save_usd
    scene = parse_sdl(SDL_LIGHTS.replace("ellipseLight 0 3 0 0 -1 0 1 1 0 2 2 2 1 1 9",
                                         "ellipseLight 0.3 3 0.1 0.2 -1 0.1 1 1 0 2 2 2 1.5 0.7 9"))
    save_usd(scene, tmp_path / "lights.usda")
    again = load_usd(tmp_path / "lights.usda")
    assert again.lights == scene.lights
    assert again.warnings == []


@needs_usd
def test_usd_lights_are_usdlux_for_other_tools(tmp_path):
    from pxr import Usd, UsdLux
    from tracer.usd import save_usd
    save_usd(parse_sdl(SDL_LIGHTS), tmp_path / "lights.usda")
    stage = Usd.Stage.Open(str(tmp_path / "lights.usda"))
    prims = {p.GetName(): p for p in stage.Traverse() if p.HasAPI(UsdLux.LightAPI)}
    assert set(prims) == {"Key_Light", "Fill", "light_2", "Sun", "light_4", "light_5"}
    assert prims["Key_Light"].GetTypeName() == "SphereLight"
    assert UsdLux.SphereLight(prims["Fill"]).GetRadiusAttr().Get() == pytest.approx(0.25)
    spot = UsdLux.ShapingAPI(prims["light_2"])
    assert spot.GetShapingConeAngleAttr().Get() == pytest.approx(30.0)  # the half-angle
    assert spot.GetShapingConeSoftnessAttr().Get() == pytest.approx(0.2)
    assert UsdLux.DistantLight(prims["Sun"]).GetAngleAttr().Get() == pytest.approx(0.53)
    rect = UsdLux.RectLight(prims["light_4"])
    assert (rect.GetWidthAttr().Get(), rect.GetHeightAttr().Get()) == (1.0, 0.5)
    assert prims["light_5"].GetTypeName() == "DiskLight"
    # the rect light shines down its -z: here the light's direction, -y
    matrix = UsdGeom_world(prims["light_4"])
    np.testing.assert_allclose(-matrix[:3, 2], (0.0, -1.0, 0.0), atol=1e-12)


def UsdGeom_world(prim) -> np.ndarray:
    from pxr import UsdGeom
    from tracer.usd.common import from_gf
    return from_gf(UsdGeom.Xformable(prim).ComputeLocalToWorldTransform(0))


@needs_usd
def test_usd_lights_edited_in_another_tool_follow_the_edit(tmp_path):
    from pxr import Gf, Usd, UsdLux
    from tracer.usd import load_usd, save_usd
    save_usd(parse_sdl(SDL_LIGHTS), tmp_path / "lights.usda")
    stage = Usd.Stage.Open(str(tmp_path / "lights.usda"))
    rect = UsdLux.RectLight(stage.GetPrimAtPath("/SDLScene/Lights/light_4"))
    rect.GetWidthAttr().Set(3.0)
    sun = stage.GetPrimAtPath("/SDLScene/Lights/Sun")
    UsdLux.DistantLight(sun).GetAngleAttr().Set(2.0)
    stage.Save()
    area, sun_light = load_usd(tmp_path / "lights.usda").lights[4], load_usd(tmp_path / "lights.usda").lights[3]
    assert area.size == (3.0, 0.5)
    assert sun_light.angle == 2.0 and sun_light.direction == (1.0, -2.0, -1.0)  # (the direction untouched)


@needs_usd
def test_usd_rect_and_disk_lights_of_other_tools_are_area_lights(tmp_path):
    from pxr import Gf, Usd, UsdGeom, UsdLux
    from tracer.usd import load_usd
    stage = Usd.Stage.CreateNew(str(tmp_path / "foreign.usda"))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
    rect = UsdLux.RectLight.Define(stage, "/World/Panel")
    rect.CreateWidthAttr(2.0)
    rect.CreateHeightAttr(1.0)
    rect.AddTranslateOp().Set(Gf.Vec3d(0, 3, 0))
    rect.AddRotateXOp().Set(-90.0)  # its -z turns to -y: it shines down
    disk = UsdLux.DiskLight.Define(stage, "/World/Disk")
    disk.CreateRadiusAttr(0.25)
    stage.Save()
    panel, round_light = load_usd(tmp_path / "foreign.usda").lights
    assert (panel.kind, panel.shape, panel.name, panel.size) == ("area", "rectangle", "Panel", (2.0, 1.0))
    np.testing.assert_allclose(panel.direction, (0.0, -1.0, 0.0), atol=1e-12)
    np.testing.assert_allclose(panel.position, (0.0, 3.0, 0.0))
    assert (round_light.shape, round_light.size) == ("ellipse", (0.5, 0.5))


@pytest.mark.parametrize("prim, attribute, value, message", [
    ("Fill", "inputs:radius", float("nan"), "finite"),
    ("Fill", "inputs:radius", -1.0, "radius must not be negative"),
    ("Sun", "inputs:angle", 720.0, "angle"),
    ("Sun", "inputs:angle", float("inf"), "finite"),
    ("light_4", "inputs:width", 0.0, "width and height"),
    ("light_4", "inputs:height", float("nan"), "finite"),
    ("light_2", "inputs:shaping:cone:angle", 0.0, "spot size"),
    ("light_2", "inputs:shaping:cone:softness", float("nan"), "finite"),
])
@needs_usd
def test_usd_lights_with_numbers_sdl_refuses_are_refused_naming_the_prim(tmp_path, prim, attribute, value, message):
    """A light's numbers read from USD are checked as SDL's statements are (tracer.sdl.lights.light_problem):
    a NaN radius, a zero-width area light or a sun of 720 degrees is one error naming the file and prim
    (strict), or a warning and the light left out (lenient); they used to reach the tracer."""
    from pxr import Usd
    from tracer.errors import TracerError
    from tracer.usd import load_usd, save_usd
    save_usd(parse_sdl(SDL_LIGHTS), tmp_path / "lights.usda")
    stage = Usd.Stage.Open(str(tmp_path / "lights.usda"))
    stage.GetPrimAtPath(f"/SDLScene/Lights/{prim}").GetAttribute(attribute).Set(value)
    stage.Save()
    with pytest.raises(TracerError) as err:
        load_usd(tmp_path / "lights.usda")
    assert message in str(err.value) and f"/SDLScene/Lights/{prim}" in str(err.value)
    assert "lights.usda" in str(err.value)
    lenient = load_usd(tmp_path / "lights.usda", strict=False)
    assert len(lenient.lights) == len(parse_sdl(SDL_LIGHTS).lights) - 1 and lenient.warnings


@needs_usd
def test_usd_spot_cone_edited_in_another_tool_follows_the_edit(tmp_path):
    from pxr import Usd, UsdLux
    from tracer.usd import load_usd, save_usd
    save_usd(parse_sdl(SDL_LIGHTS), tmp_path / "lights.usda")
    stage = Usd.Stage.Open(str(tmp_path / "lights.usda"))
    shaping = UsdLux.ShapingAPI(stage.GetPrimAtPath("/SDLScene/Lights/light_2"))
    shaping.GetShapingConeAngleAttr().Set(20.0)  # USD's half-angle: a 40-degree spot
    shaping.GetShapingConeSoftnessAttr().Set(0.5)
    stage.Save()
    spot = load_usd(tmp_path / "lights.usda").lights[2]
    assert (spot.kind, spot.spot_size, spot.spot_blend) == ("spot", 40.0, 0.5)
