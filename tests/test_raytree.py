"""The NumPy path traces its ray trees breadth first (tracer.raytree): a batch per level of the trees, not one
per node, and still the rays, counts and colours of the recursion the C core runs."""
from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

from helpers import Camera, scaling, scene_of, shape, translation
from tracer import native, raytree, trace
from tracer.compile import compile_scene
from tracer.render import render
from tracer.savings import RaySavings
from tracer.sdl.parser import parse_sdl
from tracer.trace import Tracer

requires_core = pytest.mark.skipif(native.load_error is not None, reason=f"C core not built: {native.load_error}")


def _glass_walls(depth: int):
    """Two glass slabs facing each other, reflecting and transmitting half: every ray that hits asks for two
    children, so a tree holds up to 2^(depth + 1) rays (the default cutoff would end it; these tests set 0)."""
    glass = dict(reflectivity=0.5, transparency=0.5, speed_of_light=0.8, diffuse=(0.2, 0.3, 0.4))
    return scene_of(shape("cube", translation(0, 0, -1.2) @ scaling(100, 100, 0.1), **glass),
                    shape("cube", translation(0, 0, 1.2) @ scaling(100, 100, 0.1), **glass),
                    camera=Camera((0, 0, 0), (0.1, 0.05, -1), (0, 1, 0), 40), max_recursion_depth=depth,
                    min_reflectivity=0.0, min_transparency=0.0)


def _nested_glass(reflect: float, transmit: float, speed: float):
    """The fuzz run's deep-glass case (seeds 2804008605, 2812008591, 2851008762, 2853008648; the regressions
    numpy_deep_glass_*.sdl): a hollow glass ball and a block behind it, depth 64, trees the ray budget cuts."""
    return parse_sdl("camera 0 0 6  0 0 0  0 1 0  40\nlight 2 3 4  1 1 1\nmaxRecursionDepth 64\n"
                     "minReflectivity 0 minTransparency 0\n"
                     f"reflectivity {reflect} transparency {transmit} speedOfLight {speed}\n"
                     "difference sphere push scale 0.6 0.6 0.6 sphere pop\npush translate 0 0 -1 cube pop\n")


def _traced(scene, savings: RaySavings, monkeypatch, width: int = 4, height: int = 3, spread: float = 0.3):
    """(batches of rays the NumPy path traced, secondary rays it traced) for the camera rays of a small image:
    a batch is a call of first_hits, whatever the code around it."""
    calls = []
    first_hits = trace.first_hits

    def counted(scene_, origins, *args, **kwargs):
        calls.append(origins.shape[0])
        return first_hits(scene_, origins, *args, **kwargs)

    monkeypatch.setattr(trace, "first_hits", counted)
    tracer = Tracer(compile_scene(scene), savings)
    v, u = np.meshgrid(np.linspace(-spread, spread, height), np.linspace(-spread, spread, width),
                       indexing="ij")
    look = np.asarray(scene.camera.look, float) - np.asarray(scene.camera.eye, float)
    directions = look / np.linalg.norm(look) + np.stack([u.ravel(), v.ravel(), np.zeros(u.size)], axis=1)
    tracer.camera_rays(np.broadcast_to(np.asarray(scene.camera.eye, float), directions.shape).copy(), directions)
    return len(calls), tracer.counts.reflection + tracer.counts.refraction


def test_the_batches_grow_with_the_depth_not_with_the_rays(monkeypatch):
    savings = RaySavings(cutoff=0.0)
    shallow_batches, shallow_rays = _traced(_glass_walls(5), savings, monkeypatch)
    deep_batches, deep_rays = _traced(_glass_walls(10), savings, monkeypatch)
    assert deep_rays >= 8 * shallow_rays  # (the trees double at every level: 2^5 more rays, less those that escape)
    assert shallow_batches <= 5 + 1 and deep_batches <= 10 + 1  # one per level (a batch per node: one per path)


def test_a_tree_the_budget_cuts_takes_few_batches(monkeypatch):
    batches, rays = _traced(_nested_glass(0.95, 0.95, 0.5), RaySavings(), monkeypatch, 2, 1, 0.1)
    assert rays > 2000  # (trees of up to 4,096 rays each)
    assert batches * 10 < rays  # (a batch per node: about one per ray, ~3.5 rays each at 12 x 9)


@requires_core
@pytest.mark.parametrize("budget", [3, 50, 700])
@pytest.mark.parametrize("glass", [(0.95, 0.95, 0.5), (0.9, 0.6, 1.5), (1.06, 1.33, 0.7)])
def test_breadth_first_cuts_the_recursions_rays(budget, glass):
    """Where the budget cuts trees whose rays escape, end on the depth limit and are cut by the cutoff, the
    breadth-first trace's bounds decide every ray as the C core's recursion does: the same rays, counts and
    image, bit for bit."""
    scene = _nested_glass(*glass)
    limited = replace(RaySavings(), ray_budget=budget)
    c = render(scene, 12, 9, backend="c", savings=limited)
    n = render(scene, 12, 9, backend="numpy", savings=limited)
    assert c.rays == n.rays
    assert c.rays.skipped_budget > 0
    assert np.array_equal(c.image, n.image)


def test_shade_traces_the_tree_of_each_ray_with_its_own_budget():
    """Tracer.shade on rays at a level below 0 and the same rays one at a time: the same colours and counts
    (each ray's tree has a camera ray's budget, whatever shares its batch)."""
    scene = compile_scene(_nested_glass(0.95, 0.95, 0.5))
    savings = replace(RaySavings(), ray_budget=40)
    origins = np.array([[0.0, 0.0, 6.0]] * 3)
    directions = np.array([[0.0, 0.0, -1.0], [0.1, 0.05, -1.0], [0.3, -0.2, -1.0]])
    together = Tracer(scene, savings)
    colors = together.shade(origins, directions, 0, trace.Media.air(3))
    for k in range(3):
        alone = Tracer(scene, savings)
        color = alone.shade(origins[k:k + 1], directions[k:k + 1], 0, trace.Media.air(1))
        assert np.array_equal(color[0], colors[k])
    assert together.counts.reflection > 40 and together.counts.skipped_budget > 0


def test_trees_too_large_to_hold_at_once_are_traced_in_parts(monkeypatch):
    """Past raytree.MAX_RAYS rays a batch is traced again in halves: the same image and counts."""
    scene = _nested_glass(0.95, 0.95, 0.5)
    limited = replace(RaySavings(), ray_budget=400)
    whole = render(scene, 8, 6, backend="numpy", savings=limited)
    monkeypatch.setattr(raytree, "MAX_RAYS", 300)
    parts = render(scene, 8, 6, backend="numpy", savings=limited)
    assert whole.rays == parts.rays and whole.rays.reflection + whole.rays.refraction > 1000
    assert np.array_equal(whole.image, parts.image)
