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
2. **A pilot.**  A random PILOT_FRACTION of all pixels, whatever their e0, gets jittered rays (the plan's
   for it, at least PILOT_HALF per half).  From them an :class:`ErrorModel` is fitted: a pixel refined to n
   jittered rays keeps a squared error of (kappa e0 + floor) / n^ALPHA, and a pixel left with its centre
   ray has e0 plus a floor for what centre rays do not see (a texture finer than a pixel looks smooth to
   them), counted only where the pilot shows it significantly.
3. **A plan.**  Spending the fewest rays for a predicted sum of squared errors of PLAN_AIM x P E² (P
   pixels) gives n proportional to (kappa e0 + floor)^(1 / (1 + ALPHA)) (a Lagrange multiplier, found by
   bisection over groups of pixels of nearly equal e0); counts are rounded down to a ladder, and a pixel
   whose rays are not predicted to beat its centre ray keeps it alone.
4. **Two halves.**  A refined pixel's rays come in two halves, jittered independently; the squared difference
   of the two halves' clipped means, over 4, is an unbiased estimate of the squared error of their mean (and
   (centre - their mean)² less it one of the centre ray's, which the pilot uses).  The centre ray of a
   refined pixel is not used in its colour.  Which pixels get how many rays depends only on the centre rays
   and on sums over the whole image, never on a pixel's own halves, so the estimate carries no selection
   bias (stopping a pixel because its own estimate happened to come out low would).
5. **Rounds.**  The image estimate is the halves' estimates of the refined pixels plus the model's for the
   others.  While it is above E, kappa and floor are refitted to every refined pixel and the plan is redone
   for the part of the target still missing.  It ends when the estimate is at most E, or when no pixel can
   take more rays.

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
#: Image target: the pilot's share of the pixels (chosen at random, whatever their centre rays show), and
#: the fewest rays per half it gives each.
PILOT_FRACTION = 1.0 / 16
PILOT_HALF = 2
PILOT_SALT = 0x5EED_C0DE
#: Image target: a floor the pilot measures under the centre rays' errors counts from this many standard
#: errors up.
FLOOR_SIGNIFICANCE = 2.0
MAX_ROUNDS = 16
#: Image target: bisection steps of a plan's scale (its logarithm's range, about 10, is then cut to 1e-8),
#: and the groups of nearly equal e0 a plan is made for (about 1 % apart over 10 decades).
PLAN_STEPS = 32
PLAN_BINS = 2048

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


@dataclass
class ErrorModel:
    """What a pixel's squared error is expected to be, from its centre rays' ``e0`` (:func:`centre_error`):
    ``centre_scale * e0 + centre_floor`` with the centre ray alone, ``(kappa * e0 + floor) / rays^ALPHA``
    with that many jittered rays.  The floors are what ``e0`` does not see (a texture finer than a pixel
    looks smooth to centre rays); they, kappa and floor are fitted to rays (:func:`_fitted_model`,
    :meth:`refit`)."""

    kappa: float = KAPPA_START
    floor: float = 0.0
    centre_scale: float = 1.0
    centre_floor: float = 0.0

    def centre(self, e0: np.ndarray) -> np.ndarray:
        return self.centre_scale * e0 + self.centre_floor

    def difficulty(self, e0: np.ndarray) -> np.ndarray:
        return self.kappa * e0 + self.floor

    def refit(self, e0: np.ndarray, squared_errors: np.ndarray, rays: np.ndarray) -> "ErrorModel":
        """kappa and floor fitted to refined pixels' halves (their squared errors at so many rays)."""
        kappa, floor = _fit_line(e0, squared_errors * rays ** ALPHA, (self.kappa, self.floor))
        return ErrorModel(kappa, floor, self.centre_scale, self.centre_floor)


def _fit_line(x: np.ndarray, y: np.ndarray, fallback: tuple[float, float]) -> tuple[float, float]:
    """(slope, floor), both 0 or more, of y = slope x + floor through the sums of the lower and upper halves
    of the points by x (two equations, as noisy points fit no better with more).  With too few points, or
    points at a single x, ``fallback``."""
    if x.size < 2:
        return fallback
    order = np.argsort(x, kind="stable")
    lower, upper = order[:x.size // 2], order[x.size // 2:]
    sx = np.array([x[lower].sum(), x[upper].sum()])
    sy = np.array([y[lower].sum(), y[upper].sum()])
    n = np.array([lower.size, upper.size], dtype=float)
    det = sx[0] * n[1] - sx[1] * n[0]
    if det != 0.0:
        slope = (sy[0] * n[1] - sy[1] * n[0]) / det
        floor = (sx[0] * sy[1] - sx[1] * sy[0]) / det
        if slope >= 0.0 and floor >= 0.0:
            return float(slope), float(floor)
    total_x, total_y = float(sx.sum()), max(float(sy.sum()), 0.0)
    if total_x > 0.0 and (det == 0.0 or (sy[0] * n[1] - sy[1] * n[0]) / det >= 0.0):
        return total_y / total_x, 0.0  # the floor came out below 0: a slope alone
    return 0.0, total_y / x.size  # no slope (or no x): a floor alone


def plan_halves(e0: np.ndarray, model: ErrorModel, squared_budget: float) -> np.ndarray:
    """Rays per half for each pixel (0: its centre ray alone) such that the predicted sum of squared errors
    is at most ``squared_budget`` for the fewest rays, as far as HALF_LADDER's steps allow.  A pixel is
    refined only where its rays are predicted to do better than its centre ray.

    Everything the model predicts of a pixel is a function of its e0, so pixels are planned in PLAN_BINS
    groups of nearly equal e0 (log-spaced; the model is linear in e0, so a group's sums are exact), and every
    pixel of a group gets the group's rays: the bisection then costs nothing next to the rays."""
    halves = np.zeros(e0.shape, dtype=np.int64)
    centre_all = model.centre(e0)
    if float(centre_all.sum()) <= squared_budget:
        return halves
    active = np.flatnonzero(model.difficulty(e0) > 0.0)  # (flat pixels, most of most images, never take rays)
    if active.size == 0:
        return halves
    unchanged = float(centre_all.sum() - centre_all[active].sum())
    group, count, e0_sum = _groups_by_e0(e0[active])
    e0_mean = e0_sum / count
    difficulty = model.kappa * e0_sum + model.floor * count  # each group's sums
    centre = model.centre_scale * e0_sum + model.centre_floor * count
    weight = np.power(model.difficulty(e0_mean), 1.0 / (1.0 + ALPHA))
    # Refine a group where (2h)^ALPHA exceeds this: where its rays beat its centre rays (never where a centre
    # ray is predicted exact).
    centre_mean = model.centre(e0_mean)
    better_at = np.divide(model.difficulty(e0_mean), centre_mean, out=np.full(centre_mean.shape, np.inf),
                          where=centre_mean > 0.0)

    def halves_at(scale: float) -> np.ndarray:
        rays = scale * weight
        step = HALF_LADDER[np.maximum(np.searchsorted(HALF_LADDER, rays / 2.0, side="right") - 1, 0)]
        return np.where((rays >= 2 * HALF_LADDER[0]) & ((2.0 * step) ** ALPHA > better_at), step, 0)

    def predicted(h: np.ndarray) -> float:
        return unchanged + float(np.sum(np.where(h > 0, difficulty / np.maximum(2.0 * h, 1.0) ** ALPHA, centre)))

    # The scale runs from where the likeliest pixel just takes the fewest rays to where the least likely
    # one takes the most; the prediction falls in steps between, found by bisection of its logarithm.
    low = math.log10(2 * HALF_LADDER[0] / float(weight.max()))
    high = math.log10(2 * HALF_LADDER[-1] / float(weight.min())) + 1.0
    for _ in range(PLAN_STEPS):
        middle = 0.5 * (low + high)
        if predicted(halves_at(10.0 ** middle)) > squared_budget:
            low = middle
        else:
            high = middle
    halves[active] = halves_at(10.0 ** high)[group]
    return halves


def _groups_by_e0(e0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Each value's group (PLAN_BINS log-spaced groups between the smallest value above 0 and the largest, and
    one group of zeros), and each used group's size and sum, the groups numbered 0.. in order."""
    positive = e0[e0 > 0.0]
    if positive.size:
        low, high = math.log(float(positive.min())), math.log(float(positive.max()))
        width = max(high - low, 1e-12) / PLAN_BINS
        raw = np.where(e0 > 0.0, 1 + np.minimum((np.log(np.maximum(e0, positive.min())) - low) / width,
                                                  PLAN_BINS - 1).astype(np.int64), 0)
    else:
        raw = np.zeros(e0.shape, dtype=np.int64)
    used, group = np.unique(raw, return_inverse=True)
    count = np.bincount(group, minlength=used.size).astype(np.float64)
    return group, count, np.bincount(group, weights=e0, minlength=used.size)


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
    e0 = centre_error(np.clip(film, 0.0, 1.0).reshape(height, width, 3)).ravel()
    halves = _Halves(pixels)
    budget = pixels * target * target
    # The pilot: a random PILOT_FRACTION of all pixels, whatever their e0, get the rays a plan with the
    # starting model gives them, at least PILOT_HALF per half.  Their halves measure both the centre rays'
    # true errors (the model for pixels left with their centre ray) and the jittered rays' (the plan's).
    rows, cols = np.divmod(np.arange(pixels), width)
    pilot = np.flatnonzero(sampling.pixel_uniforms(rows, cols, 1, seed ^ PILOT_SALT)[0][:, 0] < PILOT_FRACTION)
    planned = np.maximum(plan_halves(e0, ErrorModel(), PLAN_AIM * budget)[pilot], PILOT_HALF)
    _trace_halves(camera_rays, rays_for, width, halves, pilot, planned, seed, 0, cancel)
    model = _fitted_model(film, e0, halves, pilot)
    estimate = _Estimate(e0, halves, model)
    aim = PLAN_AIM * budget
    for round_index in range(1, MAX_ROUNDS):
        if estimate.total <= budget:
            break
        wanted = np.maximum(plan_halves(e0, model, aim), halves.count)
        more = wanted - halves.count
        if more.any():
            grow = np.flatnonzero(more)
            _trace_halves(camera_rays, rays_for, width, halves, grow, more[grow], seed, round_index, cancel)
            refined = np.flatnonzero(halves.count)
            estimate.update()
            model = model.refit(e0[refined], estimate.per_pixel[refined], 2.0 * halves.count[refined])
            estimate.model = model
            aim = min(aim, aim * budget / max(estimate.total, 1e-300))
        elif np.all(halves.count[model.difficulty(e0) > 0] == HALF_LADDER[-1]):
            break  # every pixel that could use rays has all it may have
        else:
            aim *= 0.8  # the plan's rounding left the estimate short: ask for a little more
        estimate.update()
    refined = np.flatnonzero(halves.count)
    film[refined] = halves.sums[:, refined].sum(axis=0) / (2.0 * halves.count[refined])[:, None]
    rays = 1 + 2 * halves.count
    result = ErrorEstimate(target=float(target), rms=math.sqrt(max(estimate.total, 0.0) / pixels),
                           worst=float(np.sqrt(estimate.per_pixel.max())), samples_mean=float(rays.mean()),
                           pixels_at_limit=int(np.count_nonzero(halves.count == HALF_LADDER[-1]))
                           if estimate.total > budget else 0,
                           per_pixel=_shown(np.sqrt(estimate.per_pixel), width, height),
                           samples=_shown(rays, width, height))
    return film.reshape(height, width, 3), result


def _fitted_model(film: np.ndarray, e0: np.ndarray, halves: _Halves, pilot: np.ndarray) -> ErrorModel:
    """The error model fitted to the pilot: per pilot pixel, its halves' squared error at its rays, and its
    centre ray's squared error, (centre - halves' mean)² less the halves' own (an unbiased estimate)."""
    squared = halves.squared_error(pilot)
    rays = 2.0 * halves.count[pilot]
    kappa, floor = _fit_line(e0[pilot], squared * rays ** ALPHA, (KAPPA_START, 0.0))
    mean = np.clip(halves.sums[:, pilot].sum(axis=0) / rays[:, None], 0.0, 1.0)
    centre_squared = ((np.clip(film[pilot], 0.0, 1.0) - mean) ** 2).mean(axis=1) - squared
    # e0 stays the centre ray's error where an edge is seen (its h²/12 is what an edge crossing the pixel at
    # random gives; a pilot of a few hundred pixels holds too few edges to scale it down safely).  What
    # centre rays do not see is a floor: the mean excess over e0 of the pilot's lower half by e0 (the upper
    # half, edges where e0 overstates, would hide it), counted only when it stands FLOOR_SIGNIFICANCE
    # standard errors above 0 (one stray edge among flat pixels would otherwise set a floor for all).
    lower = np.argsort(e0[pilot], kind="stable")[:pilot.size // 2]
    excess = centre_squared[lower] - e0[pilot][lower]
    centre_floor = 0.0
    if excess.size >= 2:
        mean, spread = float(excess.mean()), float(excess.std(ddof=1)) / math.sqrt(excess.size)
        if mean > FLOOR_SIGNIFICANCE * spread:
            centre_floor = mean
    return ErrorModel(kappa, floor, 1.0, centre_floor)


class _Estimate:
    """The image's estimated squared errors: the halves' where a pixel is refined, the model's for a centre
    ray alone where it is not."""

    def __init__(self, e0: np.ndarray, halves: _Halves, model: ErrorModel):
        self.e0, self.halves, self.model = e0, halves, model
        self.update()

    def update(self) -> None:
        refined = np.flatnonzero(self.halves.count)
        self.per_pixel = self.model.centre(self.e0)
        self.per_pixel[refined] = self.halves.squared_error(refined)
        self.total = float(self.per_pixel.sum())


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
