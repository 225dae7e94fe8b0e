"""``--sampling adaptive`` with N samples: about N camera rays per pixel on average, spent where the error
model of ``--target-error`` (:mod:`tracer.target`) says they lower the image's error most.

The block passes of the tile plan (:mod:`tracer.tiles`) trace one ray per pixel (its centre, at block size
1).  Two more passes follow:

1. **The pilot.**  The pixels :func:`tracer.target.pilot_pixels` picks (1 in 16, at random whatever their
   colour) get PILOT_HALF jittered rays in each of two independent halves.  Which pixels and how many rays
   depend on the pixel alone, so a tile's pilot needs only that tile (a cluster traces it in the task that
   traces the tile's block passes).
2. **The refinement.**  Judged once, on the whole film the block passes left (its second differences cross
   tile borders): each pixel's e0 (:func:`tracer.target.centre_error`), an ErrorModel fitted to the pilot
   (:func:`tracer.target.fitted_model`: how a pixel's error falls with jittered rays, and a floor under e0
   for what centre rays do not see), and a plan (:func:`tracer.target.plan_rays`) that spends what is left
   of N x pixels camera rays for the lowest predicted error: rays per pixel in proportion to
   (kappa e0 + floor)^(1 / (1 + ALPHA)), and none where a pixel's centre ray is predicted to do better.

**The budget**: N x pixels camera rays in all, the centre rays (one per pixel) and the pilot's included;
the plan spends what is left, up to rounding (it never spends more, and less where no pixel gains from
more).  So adaptive N costs what uniform N costs, or less, and every pixel's rays grow with N.

**Every pixel** gets at least the ladder step at or below N / 16, from 4 rays up (fewer jittered rays do
worse than a centre ray on smooth shading): what neither the centre rays nor the pilot see, a feature
thinner than a pixel that falls between centres, still converges, at the uniform rate with 1/16 of its
rays.  Without it, lecture's error stops falling near 0.0007 (two such pixels).

A refined pixel's colour is the mean of its jittered rays, its pilot's included; its centre ray is
dropped.  A pilot pixel the plan leaves alone keeps the mean of its pilot rays.  Everything here depends on
the film and on (seed, pixel) alone, so any tile order, tile size or number of machines gives the same
bytes.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Optional

import numpy as np

from . import target
from .imageio import band_rows

#: Jittered rays a refined pixel can have: about 1.5 times apart (so the plan meets its budget closely),
#: each a number whose grid of strata is nearly square (tracer.sampling.grid_shape), up to MAX_SAMPLES.
LADDER = np.array([2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, 512, 768, 1024])
#: Jittered rays in each half of a pilot pixel: the target's (a quarter of a ray per pixel of the film).
#: With 4, the bundled scenes' errors at 96 x 72 were the same or up to 12 % higher (4 seeds, N = 4 to 64):
#: the pilot's own rays cost more than its better fit gains.
PILOT_HALF = target.PILOT_HALF
#: A floor the pilot measures under the centre rays' errors counts whenever it is above 0.  The target asks
#: for two standard errors (tracer.target.FLOOR_SIGNIFICANCE), as a floor set by one stray edge would
#: inflate its estimate; here a floor set too high costs a few rays on flat pixels, one missed leaves a
#: texture's pixels with their centre rays: scenes/textures.sdl at 48 x 36 (a pilot of about 100 pixels)
#: stopped near 0.025 with 128 rays on 2 seeds of 3 where uniform jittered reaches 0.008.  (At 96 x 72 the
#: bundled scenes' errors are the same either way.)
FLOOR_SIGNIFICANCE = 0.0
#: The share of N every pixel gets whatever the plan says (see the module docstring), and the fewest rays
#: it is given as (below, none).
EVERY_PIXEL_SHARE = 1.0 / 16
EVERY_PIXEL_FEWEST = 4


@dataclass
class PilotTile:
    """The pilot's pixels of one tile and their rays."""

    pixels: np.ndarray  # flat indices in the film (row * width + column, rows from the bottom), increasing
    means: np.ndarray  # (2, pixels, channels): each half's mean colour (and coverage, with an alpha channel)


def trace_pilot(plan, rect: tuple[int, int, int, int], shade) -> PilotTile:
    """The pilot of the tile ``rect`` (rows r0..r1-1, columns c0..c1-1): its pilot pixels' two halves, each
    PILOT_HALF jittered rays with its own seed (``shade(rows, cols, per_pixel, seed)``, tracer.tiles)."""
    r0, c0, r1, c1 = rect
    rows, cols = np.divmod(np.arange((r1 - r0) * (c1 - c0)), c1 - c0)
    rows, cols = rows + r0, cols + c0
    chosen = target.pilot_pixels(rows, cols, plan.seed)
    rows, cols = rows[chosen], cols[chosen]
    means = np.stack([shade(rows, cols, PILOT_HALF, target.half_seed(plan.seed, 0, half)) for half in (0, 1)])
    return PilotTile(rows * plan.width + cols, means)


def rays_left(plan, pilot_rays: int) -> float:
    """The refinement's budget: N x pixels, less the centre rays and the pilot's."""
    pixels = plan.width * plan.height
    return float(plan.samples * pixels - pixels - pilot_rays)


def every_pixel(plan) -> int:
    """The fewest jittered rays the plan gives each pixel (see the module docstring)."""
    steps = LADDER[LADDER <= plan.samples * EVERY_PIXEL_SHARE]
    return int(steps[-1]) if steps.size and steps[-1] >= EVERY_PIXEL_FEWEST else 0


def refinement(plan, film: np.ndarray, pilot: Iterable[PilotTile]) -> np.ndarray:
    """Rays per pixel of the refinement pass, (height, width) uint16 indexed like ``film`` (the whole float
    film after the block passes, rows from the bottom; its first three channels are the colour), from the
    pilot's tiles.  Judged a band of rows at a time: besides the result, two bytes a pixel, only the bands'
    temporaries are made."""
    if film.dtype == np.uint8:
        raise ValueError("the refinement is judged on a float film, not an 8-bit one")
    pixels, means = _pilot_arrays(pilot)
    width = film.shape[1]
    pilot_rows, pilot_cols = np.divmod(pixels, width)
    # Pass 1: the range of e0 (for the bins) and e0 at the pilot's pixels.
    smallest, largest = np.inf, 0.0
    pilot_e0 = np.zeros(pixels.size, dtype=np.float32)
    for top, bottom, e0 in _centre_errors(film):
        positive = e0[e0 > 0.0]
        if positive.size:
            smallest, largest = min(smallest, float(positive.min())), max(largest, float(positive.max()))
        inside = (pilot_rows >= top) & (pilot_rows < bottom)
        pilot_e0[inside] = e0[pilot_rows[inside] - top, pilot_cols[inside]]
    model = target.fitted_model(film[pilot_rows, pilot_cols, :3], pilot_e0, means[..., :3],
                                np.full(pixels.size, 2.0 * PILOT_HALF), FLOOR_SIGNIFICANCE)
    # Pass 2: each pixel's bin, and the bins' sums; then the plan's rays per bin, put in each pixel's place.
    bins = target.E0Bins(smallest, largest)
    counts = np.empty(film.shape[:2], dtype=np.uint16)
    for top, bottom, e0 in _centre_errors(film):
        index = bins.index(e0)
        bins.add(index, e0)
        counts[top:bottom] = index
    rays = target.plan_rays(bins, model, rays_left(plan, 2 * PILOT_HALF * pixels.size), LADDER, every_pixel(plan))
    rays = rays.astype(np.uint16)
    step = band_rows(counts)
    for top in range(0, counts.shape[0], step):
        counts[top:top + step] = rays[counts[top:top + step]]
    return counts


def _pilot_arrays(pilot: Iterable[PilotTile]) -> tuple[np.ndarray, np.ndarray]:
    """All the pilot's pixels, in increasing order (whatever order the tiles came in), and their means."""
    tiles = list(pilot)
    if not tiles:
        return np.zeros(0, dtype=np.int64), np.zeros((2, 0, 3))
    pixels = np.concatenate([tile.pixels for tile in tiles])
    means = np.concatenate([tile.means for tile in tiles], axis=1)
    order = np.argsort(pixels, kind="stable")
    return pixels[order], means[:, order]


def _centre_errors(film: np.ndarray):
    """(top, bottom, e0 of rows top..bottom-1) for bands of the film: tracer.target.centre_error of its
    colour clipped to [0, 1], each band judged with the two rows either side of it, so that it is the whole
    film's."""
    height = film.shape[0]
    rows = band_rows(film)
    for top in range(0, height, rows):
        bottom = min(top + rows, height)
        above, below = max(top - 2, 0), min(bottom + 2, height)
        band = np.clip(film[above:below, :, :3], 0.0, 1.0)
        yield top, bottom, target.centre_error(band)[top - above: bottom - above]


def trace_refinement(plan, rect: tuple[int, int, int, int], shade, counts: np.ndarray,
                     pilot: Optional[PilotTile]) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The refinement of the tile ``rect``: ``counts`` is its window of :func:`refinement`, ``pilot`` its
    pilot.  Returns the pixels it gives a colour (rows, columns in the film) and their colours (the mean
    of each pixel's jittered rays, its pilot's included), for the caller to write into its film."""
    r0, c0, r1, c1 = rect
    width = plan.width
    traced = np.flatnonzero(counts)
    pixels = (traced // (c1 - c0) + r0) * width + traced % (c1 - c0) + c0  # increasing, as ``traced``
    rays = counts.ravel()[traced].astype(np.int64)
    colours = [shade(pixels[rays == n] // width, pixels[rays == n] % width, int(n)) for n in np.unique(rays)]
    values = np.empty((pixels.size, colours[0].shape[1] if colours else 3))
    for n, traced_colours in zip(np.unique(rays), colours):
        values[rays == n] = traced_colours
    if pilot is not None and pilot.pixels.size:
        # a pilot pixel's colour is the mean of all its rays (the pilot's alone where the plan gave none)
        pilot_rays = 2.0 * PILOT_HALF
        mean = 0.5 * (pilot.means[0] + pilot.means[1])
        place = np.minimum(np.searchsorted(pixels, pilot.pixels), max(pixels.size - 1, 0))
        refined = pixels[place] == pilot.pixels if pixels.size else np.zeros(pilot.pixels.size, dtype=bool)
        own = place[refined]
        n = rays[own][:, None].astype(float)
        values[own] = (pilot_rays * mean[refined] + n * values[own]) / (pilot_rays + n)
        pixels = np.concatenate([pixels, pilot.pixels[~refined]])
        values = np.concatenate([values, mean[~refined]])
    return pixels // width, pixels % width, values
