"""Anti-aliasing: regular, jittered and adaptive supersampling."""
from __future__ import annotations

import numpy as np
import pytest

import tracer
from helpers import Camera, scene_of, shape
from tracer import sampling
from tracer.errors import TracerError


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
        edges = sampling.contrast_mask(aliased[..., None].repeat(3, axis=2), 0.5)
        near_edges = edges.copy()
        for axis in (0, 1):
            for step in (-1, 1):
                near_edges |= np.roll(edges, step, axis=axis)
        assert np.all(near_edges[partial])


def test_ray_counts_and_adaptive_economy():
    full = tracer.render(_edge_scene(), 40, 30, samples=9, sampling_mode="regular")
    assert full.rays.camera == 40 * 30 * 9
    adaptive = tracer.render(_edge_scene(), 40, 30, samples=9, sampling_mode="adaptive")
    base = tracer.render(_edge_scene(), 40, 30).image
    refined = sampling.contrast_mask(base, sampling.DEFAULT_THRESHOLD)
    assert adaptive.rays.camera == 40 * 30 + refined.sum() * 9
    assert adaptive.rays.camera < full.rays.camera / 3
    assert np.array_equal(adaptive.image[~refined], base[~refined])


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
