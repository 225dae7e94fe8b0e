"""The tile scheduler (tracer.tiles): one plan of passes and tiles for the command line, a cluster and the
add-on; sub-pixel samples keyed by pixel, so that any cut into tiles, in any order, gives the same bytes."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer import sampling, tiles
from tracer.backend import make_tracer
from tracer.camera import CameraFrame
from tracer.compile import compile_scene

SCENES = Path(__file__).resolve().parent.parent / "scenes"
WIDTH, HEIGHT = 45, 34  # not multiples of any tile size: tiles at the edges are cut short


@pytest.fixture(scope="module")
def compiled():
    return compile_scene(tracer.load(SCENES / "glass.sdl"))


def _shade(compiled, plan):
    frame = CameraFrame.from_camera(compiled.scene.camera, plan.width / plan.height)
    return tiles.PixelTracer(plan, make_tracer(compiled), tiles.camera_rays_for(frame, plan.width, plan.height))


def test_pixel_offsets_depend_on_the_pixel_alone():
    rows, cols = np.arange(40) // 8, np.arange(40) % 8
    dy, dx = sampling.offsets(9, True, rows, cols, seed=3)
    pick = [31, 2, 17]  # the same pixels drawn alone, in another order
    dy_alone, dx_alone = sampling.offsets(9, True, rows[pick], cols[pick], seed=3)
    assert np.array_equal(dy[pick], dy_alone) and np.array_equal(dx[pick], dx_alone)
    other_seed, _ = sampling.offsets(9, True, rows, cols, seed=4)
    assert not np.any(other_seed == dy)
    # Each of a pixel's samples stays in its own stratum, and neighbouring pixels differ.
    assert np.all(np.floor(dy * 3) == np.repeat(np.arange(3), 3)) and np.all(np.floor(dx * 3) == np.tile(np.arange(3), 3))
    assert len({tuple(row) for row in np.round(dx, 12)}) == 40


def test_uniforms_are_spread_evenly():
    u, v = sampling.pixel_uniforms(np.arange(20000) // 200, np.arange(20000) % 200, 2, seed=0)
    for values in (u.ravel(), v.ravel()):
        counts, _ = np.histogram(values, bins=10, range=(0, 1))
        assert counts.min() > 0.9 * values.size / 10 and counts.max() < 1.1 * values.size / 10
    assert abs(np.corrcoef(u[:, 0], v[:, 0])[0, 1]) < 0.05


@pytest.mark.parametrize("settings", [
    dict(samples=4, sampling_mode="jittered"),
    dict(samples=4, sampling_mode="adaptive"),
    dict(samples=16, sampling_mode="adaptive", block_size=4, progressive=True),
    dict(samples=1, block_size=8, progressive=True),
    dict(samples=4, block_size=4, progressive=True, sampling_mode="jittered"),
])
def test_any_tile_size_gives_the_same_bytes(compiled, settings):
    images = [tracer.render(compiled, WIDTH, HEIGHT, tile=size, **settings).image for size in (8, 16, 64)]
    assert images[0].any()
    for image in images[1:]:
        assert np.array_equal(image, images[0])


def test_tiles_of_a_pass_in_any_order_and_whole_tiles_at_once_give_the_same_film(compiled):
    from tracer import adaptive

    plan = tiles.TilePlan(WIDTH, HEIGHT, block_size=4, progressive=True, tile=16, samples=8,
                          sampling_mode="adaptive")
    shade = _shade(compiled, plan)
    expected = tracer.render(compiled, WIDTH, HEIGHT, block_size=4, progressive=True, tile=16, samples=8,
                             sampling_mode="adaptive").image[::-1]
    # Pass by pass, each pass's tiles in reverse order.
    film = np.zeros((HEIGHT, WIDTH, 3), np.float32)
    run = tiles.TileRun(plan, film, lambda checkpoint: shade)
    for p in range(plan.pass_count):
        for item in reversed(plan.pass_items(p)):
            run.trace(item)
    assert np.array_equal(film, expected)
    # Tile by tile, every block pass of a tile and its pilot at once into a window of its own (as a cluster
    # worker does), then the refinement judged on the assembled film and traced tile by tile.
    film = np.zeros((HEIGHT, WIDTH, 3), np.float32)
    pilot = {}
    for rect in reversed(plan.rects):
        r0, c0, r1, c1 = rect
        film[r0:r1, c0:c1] = tiles.trace_rect(plan, rect, shade)
        pilot[rect] = adaptive.trace_pilot(plan, rect, shade)
    counts = adaptive.refinement(plan, film, pilot.values())
    assert counts.any() and not counts.all() and np.array_equal(counts, run.refinement)
    for rect in reversed(plan.rects):
        r0, c0, r1, c1 = rect
        rows, cols, values = adaptive.trace_refinement(plan, rect, shade, counts[r0:r1, c0:c1], pilot[rect])
        film[rows, cols] = values
    assert np.array_equal(film, expected)


def test_plan_cuts_tiles_on_every_stride():
    plan = tiles.TilePlan(100, 50, block_size=6, progressive=True, tile=10)
    assert plan.passes == [4, 2, 1] and plan.tile == 8 and plan.pass_count == 3
    covered = np.zeros((50, 100), int)
    for r0, c0, r1, c1 in plan.rects:
        assert r0 % 4 == 0 and c0 % 4 == 0
        covered[r0:r1, c0:c1] += 1
    assert np.all(covered == 1)
    assert len(plan.items) == 3 * len(plan.rects)
    assert [item.pass_index for item in plan.items] == sorted(item.pass_index for item in plan.items)
    adaptive = tiles.TilePlan(100, 50, samples=4, sampling_mode="adaptive")
    assert adaptive.pass_count == 3 and adaptive.per_pixel == 1 and adaptive.is_refinement(adaptive.items[-1])
    rects = len(adaptive.rects)
    assert [item.pass_index for item in adaptive.items] == [0] * rects + [1] * rects + [2] * rects
    assert adaptive.is_pilot(adaptive.items[rects]) and not adaptive.is_refinement(adaptive.items[rects])


def test_the_addon_traces_the_same_pixels_as_the_command_line(compiled):
    """addon/pure/blocks.py schedules with tracer.tiles: jittered samples give the command line's bytes."""
    from addon.pure import blocks
    frame = CameraFrame.from_camera(compiled.scene.camera, WIDTH / HEIGHT)
    renderer = blocks.BlockRenderer(compiled, tiles.camera_rays_for(frame, WIDTH, HEIGHT), WIDTH, HEIGHT,
                                    block_size=4, progressive=True, tile=16, samples=4, seed=7, chunk=100)
    renderer.run()
    expected = tracer.render(compiled, WIDTH, HEIGHT, block_size=4, progressive=True, samples=4, seed=7).image
    assert np.array_equal(renderer.color, expected[::-1])


@pytest.mark.parametrize("sampling_mode", ["jittered", "adaptive"])
def test_the_addon_on_threads_traces_the_same_pixels(compiled, sampling_mode):
    """With the NumPy path the add-on traces the work items of a pass three at a time (TileRun.run_on_threads),
    the refinement pass after every block pass: the command line's bytes, and the items reported pass by pass
    on the calling thread."""
    from addon.pure import blocks

    frame = CameraFrame.from_camera(compiled.scene.camera, 24 / 18)
    options = dict(block_size=4, progressive=True, tile=8, samples=4, seed=7, backend="numpy")
    renderer = blocks.BlockRenderer(compiled, tiles.camera_rays_for(frame, 24, 18), 24, 18, threads=3,
                                    sampling=sampling_mode, **options)
    assert renderer.item_threads == 3
    reported = []
    renderer.run(on_item=reported.append)
    expected = tracer.render(compiled, 24, 18, sampling_mode=sampling_mode, **options).image
    assert np.array_equal(renderer.color, expected[::-1])
    assert sorted(map(renderer.items.index, reported)) == list(range(len(renderer.items)))  # each once
    assert [item.pass_index for item in reported] == sorted(item.pass_index for item in reported)
    assert renderer.finished and renderer.pass_count == 3 + 2 * (sampling_mode == "adaptive")
    with pytest.raises(blocks.Cancelled):
        blocks.BlockRenderer(compiled, tiles.camera_rays_for(frame, 24, 18), 24, 18, threads=3,
                             **options).run(cancel=lambda: True)


def test_a_restarted_addon_render_judges_adaptive_sampling_again():
    """The viewport restarts its render on a scene edited in place (BlockRenderer.restart): the pilot and the
    refinement are traced and judged again, so the image is the edited scene's."""
    from dataclasses import replace

    from addon.pure import blocks
    from tracer.edit import EditableScene

    scene = EditableScene(tracer.load(SCENES / "glass.sdl"))
    frame = CameraFrame.from_camera(scene.compiled.scene.camera, WIDTH / HEIGHT)
    options = dict(samples=8, tile=16, seed=5)
    renderer = blocks.BlockRenderer(scene.compiled, tiles.camera_rays_for(frame, WIDTH, HEIGHT), WIDTH, HEIGHT,
                                    sampling="adaptive", **options)
    renderer.run()
    before = renderer.color.copy()
    scene.set_settings(replace(scene.scene.settings, background=(0.6, 0.2, 0.1)))
    renderer.restart()
    renderer.run()
    expected = tracer.render(scene.compiled, WIDTH, HEIGHT, sampling_mode="adaptive", **options).image
    assert not np.array_equal(before, expected[::-1]) and np.array_equal(renderer.color, expected[::-1])


def test_a_tile_run_keeps_its_refinement(compiled):
    """TileRun judges the refinement once, on the film the block passes left and the pilot: tiles traced one
    at a time (the viewport's slices), after earlier refinement tiles changed the film, give the whole
    render's bytes."""
    from tracer import adaptive

    plan = tiles.TilePlan(WIDTH, HEIGHT, block_size=2, progressive=True, tile=16, samples=8,
                          sampling_mode="adaptive")
    film = np.zeros((HEIGHT, WIDTH, 3), dtype=np.float32)
    shade = _shade(compiled, plan)
    run = tiles.TileRun(plan, film, lambda checkpoint: shade)
    for item in plan.items:
        if plan.is_refinement(item) and run.refinement is None:
            after_the_block_passes = adaptive.refinement(plan, film.copy(), run.pilot.values())
        run.trace(item)
    assert after_the_block_passes.any() and np.array_equal(run.refinement, after_the_block_passes)
    expected = tracer.render(compiled, WIDTH, HEIGHT, block_size=2, progressive=True, tile=16, samples=8,
                             sampling_mode="adaptive").image
    assert np.array_equal(film, expected[::-1])


@pytest.mark.parametrize("rows_a_band", [1, 2, 5])
def test_the_refinement_judged_in_bands_is_the_whole_film_s(monkeypatch, rows_a_band):
    """The refinement is judged a band of rows at a time (no full-size float temporaries): bands of any
    height, not dividing the image's, give each pixel the e0 of the whole film and the same rays."""
    from tracer import adaptive, imageio, target

    rng = np.random.default_rng(rows_a_band)
    film = rng.uniform(0, 1, size=(HEIGHT, WIDTH, 4)).astype(np.float32)  # (a fourth channel is not judged)
    film[..., :3] = np.where(rng.uniform(size=(HEIGHT, WIDTH, 1)) < 0.9, 0.5, film[..., :3])
    plan = tiles.TilePlan(WIDTH, HEIGHT, samples=64, sampling_mode="adaptive")
    pixels = np.flatnonzero(rng.uniform(size=HEIGHT * WIDTH) < 1 / 16)
    pilot = [adaptive.PilotTile(pixels, rng.uniform(0, 1, size=(2, pixels.size, 4)))]
    whole = adaptive.refinement(plan, film, pilot)
    monkeypatch.setattr(imageio, "BAND_VALUES", rows_a_band * WIDTH * 4)
    e0 = np.concatenate([band for _, _, band in adaptive._centre_errors(film)])
    assert np.array_equal(e0, target.centre_error(np.clip(film[..., :3], 0, 1)))
    banded = adaptive.refinement(plan, film, pilot)
    assert np.array_equal(banded, whole)
    assert len(np.unique(whole)) >= 2 and whole.min() >= adaptive.every_pixel(plan) == 4
    # The same film through a view of an image kept top row first (as tracer.render keeps it); the pilot's
    # tiles in any order.
    seen_flipped = film[::-1].copy()[::-1]
    halves = [adaptive.PilotTile(pixels[k::2], pilot[0].means[:, k::2]) for k in (1, 0)]
    assert np.array_equal(adaptive.refinement(plan, seen_flipped, halves), whole)
    with pytest.raises(ValueError, match="float film"):
        adaptive.refinement(plan, film.astype(np.uint8), pilot)


def test_an_eight_bit_film_gets_the_bytes_of_the_float_film(compiled):
    """Tiles traced into an 8-bit film pass by pass (a later pass copying earlier samples as bytes) give the
    float film's bytes."""
    from tracer.imageio import to_8bit

    plan = tiles.TilePlan(WIDTH, HEIGHT, block_size=8, progressive=True, tile=16, samples=4)
    shade = _shade(compiled, plan)
    floats = np.zeros((HEIGHT, WIDTH, 3), np.float32)
    eight = np.zeros((HEIGHT, WIDTH, 3), np.uint8)
    for item in plan.items:
        tiles.trace_tile(plan, item, floats, shade)
        tiles.trace_tile(plan, item, eight, shade)
    assert np.array_equal(eight, to_8bit(floats))
