"""Sampling to an error target (``--target-error E``): rays only where they lower the image's error most.

E is in linear colour clipped to [0, 1], the unit of the image before it is written as 8 bits (1/255 is one
8-bit step).  There are two kinds of target:

* **image** (the default): the image's RMSE against the converged image — the number ``bench accuracy``
  measures against its reference — is estimated to be at most E;
* **pixel** (``per_pixel=True``, ``--per-pixel``): every pixel's standard error is at most E.  Far more
  rays: flat pixels, which one ray gets right, are sampled too (see :func:`sample_each_pixel`).

The image target works in rounds:

1. **One ray through every pixel's centre.**  Where the image is smooth, the centre is the pixel's mean to
   second order.  Where an edge crosses the pixel, the centre ray is wrong by up to the step.  A step of
   height h that crosses a pixel at a uniformly random place gives the centre ray a squared error of h²/12
   on average, and the second difference across the step (x[i-1] - 2 x[i] + x[i+1]) is h.  So
   :func:`centre_error` takes, per pixel, the larger over the two axes of that second difference squared,
   over 12 (mean over the channels), as the centre ray's squared error ``e0``.  For smooth shading it is a
   generous bound: the midpoint rule's error there is the second difference over 24.
2. **A plan.**  A pixel refined to n jittered rays is expected to keep a squared error of kappa e0 / n^ALPHA.
   Spending the fewest rays for a predicted sum of squared errors of at most P E² (P pixels) gives n
   proportional to (kappa e0)^(1 / (1 + ALPHA)) (a Lagrange multiplier, found by bisection); counts are
   rounded down to a ladder, and a pixel whose n comes out below 4 keeps its centre ray alone.
3. **Two halves.**  A refined pixel's rays come in two halves, jittered independently; the squared difference
   of the two halves' clipped means, over 4, is an unbiased estimate of the squared error of their mean.  The
   centre ray of a refined pixel is not used in its colour.  Which pixels get how many rays depends only on
   the centre rays and on sums over the whole image, never on a pixel's own halves, so the estimate carries
   no selection bias (stopping a pixel because its own estimate happened to come out low would).
4. **Rounds.**  The image estimate is the halves' estimates of the refined pixels plus ``e0`` of the others.
   After each round kappa is fitted to the halves (the rays so far against what the plan expected), and the
   plan is redone for the part of the target the estimate still misses.  The first round aims at twice the
   target's squared error, as kappa is not known yet.  It ends when the estimate is at most E, or when no
   pixel can take more rays.

ALPHA = 1.25 is how fast the halves' estimate falls with rays on the bundled scenes.  Stratified rays beat
1/n (the bench's jittered slopes, -0.72 to -0.80 in RMSE, are 1.44 to 1.6 in squared error), but two
independent halves of n/2 strata are a little worse than one set of n.  ALPHA only sets the shape of the
plan; kappa is measured.  docs/accuracy.md shows the rays each target costs against uniform and adaptive
sampling.

What no ray through a pixel's centre shows — a feature thinner than a pixel that falls between centres —
the estimate does not see either.
"""
from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Callable, Optional

import numpy as np

from . import sampling
from .errors import RenderCancelled, TracerError

MAX_SAMPLES = sampling.MAX_SAMPLES
MAX_RAYS_PER_CALL = 1 << 18  # bounds the memory of one batch of rays (about 240 bytes a ray, C core included)

#: Image target: rays per half a refined pixel can have (about 1.5x apart, so a plan is met closely; the top
#: keeps centre + two halves within MAX_SAMPLES).
HALF_LADDER = np.array([2, 3, 4, 6, 8, 12, 16, 24, 32, 48, 64, 96, 128, 192, 256, 384, (MAX_SAMPLES - 1) // 2])
#: Image target: a refined pixel's squared error is expected to fall as 1 / rays^ALPHA (see the docstring).
ALPHA = 1.25
#: Image target: kappa before the first round has measured it (the h²/12 model's variance for rays spread
#: evenly over the pixel is twice the centre ray's error; the halves cost some of it back).
KAPPA_START = 1.0
#: Image target: plans aim at this fraction of the target's squared error, so that the estimate's scatter
#: and the plan's rounding seldom leave a round short of the target.
PLAN_AIM = 0.9
#: Image target: every this-many-th pixel that may need rays is in the pilot that measures kappa.
PILOT_EVERY = 10
MAX_ROUNDS = 16

#: Pixel target: every pixel's first batch of rays (enough for a variance, one 4 x 4 grid of strata).
FIRST_BATCH = 16


def check(target: float) -> None:
    if not (math.isfinite(target) and target > 0.0):
        raise TracerError(f"the target error must be a number above 0, not {target}")


@dataclass
class ErrorEstimate:
    """What sampling to a target reached (estimates in linear colour)."""

    target: float
    rms: float  # the image's estimated RMSE (root mean square of the per-pixel estimates)
    worst: float  # the largest per-pixel estimate
    samples_mean: float
    pixels_at_limit: int  # pixels that stopped at the ray limit while the target was not met
    per_pixel: np.ndarray  # (height, width) estimated error, row 0 at the top
    samples: np.ndarray  # (height, width) rays traced per pixel, row 0 at the top
    kind: str = "image"  # "image": the image's RMSE is the target; "pixel": every pixel's standard error

    def as_dict(self) -> dict:
        return {"target": self.target, "kind": self.kind, "estimated_rmse": round(self.rms, 8),
                "worst_pixel": round(self.worst, 8), "samples_mean": round(self.samples_mean, 3),
                "pixels_at_limit": int(self.pixels_at_limit)}


#: ``camera_rays(origins, directions) -> (N, 3)`` colours; ``rays_for(rows, cols, dy, dx)`` the rays through
#: film pixels (tracer.tiles.RaysFor).
CameraRays = Callable[[np.ndarray, np.ndarray], np.ndarray]


def sample_to_error(camera_rays: CameraRays, rays_for, width: int, height: int, target: float, seed: int = 0,
                    cancel: Optional[Callable[[], bool]] = None,
                    per_pixel: bool = False) -> tuple[np.ndarray, ErrorEstimate]:
    """The film (rows from the bottom, float32) and its estimate, for an image target (the default) or a
    per-pixel one."""
    check(target)
    sample = sample_each_pixel if per_pixel else sample_image
    return sample(camera_rays, rays_for, width, height, target, seed, cancel)


# ---------------------------------------------------------------------------------------------------------
# The image target

def centre_error(centre: np.ndarray) -> np.ndarray:
    """Per pixel of a (H, W, 3) image of centre rays (clipped to [0, 1]): the squared error those rays are
    taken to have, the larger over the axes of (second difference)² / 12, mean over channels (see the module
    docstring).  A pixel on the image's border takes its inner neighbour's second difference (a ramp stays a
    ramp there); along an axis shorter than 3 pixels there is none."""
    return (np.maximum(_second_difference(centre, 0), _second_difference(centre, 1)) / 12.0).mean(axis=-1)


def _second_difference(image: np.ndarray, axis: int) -> np.ndarray:
    """(x[i-1] - 2 x[i] + x[i+1])² along ``axis``, each border pixel given its neighbour's value."""
    if image.shape[axis] < 3:
        return np.zeros_like(image)
    inner = np.diff(image, n=2, axis=axis) ** 2
    first, last = np.take(inner, [0], axis=axis), np.take(inner, [-1], axis=axis)
    return np.concatenate([first, inner, last], axis=axis)


def plan_halves(centre_errors: np.ndarray, kappa: float, squared_budget: float) -> np.ndarray:
    """Rays per half for each pixel (0: its centre ray alone) such that the predicted sum of squared errors
    is at most ``squared_budget`` for the fewest rays, as far as HALF_LADDER's steps allow."""
    weight = np.power(kappa * centre_errors, 1.0 / (1.0 + ALPHA))

    def halves_at(scale: float) -> np.ndarray:
        rays = scale * weight
        step = np.searchsorted(HALF_LADDER, rays / 2.0, side="right") - 1
        return np.where(rays >= 2 * HALF_LADDER[0], HALF_LADDER[np.maximum(step, 0)], 0)

    def predicted(halves: np.ndarray) -> float:
        refined = halves > 0
        return float(np.sum(np.where(refined, kappa * centre_errors / np.maximum(2.0 * halves, 1.0) ** ALPHA,
                                     centre_errors)))

    if predicted(np.zeros_like(centre_errors, dtype=np.int64)) <= squared_budget:
        return np.zeros(centre_errors.shape, dtype=np.int64)
    low, high = -30.0, 30.0  # log10 of the scale
    for _ in range(48):
        middle = 0.5 * (low + high)
        if predicted(halves_at(10.0 ** middle)) > squared_budget:
            low = middle
        else:
            high = middle
    return halves_at(10.0 ** high).astype(np.int64)


class _Halves:
    """The two halves' colour sums of every pixel and how many rays each half has."""

    def __init__(self, pixels: int):
        self.sums = np.zeros((2, pixels, 3))
        self.count = np.zeros(pixels, dtype=np.int64)

    def means(self, pixels: np.ndarray) -> np.ndarray:
        return self.sums[:, pixels] / self.count[pixels][None, :, None]

    def squared_error(self, pixels: np.ndarray) -> np.ndarray:
        """Per pixel: (clipped mean of half 0 - clipped mean of half 1)² / 4, mean over channels."""
        means = np.clip(self.means(pixels), 0.0, 1.0)
        return ((means[0] - means[1]) ** 2).mean(axis=1) / 4.0


def _trace_halves(camera_rays: CameraRays, rays_for, width: int, halves: _Halves, pixels: np.ndarray,
                  more: np.ndarray, seed: int, round_index: int, cancel) -> None:
    """Give each pixel ``more[i]`` new rays in each half: a jittered set per half, independent of the other
    half and of earlier rounds (its own seed)."""
    for extra in np.unique(more):
        group = pixels[more == extra]
        extra = int(extra)
        step = max(1, MAX_RAYS_PER_CALL // extra)
        for half in (0, 1):
            half_seed = (int(seed) << 16) + 2 * round_index + half
            for start in range(0, group.size, step):
                if cancel is not None and cancel():
                    raise RenderCancelled("render cancelled")
                chunk = group[start:start + step]
                rows, cols = np.divmod(chunk, width)
                dy, dx = sampling.offsets(extra, True, rows, cols, half_seed)
                origins, directions = rays_for(np.repeat(rows, extra), np.repeat(cols, extra), dy.ravel(),
                                               dx.ravel())
                colors = np.asarray(camera_rays(origins, directions), dtype=np.float64)
                halves.sums[half, chunk] += colors.reshape(-1, extra, 3).sum(axis=1)
    halves.count[pixels] += more


def _trace_centres(camera_rays: CameraRays, rays_for, width: int, height: int, cancel) -> np.ndarray:
    pixels = width * height
    centre = np.empty((pixels, 3), dtype=np.float32)
    for start in range(0, pixels, MAX_RAYS_PER_CALL):
        if cancel is not None and cancel():
            raise RenderCancelled("render cancelled")
        rows, cols = np.divmod(np.arange(start, min(pixels, start + MAX_RAYS_PER_CALL)), width)
        centre[start:start + rows.size] = camera_rays(*rays_for(rows, cols))
    return centre


def sample_image(camera_rays: CameraRays, rays_for, width: int, height: int, target: float, seed: int = 0,
                 cancel: Optional[Callable[[], bool]] = None) -> tuple[np.ndarray, ErrorEstimate]:
    """Sample until the image's estimated RMSE is at most ``target`` (the module docstring says how)."""
    check(target)
    pixels = width * height
    film = _trace_centres(camera_rays, rays_for, width, height, cancel)
    errors = centre_error(np.clip(film, 0.0, 1.0).reshape(height, width, 3)).ravel()
    candidates = np.flatnonzero(errors > 0.0)  # a pixel like all its neighbours never needs more rays
    halves = _Halves(pixels)
    budget = pixels * target * target
    estimate = _Estimate(errors, halves)
    if estimate.total > budget:
        # The pilot: every PILOT_EVERY-th candidate gets the rays a plan with KAPPA_START gives it, and kappa
        # is fitted to them; then every pixel gets its rays at once (one jittered set per half samples a
        # pixel better than several rounds' sets of the same total).
        pilot = candidates[::PILOT_EVERY]
        planned = plan_halves(errors[candidates], KAPPA_START, PLAN_AIM * budget)[::PILOT_EVERY]
        _trace_halves(camera_rays, rays_for, width, halves, pilot[planned > 0], planned[planned > 0], seed, 0,
                      cancel)
        kappa = estimate.kappa(pilot[planned > 0]) or KAPPA_START
        aim = PLAN_AIM * budget
        for round_index in range(1, MAX_ROUNDS):
            wanted = np.maximum(plan_halves(errors[candidates], kappa, aim), halves.count[candidates])
            more = wanted - halves.count[candidates]
            if more.any():
                _trace_halves(camera_rays, rays_for, width, halves, candidates[more > 0], more[more > 0], seed,
                              round_index, cancel)
                refined = candidates[halves.count[candidates] > 0]
                estimate.update(refined)
                if estimate.total <= budget:
                    break
                kappa = estimate.kappa(refined) or kappa
                aim = min(aim, aim * budget / estimate.total)
            elif np.all(halves.count[candidates] == HALF_LADDER[-1]):
                break  # every pixel that could use rays has all it may have
            else:
                aim *= 0.8  # the plan's rounding left the estimate short: ask for a little more
    refined = candidates[halves.count[candidates] > 0]
    film[refined] = halves.sums[:, refined].sum(axis=0) / (2.0 * halves.count[refined])[:, None]
    rays = 1 + 2 * halves.count
    result = ErrorEstimate(target=float(target), rms=math.sqrt(max(estimate.total, 0.0) / pixels),
                           worst=float(np.sqrt(estimate.per_pixel.max())), samples_mean=float(rays.mean()),
                           pixels_at_limit=int(np.count_nonzero(halves.count == HALF_LADDER[-1]))
                           if estimate.total > budget else 0,
                           per_pixel=_shown(np.sqrt(estimate.per_pixel), width, height),
                           samples=_shown(rays, width, height))
    return film.reshape(height, width, 3), result


class _Estimate:
    """The image's estimated squared errors: the centre rays' (``errors``) where a pixel is not refined,
    its halves' where it is."""

    def __init__(self, errors: np.ndarray, halves: _Halves):
        self.errors, self.halves = errors, halves
        self.per_pixel = errors.copy()
        self.total = float(errors.sum())

    def update(self, refined: np.ndarray) -> None:
        self.per_pixel[refined] = self.halves.squared_error(refined)
        self.total = float(self.per_pixel.sum())

    def kappa(self, refined: np.ndarray) -> Optional[float]:
        """kappa fitted to these refined pixels: their halves' squared errors against e0 / rays^ALPHA."""
        if refined.size == 0:
            return None
        self.update(refined)
        rays = 2.0 * self.halves.count[refined]
        return max(1e-6, float(np.sum(self.per_pixel[refined] * rays ** ALPHA) / np.sum(self.errors[refined])))


def _shown(values: np.ndarray, width: int, height: int) -> np.ndarray:
    """A per-pixel array of the film (rows from the bottom) as an image's rows (row 0 at the top)."""
    return np.ascontiguousarray(values.reshape(height, width)[::-1])


# ---------------------------------------------------------------------------------------------------------
# The per-pixel target

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
    from scipy.ndimage import binary_dilation  # (SciPy comes with scikit-image; only this mode needs it)

    above = np.zeros(width * height, dtype=bool)
    above[traced] = estimate[traced] > target
    near = binary_dilation(above.reshape(height, width)).ravel()
    return traced[near[traced]]


def sample_each_pixel(camera_rays: CameraRays, rays_for, width: int, height: int, target: float, seed: int = 0,
                      cancel: Optional[Callable[[], bool]] = None) -> tuple[np.ndarray, ErrorEstimate]:
    """Every pixel starts with FIRST_BATCH jittered rays.  After each round a pixel's error is estimated as
    the standard error of its mean colour, sqrt(s² / n) with s² the unbiased variance of its n samples (the
    largest over the channels).  Pixels whose estimate is above E, and their neighbours of the same round,
    get as many rays again (a new seed per round), until that stops or the pixel has MAX_SAMPLES.  The
    samples of a round are stratified, and the sample variance of stratified samples overstates the
    variance of their mean, so the estimate errs on the safe side."""
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
    result = ErrorEstimate(target=float(target), rms=float(np.sqrt(np.mean(estimate ** 2))),
                           worst=float(estimate.max()), samples_mean=float(count.mean()),
                           pixels_at_limit=int(np.count_nonzero(estimate > target)),
                           per_pixel=_shown(estimate, width, height), samples=_shown(count, width, height),
                           kind="pixel")
    return film.reshape(height, width, 3), result


# ---------------------------------------------------------------------------------------------------------

def render_to_error(compiled, width: int, height: int, target: float, *, backend: str = "auto",
                    threads: Optional[int] = None, seed: int = 0, savings=None,
                    cancel: Optional[Callable[[], bool]] = None, per_pixel: bool = False):
    """tracer.render.render with ``target_error``: a RenderResult whose ``error_estimate`` is filled in."""
    from .backend import make_tracer
    from .camera import CameraFrame, scene_camera
    from .render import RenderResult
    from .tiles import camera_rays_for

    started = time.perf_counter()
    frame = CameraFrame.from_camera(scene_camera(compiled.scene, compiled, width / height), width / height)
    tracer = make_tracer(compiled, backend, threads, savings)
    film, estimate = sample_to_error(tracer.camera_rays, camera_rays_for(frame, width, height), width, height,
                                     target, seed, cancel, per_pixel)
    return RenderResult(image=np.ascontiguousarray(film[::-1]), rays=tracer.counts,
                        seconds=time.perf_counter() - started, backend=tracer.name, effects=compiled.effects,
                        error_estimate=estimate)
