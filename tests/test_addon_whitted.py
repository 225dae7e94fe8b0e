"""The table of Blender shaders as Whitted materials (addon/pure/whitted.py) and Blender's lights in the
tracer's units (addon/pure/light_units.py), without Blender: each rule of docs/blender.md, "Blender
materials" and "Blender lights".  That the result renders as Cycles does is tests/test_addon_cycles.py's."""
from __future__ import annotations

import math

import numpy as np
import pytest

from addon.pure import light_units, whitted
from addon.pure.whitted import Add, Mix, Surface
from tracer.model import Light, Material


def fields(shader) -> dict:
    out = whitted.whitted(shader)
    assert Material(**{k: v for k, v in out.items() if k != "image"})  # every field the tracer takes
    return out


def test_a_default_principled_is_lambert_with_a_ggx_sized_highlight():
    out = fields(Surface(base_color=(0.8, 0.1, 0.1), roughness=0.5, specular_f0=0.04))
    assert out["diffuse"] == out["ambient"] == pytest.approx((0.8 * 0.96, 0.1 * 0.96, 0.1 * 0.96))  # b (1 - F0)
    assert out["specular_exponent"] == pytest.approx(30.0)  # 2 / 0.5^4 - 2
    assert out["specular"] == pytest.approx((0.04 * 32 / 8,) * 3)  # F0 (f + 2) / 8
    # its own reflection, Schlick from F0, half-faded at Roughness 0.5
    assert (out["fresnel"], out["reflectivity"], out["transparency"]) == ("metal", 0.5, 0.0)
    assert out["fresnel_tint"] == pytest.approx((0.04,) * 3)


def test_rougher_is_wider_and_dimmer():
    exponents = [whitted.highlight_exponent(r) for r in (0.15, 0.3, 0.5, 0.8, 1.0)]
    assert exponents == sorted(exponents, reverse=True) and exponents[-1] == 1.0
    assert whitted.highlight_exponent(0.001) == whitted.MAX_EXPONENT
    peaks = [fields(Surface(roughness=r))["specular"][0] for r in (0.3, 0.5, 0.8)]
    assert peaks == sorted(peaks, reverse=True)
    assert fields(Surface(roughness=0.0))["specular"] == (0.0, 0.0, 0.0)  # a mirror shows no point light


def test_principled_glass_is_a_dielectric_of_its_ior():
    out = fields(Surface(base_color=(1, 1, 1), transmission=1.0, ior=1.45, roughness=0.0))
    assert out["fresnel"] == "dielectric" and out["reflectivity"] == 1.0 and out["transparency"] == 1.0
    assert out["speed_of_light"] == pytest.approx(1 / 1.45)
    assert out["diffuse"] == (0.0, 0.0, 0.0) and out["specular"] == (0.0, 0.0, 0.0)


def test_a_metal_is_a_mirror_tinted_by_its_base_colour():
    gold = (1.0, 0.76, 0.33)
    out = fields(Surface(base_color=gold, metallic=1.0, roughness=0.0))
    assert out["fresnel"] == "metal" and out["reflectivity"] == 1.0
    assert out["fresnel_tint"] == pytest.approx(gold) and out["diffuse"] == (0.0, 0.0, 0.0)
    half = fields(Surface(base_color=gold, metallic=0.5, roughness=0.6, specular_f0=0.04))
    coat = 0.5 * (1 - 0.6)  # the dielectric half's own reflection, faded by roughness
    assert half["reflectivity"] == pytest.approx(0.5 + coat)
    assert half["fresnel_tint"] == pytest.approx(tuple((0.5 * c + coat * 0.04) / (0.5 + coat) for c in gold))
    assert half["diffuse"] == pytest.approx(tuple(0.5 * 0.96 * c for c in gold))


def test_a_dielectric_reflects_less_the_rougher_it_is():
    smooth = fields(Surface(roughness=0.1, specular_f0=0.04))
    assert smooth["fresnel"] == "metal" and smooth["reflectivity"] == pytest.approx(0.9)
    assert smooth["fresnel_tint"] == pytest.approx((0.04,) * 3)
    assert fields(Surface(roughness=0.0))["reflectivity"] == 1.0
    assert fields(Surface(roughness=1.0))["reflectivity"] == 0.0
    assert fields(Surface(roughness=0.0, specular_f0=0.0))["reflectivity"] == 0.0  # (a Diffuse BSDF)


def test_alpha_lets_light_through_unbent():
    out = fields(Surface(base_color=(1, 1, 1), alpha=0.25, roughness=1.0, specular_f0=0.0))
    assert out["transparency"] == pytest.approx(0.75) and out["speed_of_light"] == 1.0
    assert out["fresnel"] == "constant" and out["diffuse"] == pytest.approx((0.25,) * 3)


def test_emission_and_mixes():
    lamp = Surface(base_color=(0, 0, 0), emission=(2.0, 1.0, 0.5), roughness=1.0, specular_f0=0.0)
    assert fields(lamp)["emissive"] == (2.0, 1.0, 0.5) and fields(lamp)["diffuse"] == (0.0, 0.0, 0.0)
    red = Surface(base_color=(1, 0, 0), roughness=1.0, specular_f0=0.0)
    glass = Surface(transmission=1.0, roughness=0.0)
    mixed = fields(Mix(0.25, red, glass))
    assert mixed["diffuse"] == pytest.approx((0.75, 0, 0)) and mixed["transparency"] == pytest.approx(0.25)
    assert mixed["fresnel"] == "dielectric" and mixed["reflectivity"] == pytest.approx(0.25)
    added = fields(Add(red, lamp))
    assert added["diffuse"] == pytest.approx((1, 0, 0)) and added["emissive"] == (2.0, 1.0, 0.5)
    assert fields(None)["diffuse"] == (0.0, 0.0, 0.0)  # nothing connected: black, as in Cycles


def test_a_picture_on_base_color_is_the_diffuse_colour():
    out = fields(Surface(base_color=(1, 1, 1), image="/pictures/bricks.png", roughness=1.0, specular_f0=0.0))
    assert out["image"] == "/pictures/bricks.png" and out["diffuse"] == (1.0, 1.0, 1.0)


def _matrix(position=(0.0, 0.0, 0.0), rotation=np.eye(3), scale=(1.0, 1.0, 1.0)) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rotation @ np.diag(scale)
    m[:3, 3] = position
    return m


def test_lights_in_blender_units():
    point = Light(**light_units.point(_matrix((1, 2, 3)), (1.0, 0.5, 0.0), 1000.0, 0.0, 16, "Key Light"))
    assert point.kind == "sphere" and point.position == (1, 2, 3) and point.name == "Key Light"
    assert point.color == pytest.approx((1000 / (4 * math.pi ** 2), 500 / (4 * math.pi ** 2), 0.0))
    assert point.samples == 1 and not point.soft  # radius 0: one feeler, hard shadows
    sun = Light(**light_units.sun(_matrix(), (1, 1, 1), 3.0, math.radians(2.0), 8))
    assert sun.kind == "sun" and sun.direction == (0, 0, -1) and sun.color == pytest.approx((3 / math.pi,) * 3)
    assert sun.angle == pytest.approx(2.0) and sun.samples == 8
    tilted = np.array([[1, 0, 0], [0, 0, -1], [0, 1, 0]], dtype=float)  # local -Z to world +Y
    spot = Light(**light_units.spot(_matrix(rotation=tilted), (1, 1, 1), 100.0, 0.1, math.radians(40), 0.2, 4))
    assert spot.direction == pytest.approx((0, 1, 0)) and spot.spot_size == pytest.approx(40.0)
    assert spot.spot_blend == 0.2 and spot.samples == 4 and spot.radius == pytest.approx(0.1)


def test_an_area_light_is_its_power_over_pi_squared_per_unit_area():
    for shape, size_y, surface in (("SQUARE", 9.0, 2.0 * 2.0), ("RECTANGLE", 0.5, 2.0 * 0.5),
                                   ("DISK", 9.0, math.pi), ("ELLIPSE", 0.5, math.pi / 4 * 2.0 * 0.5)):
        light = Light(**light_units.area(_matrix(), (1, 1, 1), 100.0, shape, 2.0, size_y, 16))
        assert light.color[0] * surface == pytest.approx(100.0 / math.pi ** 2), shape
        assert light.shape == ("ellipse" if shape in ("DISK", "ELLIPSE") else "rectangle")
    stretched = Light(**light_units.area(_matrix(scale=(3.0, 1.0, 1.0)), (1, 1, 1), 100.0, "SQUARE", 2.0, 0, 16))
    assert stretched.size == pytest.approx((6.0, 2.0))  # the object's scale stretches the light
    assert stretched.color[0] * 12.0 == pytest.approx(100.0 / math.pi ** 2)


def test_sdl_light_colours_back_to_blender_units():
    color = (2.0, 1.0, 0.5)
    rgb, watts = light_units.watts_of_sphere_light(color)
    assert Light(**light_units.point(_matrix(), rgb, watts, 0.0, 1)).color == pytest.approx(color)
    rgb, strength = light_units.strength_of_sun(color)
    assert Light(**light_units.sun(_matrix(), rgb, strength, 0.0, 1)).color == pytest.approx(color)
    rgb, watts = light_units.watts_of_area_light(color, 2.0 * 0.5)
    assert Light(**light_units.area(_matrix(), rgb, watts, "RECTANGLE", 2.0, 0.5, 1)).color == pytest.approx(color)
