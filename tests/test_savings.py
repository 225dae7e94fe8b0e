"""No useless rays (tracer.savings): the rays skipped change no bundled image visibly, are counted per
reason, and are skipped the same way by the C core and the NumPy path."""
from __future__ import annotations

import json
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import tracer
from helpers import Camera, Light, scaling, scene_of, shape, translation
from tracer import native
from tracer.cli import main
from tracer.compile import compile_scene
from tracer.render import render
from tracer.savings import SKIP_REASONS, RaySavings
from tracer.skippable import sealed_lights

ROOT = Path(__file__).resolve().parent.parent
SCENES = sorted((ROOT / "scenes").glob("*.sdl"))
requires_core = pytest.mark.skipif(native.load_error is not None, reason=f"C core not built: {native.load_error}")
BACKENDS = ["numpy", pytest.param("c", marks=requires_core)]


def _total(result) -> int:
    return sum(result.rays.as_dict().values())


def _max_change_8bit(a, b) -> float:
    """Largest difference per pixel and channel, in 8-bit steps of the written image."""
    return float(np.abs(np.clip(a.image, 0, 1) - np.clip(b.image, 0, 1)).max() * 255)


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_bundled_scenes_change_by_at_most_half_a_step(path):
    scene = tracer.load(path)
    backend = "auto"
    every = render(scene, 160, 120, backend=backend, savings=RaySavings.none())
    saved = render(scene, 160, 120, backend=backend)
    assert _max_change_8bit(saved, every) <= 0.5
    assert _total(saved) <= _total(every)
    assert sum(every.rays.skipped().values()) == 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_glass_traces_at_least_15_percent_fewer_rays(backend):
    scene = tracer.load(ROOT / "scenes" / "glass.sdl")
    size = (160, 120) if backend == "c" else (80, 60)
    every = render(scene, *size, backend=backend, savings=RaySavings.none())
    saved = render(scene, *size, backend=backend)
    assert _total(saved) <= 0.85 * _total(every)
    skipped = saved.rays.skipped()
    assert skipped["cutoff"] > 0 and skipped["inside_shadow"] > 0 and skipped["shared_tir"] > 0
    assert _max_change_8bit(saved, every) <= 0.5


@requires_core
def test_both_backends_skip_the_same_rays():
    scene = tracer.load(ROOT / "scenes" / "glass.sdl")
    c = render(scene, 64, 48, backend="c")
    n = render(scene, 64, 48, backend="numpy")
    assert c.rays == n.rays  # every kind cast and every reason skipped
    assert np.abs(c.image - n.image).max() <= 1 / 255


@pytest.mark.parametrize("backend", BACKENDS)
def test_shared_total_internal_reflection_is_exact(backend):
    """The mirror ray stands for the internally reflected one: the same image, bit for bit, fewer rays."""
    scene = tracer.load(ROOT / "scenes" / "glass.sdl")
    only_tir = replace(RaySavings.none(), shared_tir=True)
    every = render(scene, 48, 36, backend=backend, savings=RaySavings.none())
    shared = render(scene, 48, 36, backend=backend, savings=only_tir)
    assert np.array_equal(shared.image, every.image)
    assert shared.rays.skipped_shared_tir > 0
    assert shared.rays.reflection < every.rays.reflection


def _mirror_scene():
    """A pure mirror (no diffuse, no specular) beside a lit matte sphere."""
    mirror = shape("cube", translation(0, 0, -2) @ scaling(3, 3, 0.1), diffuse=(0, 0, 0), specular=(0, 0, 0),
                   reflectivity=0.8, ambient=(0, 0, 0))
    ball = shape("sphere", translation(0, 0, 0), diffuse=(0.8, 0.3, 0.2))
    return scene_of(mirror, ball, lights=[Light((3, 4, 5), (1, 1, 1))],
                    camera=Camera((1, 1, 6), (0, 0, -1), (0, 1, 0), 50))


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_material_that_takes_no_light_casts_no_feelers(backend):
    scene = _mirror_scene()
    only_dark = replace(RaySavings.none(), dark_materials=True)
    every = render(scene, 40, 30, backend=backend, savings=RaySavings.none())
    saved = render(scene, 40, 30, backend=backend, savings=only_dark)
    assert saved.rays.skipped_dark_material > 0
    assert every.rays.shadow - saved.rays.shadow == saved.rays.skipped_dark_material
    assert np.array_equal(saved.image, every.image)


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_cutoff_stops_long_chains_of_weak_reflections(backend):
    mirror = dict(reflectivity=0.5, diffuse=(0, 0, 0), ambient=(0.2, 0.2, 0.2))
    scene = scene_of(shape("cube", translation(0, 0, -1.2) @ scaling(100, 100, 0.1), **mirror),
                     shape("cube", translation(0, 0, 1.2) @ scaling(100, 100, 0.1), **mirror),
                     camera=Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), 2), max_recursion_depth=30)
    every = render(scene, 8, 6, backend=backend, savings=RaySavings.none())
    cut = render(scene, 8, 6, backend=backend)
    # weight 0.5^k: the 9th bounce (1/512) is the last traced, the 10th is cut
    assert every.rays.reflection == 30 * 48
    assert cut.rays.reflection == 9 * 48 and cut.rays.skipped_cutoff == 48
    assert np.abs(cut.image - every.image).max() <= 2 * 0.2 * 0.5 ** 10  # the geometric tail left out


def test_sealed_lights_only_for_closed_solids_with_the_light_outside():
    glass = dict(transparency=0.9, speed_of_light=0.7)
    scene = scene_of(shape("sphere", **glass),  # holds the first light
                     shape("sphere", translation(5, 0, 0), **glass),
                     shape("square", translation(-5, 0, 0), **glass),  # a sheet: no inside
                     shape("sphere", translation(0, 5, 0)),  # opaque: rays do not get in
                     lights=[Light((0.2, 0.1, 0), (1, 1, 1)), Light((0, 0, 20), (1, 1, 1))])
    sealed = sealed_lights(compile_scene(scene))
    assert sealed.tolist() == [[False, True], [True, True], [False, False], [False, False]]


def test_cli_stats_count_skipped_rays_and_all_rays_skips_none(tmp_path, capsys):
    glass = str(ROOT / "scenes" / "glass.sdl")
    out = str(tmp_path / "g.png")
    assert main(["render", glass, "-o", out, "--width", "48", "--height", "36", "--stats", "-q"]) == 0
    saved = json.loads(capsys.readouterr().out)
    assert set(saved["skipped"]) == set(SKIP_REASONS) and saved["skipped"]["inside_shadow"] > 0
    assert main(["render", glass, "-o", out, "--width", "48", "--height", "36", "--stats", "-q", "--all-rays"]) == 0
    every = json.loads(capsys.readouterr().out)
    assert not any(every["skipped"].values())
    assert sum(every["rays"].values()) > sum(saved["rays"].values())
    assert main(["render", glass, "-o", out, "--cutoff", "-1", "-q"]) == 2
    assert "error: --cutoff" in capsys.readouterr().err


def _facing_mirrors(reflect: float, transmit: float, depth: int = 64):
    """Two glass walls facing each other, reflecting and transmitting: without a budget the tree doubles at
    every level (2^64 rays at depth 64)."""
    glass = dict(reflectivity=reflect, transparency=transmit, speed_of_light=0.8, diffuse=(0.2, 0.3, 0.4))
    return scene_of(shape("cube", translation(0, 0, -1.2) @ scaling(100, 100, 0.1), **glass),
                    shape("cube", translation(0, 0, 1.2) @ scaling(100, 100, 0.1), **glass),
                    camera=Camera((0, 0, 0), (0.1, 0.05, -1), (0, 1, 0), 40), max_recursion_depth=depth,
                    min_reflectivity=0.0, min_transparency=0.0)


@pytest.mark.parametrize("budget", [1, 2, 7, 40, 300])
@requires_core
def test_the_ray_budget_cuts_the_same_rays_in_both_backends(budget):
    """The budget is shared down the tree by one rule in both backends: the same rays traced and cut, to the
    ray, and the same image."""
    scene = _facing_mirrors(0.95, 0.95)
    limited = replace(RaySavings(), ray_budget=budget)
    c = render(scene, 6, 4, backend="c", savings=limited)
    n = render(scene, 6, 4, backend="numpy", savings=limited)
    assert c.rays == n.rays
    assert c.rays.skipped_budget > 0
    assert c.rays.reflection + c.rays.refraction <= budget * 24
    assert np.abs(c.image - n.image).max() <= 1 / 255


@pytest.mark.parametrize("backend", BACKENDS)
def test_the_ray_budget_bounds_the_tree_of_each_camera_ray(backend):
    scene = _facing_mirrors(0.95, 0.95)
    result = render(scene, 4, 3, backend=backend, savings=RaySavings.none())
    secondary = result.rays.reflection + result.rays.refraction
    assert secondary <= RaySavings().ray_budget * 12  # (12 camera rays; the depth limit alone allows 2^64 each)
    assert result.rays.skipped_budget > 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_a_tree_within_the_budget_is_traced_whole(backend):
    """Reflectivity and transparency that add up to 1: the cutoff ends the tree long before the budget."""
    scene = _facing_mirrors(0.6, 0.4)
    within = render(scene, 4, 3, backend=backend)
    unlimited = render(scene, 4, 3, backend=backend, savings=replace(RaySavings(), ray_budget=10**9))
    assert within.rays == unlimited.rays and within.rays.skipped_budget == 0
    assert np.array_equal(within.image, unlimited.image)


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_no_bundled_scene_meets_the_budget(path):
    assert render(tracer.load(path), 64, 48, savings=RaySavings.none()).rays.skipped_budget == 0


def test_the_command_line_says_once_that_the_budget_cut_rays(tmp_path, capsys):
    scene = tmp_path / "glass.sdl"
    scene.write_text("camera 0 0 6  0 0 0  0 1 0  40\nlight 2 3 4  1 1 1\n"
                     "maxRecursionDepth 64 minReflectivity 0 minTransparency 0\n"
                     "transparency 0.95 reflectivity 0.95 speedOfLight 0.7\nsphere\npush scale 0.5 0.5 0.5 sphere pop\n")
    assert main(["render", str(scene), "-o", str(tmp_path / "g.png"), "--width", "16", "--height", "12", "-q"]) == 0
    lines = capsys.readouterr().err.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"warning: {scene}:") and "4,096" in lines[0], lines
