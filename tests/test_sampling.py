"""Anti-aliasing: regular, jittered and adaptive supersampling."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import tracer
from helpers import Camera, scene_of, shape
from tracer.compile import compile_scene
from tracer import sampling
from tracer.errors import TracerError

SCENES = Path(__file__).resolve().parent.parent / "scenes"


def _edge_scene():
    # A white emissive square, turned so its edges cross pixels at odd angles, on black.
    from tracer.transforms import rotation
    return scene_of(shape("square", rotation(17, 0, 0, 1), emissive=(1, 1, 1), ambient=(0, 0, 0), diffuse=(0, 0, 0)),
                    background=(0, 0, 0), camera=Camera((0, 0, 4), (0, 0, 0), (0, 1, 0), 40))


def test_one_sample_is_the_pixel_centre_ray():
    a = tracer.render(_edge_scene(), 32, 24).image
    for mode in sampling.MODES:
        assert np.array_equal(tracer.render(_edge_scene(), 32, 24, samples=1, sampling_mode=mode).image, a)


def test_aliased_edges_have_no_partial_pixels_and_antialiased_ones_do():
    aliased = tracer.render(_edge_scene(), 48, 36).image[..., 0]
    assert set(np.unique(aliased)) <= {0.0, 1.0}
    for mode in sampling.MODES:
        smooth = tracer.render(_edge_scene(), 48, 36, samples=16, sampling_mode=mode).image[..., 0]
        partial = (smooth > 0.02) & (smooth < 0.98)
        assert partial.sum() > 20, mode
        # Partial pixels lie only along the edges of the square (within a pixel of the aliased steps).
        edges = _differs_from_a_neighbour(aliased)
        near_edges = edges.copy()
        for axis in (0, 1):
            for step in (-1, 1):
                near_edges |= np.roll(edges, step, axis=axis)
        assert np.all(near_edges[partial])


def _differs_from_a_neighbour(image: np.ndarray) -> np.ndarray:
    """Pixels of a (H, W) image whose value differs from a 4-neighbour's."""
    mask = np.zeros(image.shape, dtype=bool)
    vertical, horizontal = np.diff(image, axis=0) != 0, np.diff(image, axis=1) != 0
    mask[:-1] |= vertical
    mask[1:] |= vertical
    mask[:, :-1] |= horizontal
    mask[:, 1:] |= horizontal
    return mask


def test_adaptive_spends_about_n_rays_per_pixel_on_the_edges():
    """Adaptive N: N camera rays per pixel on average at most, most of them spent (here, with few distinct
    edges, the ladder's steps leave more unspent than on the bundled scenes); the pixels whose centre rays
    show no edge keep their colour (a pilot pixel's jittered rays of a flat colour give it again), the edges
    get partial colours."""
    from tracer.target import centre_error

    full = tracer.render(_edge_scene(), 40, 30, samples=9, sampling_mode="regular")
    assert full.rays.camera == 40 * 30 * 9
    adaptive = tracer.render(_edge_scene(), 40, 30, samples=9, sampling_mode="adaptive")
    assert 0.8 * full.rays.camera <= adaptive.rays.camera <= full.rays.camera
    base = tracer.render(_edge_scene(), 40, 30).image
    unseen = centre_error(base) == 0.0
    assert 0.5 < unseen.mean() < 1.0
    assert np.array_equal(adaptive.image[unseen], base[unseen])
    near_edges = adaptive.image[~unseen][:, 0]
    assert np.count_nonzero((near_edges > 0.02) & (near_edges < 0.98)) > 0.5 * near_edges.size


def test_adaptive_keeps_converging_where_centre_rays_see_no_edge():
    """On scenes/textures.sdl's bricks and checks, centre rays look smooth where a pixel holds fine texture:
    adaptive sampling that refines only what they show stopped improving from 16 samples on (at 0.037,
    docs/accuracy.md).  Now 128 samples have a quarter of 16's error, close to uniform jittered 128's."""
    scene = compile_scene(tracer.load(SCENES / "textures.sdl"))

    def error(samples, mode):
        image = tracer.render(scene, 48, 36, samples=samples, sampling_mode=mode).image
        return float(np.sqrt(np.mean((np.clip(image, 0, 1) - reference) ** 2)))

    reference = np.clip(tracer.render(scene, 48, 36, samples=512, seed=99).image, 0, 1)
    sixteen, many = error(16, "adaptive"), error(128, "adaptive")
    assert many < 0.4 * sixteen and many < 1.25 * error(128, "jittered")


def test_strata():
    assert sampling.grid_shape(16) == (4, 4) and sampling.grid_shape(8) == (2, 4) and sampling.grid_shape(7) == (1, 7)
    dy, dx = sampling.offsets(16, False, np.array([0]), np.array([0]))
    assert sorted(set(np.round(dx[0], 6))) == [0.125, 0.375, 0.625, 0.875]
    dy, dx = sampling.offsets(16, True, np.arange(500) // 20, np.arange(500) % 20, seed=1)
    cell_x = np.floor(dx * 4).astype(int)
    cell_y = np.floor(dy * 4).astype(int)
    assert np.all(cell_x == np.tile(np.arange(4), 4)) and np.all(cell_y == np.repeat(np.arange(4), 4))


def test_jittered_render_is_repeatable():
    a = tracer.render(_edge_scene(), 24, 18, samples=4).image
    assert np.array_equal(a, tracer.render(_edge_scene(), 24, 18, samples=4).image)


@pytest.mark.parametrize("samples, mode", [(0, "jittered"), (4, "random")])
def test_bad_settings(samples, mode):
    with pytest.raises(TracerError):
        tracer.render(_edge_scene(), 8, 8, samples=samples, sampling_mode=mode)
