"""Material.fresnel (docs/tracer.md, "Materials for Blender scenes"): a tinted metal's reflectance follows
Schlick's formula, a dielectric's the exact Fresnel equations (written here with Snell's law and indices, not
as tracer.fresnel writes them), at normal and grazing incidence, on both backends; glass keeps the light it
receives (total internal reflection included); C = NumPy; SDL keeps the modes."""
from __future__ import annotations

import math

import numpy as np
import pytest

import tracer
from helpers import scene_of, shape
from tracer import fresnel
from tracer.backend import make_tracer
from tracer.compile import compile_scene
from tracer.model import Camera, Material
from tracer.savings import RaySavings
from tracer.sdl.parser import parse_sdl
from tracer.sdl.writer import save_sdl
from tracer.transforms import rotation, scaling, translation

BACKGROUND = (0.2, 0.5, 0.8)
ANGLES = (0.0, 20.0, 45.0, 56.3, 70.0, 85.0, 89.0)
DARK = dict(ambient=(0.0, 0.0, 0.0), diffuse=(0.0, 0.0, 0.0))


def surface(**material):
    """The plane y = 0 (its solid below), of this material."""
    return shape("plane", rotation(-90, 1, 0, 0), **{**DARK, **material})


def shade_at_angles(backend, scene, angles=ANGLES, height=2.0):
    """Colours of rays reaching the origin from above at these angles (degrees) from the normal +y."""
    theta = np.radians(np.asarray(angles))
    directions = np.stack([np.sin(theta), -np.cos(theta), np.zeros_like(theta)], axis=1)
    origins = -height * directions
    t = make_tracer(compile_scene(scene), backend, threads=1, savings=RaySavings.none())
    return t.camera_rays(origins, directions), t


def exact_dielectric(theta, n1, n2):
    """Unpolarised reflectance of light going from index n1 into n2 at angle theta (radians)."""
    sin_t = n1 / n2 * math.sin(theta)
    if sin_t >= 1.0:
        return 1.0
    ci, ct = math.cos(theta), math.sqrt(1.0 - sin_t * sin_t)
    rs = (n1 * ci - n2 * ct) / (n1 * ci + n2 * ct)
    rp = (n2 * ci - n1 * ct) / (n2 * ci + n1 * ct)
    return (rs * rs + rp * rp) / 2


def test_metal_reflectance_is_schlicks_coloured_fresnel(backend):
    tint = np.array([0.95, 0.64, 0.54])
    scene = scene_of(surface(reflectivity=0.9, fresnel="metal", fresnel_tint=tuple(tint)), background=BACKGROUND,
                     global_ambient=(0.0, 0.0, 0.0))
    colour, t = shade_at_angles(backend, scene)
    for row, angle in zip(colour, ANGLES):
        cos = math.cos(math.radians(angle))
        expected = 0.9 * (tint + (1 - tint) * (1 - cos) ** 5) * BACKGROUND
        np.testing.assert_allclose(row, expected, rtol=1e-12)
    assert colour[0] == pytest.approx(0.9 * tint * BACKGROUND)  # normal incidence: the tint itself
    assert (colour[-1] > 0.95 * 0.9 * np.array(BACKGROUND)).all()  # grazing: nearly white
    assert t.counts.reflection == len(ANGLES)


def test_dielectric_reflectance_is_the_exact_fresnel_equations(backend):
    ior = 1.5
    scene = scene_of(surface(reflectivity=1.0, fresnel="dielectric", speed_of_light=1 / ior), background=BACKGROUND,
                     global_ambient=(0.0, 0.0, 0.0))
    colour, _ = shade_at_angles(backend, scene)
    for row, angle in zip(colour, ANGLES):
        expected = exact_dielectric(math.radians(angle), 1.0, ior)
        np.testing.assert_allclose(row, expected * np.array(BACKGROUND), rtol=1e-9)
    assert colour[0, 0] / BACKGROUND[0] == pytest.approx(((ior - 1) / (ior + 1)) ** 2)  # 0.04
    brewster = shade_at_angles(backend, scene, [math.degrees(math.atan(ior))])[0][0, 0] / BACKGROUND[0]
    assert brewster == pytest.approx(((ior ** 2 - 1) / (ior ** 2 + 1)) ** 2 / 2)  # rp = 0 there


def test_glass_transmits_one_minus_the_reflectance(backend):
    """Glass below y = 0 (a half-space), an emissive white sheet deep inside it, a black sky: what comes back
    is the transmitted share 1 - F of the sheet's light."""
    ior = 1.45
    glass = surface(reflectivity=1.0, transparency=1.0, fresnel="dielectric", speed_of_light=1 / ior)
    sheet = shape("square", translation(0, -3, 0) @ rotation(-90, 1, 0, 0) @ scaling(100, 100, 1),
                  emissive=(1.0, 1.0, 1.0), **DARK)
    scene = scene_of(glass, sheet, background=(0.0, 0.0, 0.0), global_ambient=(0.0, 0.0, 0.0),
                     min_reflectivity=0.0, min_transparency=0.0)
    colour, t = shade_at_angles(backend, scene)
    for row, angle in zip(colour, ANGLES):
        np.testing.assert_allclose(row, 1.0 - exact_dielectric(math.radians(angle), 1.0, ior), rtol=1e-9)
    assert t.counts.refraction == len(ANGLES)


def test_dielectric_reflectance_past_the_critical_angle_is_total():
    ratio = np.full(4, 1.5)  # from glass (n 1.5) out into air: c2 / c1 = 1.5
    critical = math.asin(1 / 1.5)
    angles = np.array([0.0, critical - 1e-3, critical + 1e-3, 1.4])
    reflectance = fresnel.dielectric(np.cos(angles), ratio)
    assert reflectance[0] == pytest.approx(0.04)
    assert reflectance[1] < 1.0 and reflectance[2] == 1.0 and reflectance[3] == 1.0
    assert reflectance[1] == pytest.approx(exact_dielectric(critical - 1e-3, 1.5, 1.0))


def glass_cube_scene():
    cube = shape("cube", translation(0, 0, 0) @ rotation(30, 1, 1, 0),
                 **DARK, reflectivity=1.0, transparency=1.0, fresnel="dielectric", speed_of_light=1 / 1.5)
    return scene_of(cube, background=BACKGROUND, global_ambient=(0.0, 0.0, 0.0), max_recursion_depth=24,
                    min_reflectivity=0.0, min_transparency=0.0, camera=Camera((0, 0, 6), (0, 0, 0), (0, 1, 0), 30))


def test_glass_keeps_the_light_it_receives(backend):
    """Without lights, every path through clear glass ends in the uniform background, and the Fresnel
    weights (with total internal reflection) sum to one at each surface: the cube is the background's colour,
    but for the paths cut at the recursion depth."""
    result = tracer.render(glass_cube_scene(), 48, 48, backend=backend, savings=RaySavings(cutoff=1e-4))
    centre = result.image[12:36, 12:36].reshape(-1, 3)
    np.testing.assert_allclose(centre.mean(axis=0), BACKGROUND, rtol=0.02)
    assert result.rays.reflection > result.rays.camera  # the inner reflections, total ones included


def test_c_and_numpy_agree_on_fresnel_materials():
    from tracer import native
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    scene = glass_cube_scene()
    scene.objects.append(shape("sphere", translation(1.5, -1, -1) @ scaling(0.6, 0.6, 0.6), **DARK,
                               reflectivity=0.8, fresnel="metal", fresnel_tint=(1.0, 0.8, 0.3)))
    c = tracer.render(scene, 80, 60, backend="c")
    n = tracer.render(scene, 80, 60, backend="numpy")
    assert np.abs(c.image - n.image).max() <= 1 / 255  # (test_native's standard)
    assert c.rays.as_dict() == n.rays.as_dict() and c.rays.skipped() == n.rays.skipped()
    assert "fresnel" in c.stats()["effects"]


def test_constant_mode_is_sdls_and_pays_nothing():
    mirror = surface(reflectivity=0.7)
    assert "fresnel" not in compile_scene(scene_of(mirror)).effects
    # a Fresnel mode on a material that neither reflects nor transmits changes nothing either
    assert "fresnel" not in compile_scene(scene_of(surface(fresnel="metal"))).effects


def test_sdl_round_trip_keeps_the_modes(tmp_path):
    scene = parse_sdl("fresnel metal fresnelTint 0.9 0.6 0.2 reflectivity 1 sphere\n"
                      "fresnel dielectric transparency 1 cube\nfresnel constant cone\n")
    materials = [s.material for s in scene.shapes()]
    assert [m.fresnel for m in materials] == ["metal", "dielectric", "constant"]
    assert materials[0].fresnel_tint == (0.9, 0.6, 0.2)
    save_sdl(scene, tmp_path / "f.sdl")
    assert [s.material for s in tracer.load(tmp_path / "f.sdl").shapes()] == materials


def test_unknown_modes_are_refused():
    with pytest.raises(tracer.errors.SDLError, match="unknown fresnel mode"):
        parse_sdl("fresnel shiny sphere")
    with pytest.raises(tracer.errors.SceneError):
        Material(fresnel="shiny")


def test_usd_keeps_the_modes_and_shows_a_metal_as_metallic(tmp_path):
    from pxr import Usd, UsdShade
    from tracer.usd import load_usd, save_usd
    scene = parse_sdl("fresnel metal fresnelTint 0.9 0.6 0.2 reflectivity 1 sphere\n"
                      "fresnel dielectric transparency 1 speedOfLight 0.7 cube\ndefaultMaterials cone\n")
    save_usd(scene, tmp_path / "f.usda")
    assert [s.material for s in load_usd(tmp_path / "f.usda").shapes()] == [s.material for s in scene.shapes()]
    stage = Usd.Stage.Open(str(tmp_path / "f.usda"))
    shaders = [UsdShade.Shader(p) for p in stage.Traverse() if p.IsA(UsdShade.Shader)]
    metals = [s for s in shaders if s.GetInput("metallic").Get() == 1.0]
    assert len(metals) == 1 and tuple(metals[0].GetInput("diffuseColor").Get()) == pytest.approx((0.9, 0.6, 0.2))
