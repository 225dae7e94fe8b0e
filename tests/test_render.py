"""Rendering: blocks, progressive passes, callbacks, cancel, the camera, shading values, live effects (each on
both backends where it renders)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from helpers import Camera, Light, rotation, scaling, scene_of, shape, translation
from tracer.camera import CameraFrame, framing_camera
from tracer.compile import compile_scene
from tracer.errors import RenderCancelled, TracerError
from tracer.imageio import to_8bit
from tracer.render import render
from tracer.tiles import TilePlan, block_passes
from tracer.backend import make_tracer


def _scene(**settings):
    return scene_of(
        shape("plane", rotation(-90, 1, 0, 0), diffuse=(0.5, 0.5, 0.5)),
        shape("sphere", translation(0, 1, 0), diffuse=(0.9, 0.1, 0.1), specular=(0.6, 0.6, 0.6),
              specular_exponent=30),
        shape("cube", translation(2.2, 0.7, 0) @ scaling(0.7, 0.7, 0.7), diffuse=(0.1, 0.8, 0.1)),
        lights=[Light((4, 6, 5), (1, 1, 1))],
        camera=Camera((0, 2.5, 7), (0, 0.8, 0), (0, 1, 0), 45), **settings)


def test_block_passes():
    assert block_passes(8, progressive=True) == [8, 4, 2, 1]
    assert block_passes(6, progressive=True) == [4, 2, 1]
    assert block_passes(3, progressive=False) == [3]
    with pytest.raises(TracerError):
        block_passes(0, progressive=False)


def test_block_size_fills_blocks_with_lower_left_sample(backend):
    full = render(_scene(), 48, 32, backend=backend).image
    blocky = render(_scene(), 48, 32, block_size=4, backend=backend).image
    h = full.shape[0]
    for top in range(0, h, 4):
        for left in range(0, 48, 4):
            block = blocky[top:top + 4, left:left + 4]
            # Rows count from the bottom: a block's sample is its lower-left pixel.
            bottom_row = h - 1 - ((h - 1 - (top + 3)) // 4 * 4)
            sample = full[bottom_row, left]
            assert np.all(block == sample)


def test_progressive_traces_each_pixel_once_and_matches_full_render(backend):
    seen = []
    result = render(_scene(), 40, 30, block_size=8, progressive=True, tile=16, on_tile=seen.append,
                    backend=backend)
    assert result.rays.camera == 40 * 30
    assert np.array_equal(result.image, render(_scene(), 40, 30, backend=backend).image)
    strides = [u.block_size for u in seen]
    assert strides == sorted(strides, reverse=True) and set(strides) == {8, 4, 2, 1}
    fractions = [u.fraction for u in seen]
    assert fractions == sorted(fractions) and fractions[-1] == 1.0
    # Each pass's tiles cover the image exactly once.
    for stride in (8, 4, 2, 1):
        cover = np.zeros((30, 40), dtype=int)
        for u in seen:
            if u.block_size == stride:
                cover[u.y0:u.y1, u.x0:u.x1] += 1
        assert np.all(cover == 1)


def test_cancel_stops_between_tiles(backend):
    calls = []
    with pytest.raises(RenderCancelled):
        render(_scene(), 64, 64, tile=16, on_tile=calls.append, cancel=lambda: len(calls) >= 3, backend=backend)
    assert len(calls) == 3


@pytest.mark.parametrize("width, height", [(0, 10), (10, -1), (100000, 10)])
def test_bad_image_sizes_are_refused(width, height):
    with pytest.raises(TracerError, match="between 1 and"):
        render(_scene(), width, height)


def test_shading_matches_blinn_phong_by_hand(backend):
    # One ray straight down onto the top of a unit sphere; light above and to the side.
    mat = dict(ambient=(0.2, 0.3, 0.4), diffuse=(0.5, 0.6, 0.7), specular=(0.8, 0.8, 0.8),
               specular_exponent=10, emissive=(0.01, 0.02, 0.03))
    light_pos, light_col = np.array([3.0, 4.0, 0.0]), np.array([0.9, 0.8, 0.7])
    scene = scene_of(shape("sphere", **mat), lights=[Light(tuple(light_pos), tuple(light_col))],
                     global_ambient=(0.5, 0.5, 0.5))
    tracer = make_tracer(compile_scene(scene), backend)
    color = tracer.camera_rays(np.array([[0.0, 5.0, 0.0]]), np.array([[0.0, -1.0, 0.0]]))[0]
    p, m, v = np.array([0, 1.0, 0]), np.array([0, 1.0, 0]), np.array([0, 1.0, 0])
    s = (light_pos - p) / np.linalg.norm(light_pos - p)
    h = (s + v) / np.linalg.norm(s + v)
    expected = (np.array(mat["emissive"]) + 0.5 * np.array(mat["ambient"])
                + light_col * (np.dot(s, m) * np.array(mat["diffuse"]) + np.dot(h, m) ** 10 * 0.8))
    assert color == pytest.approx(expected, rel=1e-12)


def test_symmetric_scene_gives_symmetric_image(backend):
    scene = scene_of(
        shape("plane", rotation(-90, 1, 0, 0), diffuse=(0.5, 0.5, 0.5)),
        shape("sphere", translation(0, 1, 0), diffuse=(0.8, 0.3, 0.2), specular=(0.5, 0.5, 0.5), specular_exponent=20),
        shape("cone", translation(-2, 0, 0) @ rotation(-90, 1, 0, 0)),
        shape("cone", translation(2, 0, 0) @ rotation(-90, 1, 0, 0)),
        lights=[Light((0, 6, 4), (1, 1, 1))], camera=Camera((0, 2, 8), (0, 1, 0), (0, 1, 0), 40))
    image = render(scene, 64, 48, backend=backend).image
    assert np.abs(image - image[:, ::-1]).max() < 1e-9
    assert np.abs(image - image[::-1]).max() > 0.1  # and it is not trivially uniform


def test_default_camera_frames_every_object(backend):
    objects = [shape("sphere", translation(x, y, z)) for x, y, z in [(-5, 0, 0), (6, 2, -3), (0, -4, 2)]]
    scene = scene_of(*objects, background=(0, 0, 0))
    compiled = compile_scene(scene)
    cam = framing_camera(compiled, 4 / 3)
    frame = CameraFrame.from_camera(cam, 4 / 3)
    for obj in objects:
        c = obj.matrix[:3, 3]
        rel = c - frame.eye
        depth = -np.dot(rel, frame.n)
        x = np.dot(rel, frame.u) / depth / frame.half_width
        y = np.dot(rel, frame.v) / depth / frame.half_height
        assert depth > 0 and abs(x) < 0.9 and abs(y) < 0.9
    image = render(scene, 80, 60, backend=backend).image
    assert (image.max(axis=2) > 0).mean() > 0.01  # the objects are visible


def _counts(scene, backend):
    result = render(scene, 24, 18, backend=backend)
    assert result.backend == backend
    return result.rays


def test_only_live_effects_cast_rays(backend):
    base = _counts(_scene(), backend)
    assert base.shadow > 0 and base.reflection == 0 and base.refraction == 0
    dark = _scene()
    dark.lights.clear()
    assert _counts(dark, backend).shadow == 0
    mirror = _scene()
    mirror.objects.append(shape("cube", translation(-2.2, 0.7, 0), reflectivity=0.8))
    with_mirror = _counts(mirror, backend)
    assert with_mirror.reflection > 0 and with_mirror.refraction == 0
    weak = _scene()
    weak.objects.append(shape("cube", translation(-2.2, 0.7, 0), reflectivity=0.3))  # below minReflectivity 0.5
    assert _counts(weak, backend).reflection == 0
    glass = _scene()
    glass.objects.append(shape("sphere", translation(-2.2, 1, 1), transparency=0.9, speed_of_light=0.7))
    assert _counts(glass, backend).refraction > 0
    flat = _scene(max_recursion_depth=0)
    flat.objects.append(shape("sphere", translation(-2.2, 1, 1), transparency=0.9, reflectivity=0.9))
    counts = _counts(flat, backend)
    assert counts.reflection == 0 and counts.refraction == 0
    assert "refraction" not in compile_scene(flat).effects


def test_rays_go_through_pixel_centres():
    frame = CameraFrame.from_camera(Camera((0, 0, 0), (0, 0, -1), (0, 1, 0), 90), 2.0)
    d = frame.directions(np.array([0]), np.array([0]), 2, 4)[0]
    # 4 columns span [-W, W] = [-2, 2]: the first centre is at -2 + 0.5; 2 rows over [-1, 1]: -0.5.
    assert d == pytest.approx([-1.5, -0.5, -1.0])
    assert frame.half_height == pytest.approx(math.tan(math.radians(45)))


@pytest.mark.parametrize("settings", [
    dict(),
    dict(block_size=4),
    dict(block_size=8, progressive=True, tile=16),
    dict(samples=4, sampling_mode="jittered", tile=16),
    dict(samples=4, sampling_mode="regular", block_size=2, progressive=True),
    dict(samples=4, sampling_mode="adaptive", threshold=0.02, tile=16),
    dict(target_error=0.05),
])
def test_eight_bit_render_keeps_the_bytes_of_the_float_film(settings):
    """What the command line keeps (each tile's 8-bit values as it is traced, or the float film converted at
    the end where the mode needs floats) is the float image converted, byte for byte, in every mode; and the
    tile updates show the film so far in the same type."""
    scene = compile_scene(_scene())
    floats = render(scene, 37, 23, **settings)
    updates = []
    eight = render(scene, 37, 23, eight_bit=True, on_tile=updates.append, **settings)
    assert floats.image.dtype == np.float32 and floats.image.flags.c_contiguous
    assert eight.image.dtype == np.uint8 and eight.image.shape == (23, 37, 3)
    assert np.array_equal(eight.image, to_8bit(floats.image))
    assert eight.rays == floats.rays
    assert len(np.unique(eight.image)) > 20  # a picture, not a blank
    if updates:
        assert updates[-1].image.dtype == (np.float32 if settings.get("sampling_mode") == "adaptive" else np.uint8)


@pytest.mark.parametrize("settings", [
    dict(),
    dict(tile=8),  # bands that do not divide the height
    dict(block_size=8, progressive=True, tile=16),
    dict(samples=4, sampling_mode="jittered", tile=16),
    dict(block_size=64),  # a block (and so a tile) taller than the image
    dict(samples=4, sampling_mode="adaptive", threshold=0.02, tile=16),  # rows given at the end
    dict(target_error=0.05),
])
def test_rows_handed_over_as_bands_finish_are_the_eight_bit_image(settings):
    """render(..., on_rows=...) keeps no image: its bands, top first, make up the eight_bit image byte for
    byte, with the same ray counts and one update per tile; bands come while tracing (before the last
    tile's update) except in the modes that need the whole film."""
    scene = compile_scene(_scene())
    whole = render(scene, 37, 23, eight_bit=True, **settings)
    bands, events = [], []

    def take(rows):
        assert rows.dtype == np.uint8 and rows.shape[1:] == (37, 3)
        bands.append(rows.copy())  # (the band's buffer is reused for the next one)
        events.append("rows")

    streamed = render(scene, 37, 23, on_rows=take, on_tile=lambda update: events.append(update), **settings)
    assert streamed.image is None and streamed.stats()["width"] == 37 and streamed.stats()["height"] == 23
    assert np.array_equal(np.concatenate(bands), whole.image)
    assert streamed.rays == whole.rays
    updates = [event for event in events if event != "rows"]
    whole_film = settings.get("sampling_mode") == "adaptive" or "target_error" in settings
    if not whole_film:
        assert all(update.image is None for update in updates)
        assert len(updates) == updates[-1].tiles_total == updates[-1].tiles_done
        tile = TilePlan(37, 23, **settings).tile
        assert [len(band) for band in bands] == [min(tile, 23 - r0) for r0 in reversed(range(0, 23, tile))]
        if len(bands) > 1:  # the top band went out before the last tile was traced
            assert events.index("rows") < events.index(updates[-1])
