"""Sampling to an error target (``--target-error E``): more rays only where a pixel is still uncertain.

Every pixel starts with FIRST_BATCH jittered rays.  After each round, a pixel's error is estimated as the
standard error of its mean colour, sqrt(s^2 / n) with s^2 the unbiased variance of its n samples (the
largest over the three channels).  Pixels whose estimate is above E, and their neighbours of the same round
(an edge that one pixel's rays all missed is seen by the next pixel's), get as many rays again (a new seed
per round, so each round's strata are placed independently), until that stops or the pixel has
MAX_SAMPLES.  The samples of a round are stratified, and the sample variance of stratified samples
overstates the variance of their mean, so the estimate errs on the safe side: what is measured against a
converged reference comes out below it (docs/accuracy.md shows both).

E is in linear colour, the unit of the image before it is written as 8 bits (1/255 is one 8-bit step).
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from . import sampling
from .errors import RenderCancelled, TracerError

FIRST_BATCH = 16  # enough samples for a variance, one 4 x 4 grid of strata
MAX_SAMPLES = sampling.MAX_SAMPLES
MAX_RAYS_PER_CALL = 1 << 18  # bounds the memory of one batch of rays (about 240 bytes a ray, C core included)


def check(target: float) -> None:
    if not (math.isfinite(target) and target > 0.0):
        raise TracerError(f"the target error must be a number above 0, not {target}")


@dataclass
class ErrorEstimate:
    """What sampling to a target reached (per-pixel estimates in linear colour)."""

    target: float
    rms: float  # root mean square of the per-pixel estimates: the expected RMSE of the image
    worst: float  # the largest per-pixel estimate
    samples_mean: float
    pixels_at_limit: int  # pixels that stopped at MAX_SAMPLES above the target
    per_pixel: np.ndarray  # (height, width) estimate, row 0 at the top
    samples: np.ndarray  # (height, width) rays traced per pixel, row 0 at the top

    def as_dict(self) -> dict:
        return {"target": self.target, "estimated_rmse": round(self.rms, 8), "worst_pixel": round(self.worst, 8),
                "samples_mean": round(self.samples_mean, 3), "pixels_at_limit": int(self.pixels_at_limit)}


def standard_error(total: np.ndarray, squares: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Per pixel: the largest over the channels of sqrt(unbiased sample variance / n)."""
    n = count[:, None].astype(float)
    mean = total / n
    variance = np.maximum(squares / n - mean * mean, 0.0) * n / np.maximum(n - 1.0, 1.0)
    return np.sqrt(variance / n).max(axis=1)


def _still_uncertain(traced: np.ndarray, estimate: np.ndarray, target: float, width: int, height: int) -> np.ndarray:
    """The pixels of this round that go on: those above the target and their 4-neighbours of this round.
    A pixel whose first rays all missed a thin feature has a variance of 0 and would stop, but an edge runs
    on into the next pixel, whose rays see it."""
    from scipy.ndimage import binary_dilation

    above = np.zeros(width * height, dtype=bool)
    above[traced] = estimate[traced] > target
    near = binary_dilation(above.reshape(height, width)).ravel()
    return traced[near[traced]]


def sample_to_error(camera_rays: Callable[[np.ndarray, np.ndarray], np.ndarray], rays_for, width: int,
                    height: int, target: float, seed: int = 0,
                    cancel: Optional[Callable[[], bool]] = None) -> tuple[np.ndarray, ErrorEstimate]:
    """The film (rows from the bottom, float32) and its estimate.  ``camera_rays(origins, directions)``
    shades rays; ``rays_for(rows, cols, dy, dx)`` makes the rays through film pixels (tracer.tiles)."""
    check(target)
    pixels = width * height
    # Per pixel only what the rounds need (68 bytes): the float64 sums and squares, the count, the estimate
    # and the active list.  Rows and columns, means and variances are made a chunk of pixels at a time.
    total = np.zeros((pixels, 3))
    squares = np.zeros((pixels, 3))
    count = np.zeros(pixels, dtype=np.int32)
    estimate = np.full(pixels, np.inf)
    active = np.arange(pixels)
    batch, round_index = FIRST_BATCH, 0
    while active.size:
        step = max(1, MAX_RAYS_PER_CALL // batch)
        for start in range(0, active.size, step):
            if cancel is not None and cancel():
                raise RenderCancelled("render cancelled")
            chunk = active[start:start + step]
            rows, cols = np.divmod(chunk, width)
            dy, dx = sampling.offsets(batch, True, rows, cols, seed + round_index)
            origins, directions = rays_for(np.repeat(rows, batch), np.repeat(cols, batch), dy.ravel(), dx.ravel())
            colors = np.asarray(camera_rays(origins, directions), dtype=np.float64).reshape(-1, batch, 3)
            total[chunk] += colors.sum(axis=1)
            squares[chunk] += (colors * colors).sum(axis=1)
            count[chunk] += batch
        for start in range(0, active.size, MAX_RAYS_PER_CALL):
            part = active[start:start + MAX_RAYS_PER_CALL]
            estimate[part] = standard_error(total[part], squares[part], count[part])
        active = _still_uncertain(active, estimate, target, width, height)
        active = active[count[active] < MAX_SAMPLES]
        if active.size:  # every active pixel has the same count: double it, up to the limit
            done = int(count[active[0]])
            batch = min(done, MAX_SAMPLES - done)
            round_index += 1
    film = np.empty((pixels, 3), dtype=np.float32)
    for start in range(0, pixels, MAX_RAYS_PER_CALL):
        part = slice(start, start + MAX_RAYS_PER_CALL)
        film[part] = total[part] / count[part, None]
    film = film.reshape(height, width, 3)
    shown = lambda a: np.ascontiguousarray(a.reshape(height, width)[::-1])  # noqa: E731 (row 0 at the top)
    result = ErrorEstimate(target=float(target), rms=float(np.sqrt(np.mean(estimate ** 2))),
                           worst=float(estimate.max()), samples_mean=float(count.mean()),
                           pixels_at_limit=int(np.count_nonzero(estimate > target)),
                           per_pixel=shown(estimate), samples=shown(count))
    return film, result
