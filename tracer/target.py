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
    looks smooth to centre rays); they, kappa and floor are fitted to rays (:func:`fitted_model`,
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
    is at most ``squared_budget`` for the fewest rays, as far as HALF_LADDER's steps allow (see
    :class:`LagrangePlan`)."""
    if float(model.centre(e0).sum()) <= squared_budget:
        return np.zeros(e0.shape, dtype=np.int64)
    bins = E0Bins.spanning(e0)
    index = bins.index(e0)
    bins.add(index, e0)
    plan = LagrangePlan(bins, model, 2 * HALF_LADDER)
    return plan.least(lambda rays: plan.predicted(rays) <= squared_budget)[index] // 2


def plan_rays(bins: "E0Bins", model: ErrorModel, ray_budget: float, ladder: np.ndarray,
              minimum: int = 0) -> np.ndarray:
    """Jittered rays for the pixels of each bin (0: their centre rays alone, else a step of ``ladder``), at
    least ``minimum`` each, that spend at most ``ray_budget`` rays in all for the lowest predicted sum of
    squared errors (see :class:`LagrangePlan`): ``--sampling adaptive``'s refinement (tracer.adaptive)."""
    plan = LagrangePlan(bins, model, ladder)
    idle = float(bins.count.sum() - plan.count.sum())  # pixels with nothing to gain: the minimum alone

    def affordable(rays: np.ndarray) -> bool:
        return plan.cost(np.maximum(rays, minimum)) + minimum * idle <= ray_budget

    return np.maximum(plan.most(affordable), minimum)


class E0Bins:
    """Pixels grouped by e0, all that a plan needs to know of them: PLAN_BINS log-spaced bins between the
    smallest e0 above 0 and the largest (about 1 % apart over 10 decades), and bin 0 for e0 = 0, with each
    bin's pixels and sum of e0 (the model is linear in e0, so a bin's sums are exact).  Filled all at once
    or a band of pixels at a time (:meth:`index`, :meth:`add`), so that a big film needs only its bins'
    numbers, two bytes a pixel."""

    def __init__(self, smallest: float, largest: float):
        """``smallest`` and ``largest``: the range of the values above 0 (inf and 0 when there are none)."""
        self.smallest = smallest
        if math.isfinite(smallest):
            self.low = math.log(smallest)
            self.width = max(math.log(largest) - self.low, 1e-12) / PLAN_BINS
        self.count = np.zeros(PLAN_BINS + 1)
        self.total = np.zeros(PLAN_BINS + 1)

    @classmethod
    def spanning(cls, e0: np.ndarray) -> "E0Bins":
        positive = e0[e0 > 0.0]
        if positive.size == 0:
            return cls(math.inf, 0.0)
        return cls(float(positive.min()), float(positive.max()))

    def index(self, e0: np.ndarray) -> np.ndarray:
        """Each value's bin (values outside the range go to the nearest bin)."""
        if not math.isfinite(self.smallest):
            return np.zeros(e0.shape, dtype=np.int64)
        place = (np.log(np.maximum(e0, self.smallest)) - self.low) / self.width
        return np.where(e0 > 0.0, 1 + np.minimum(place, PLAN_BINS - 1).astype(np.int64), 0)

    def add(self, index: np.ndarray, e0: np.ndarray) -> None:
        self.count += np.bincount(index.ravel(), minlength=PLAN_BINS + 1)
        self.total += np.bincount(index.ravel(), weights=e0.ravel(), minlength=PLAN_BINS + 1)


class LagrangePlan:
    """The rays each bin of pixels gets at one price of error, for every price: spending the fewest rays for
    a predicted sum of squared errors (or the lowest sum for so many rays) gives each pixel rays in
    proportion to ``model.difficulty(e0) ** (1 / (1 + ALPHA))`` (a Lagrange multiplier); ``scale`` is that
    proportion.  Counts are rounded down to ``ladder`` (rays per pixel, increasing), and a bin is refined
    only where its rays are predicted to do better than its centre rays.  Every pixel of a bin of
    :class:`E0Bins` gets the bin's rays, so finding the scale by bisection (:meth:`least`, :meth:`most`)
    costs nothing next to the rays.  Both return rays per bin (index them with :meth:`E0Bins.index`)."""

    def __init__(self, bins: E0Bins, model: ErrorModel, ladder: np.ndarray):
        self.ladder = np.asarray(ladder)
        used = np.flatnonzero(bins.count)
        used_mean = bins.total[used] / bins.count[used]
        active = model.difficulty(used_mean) > 0.0  # (flat pixels, most of most images, never take rays)
        self.bins, idle = used[active], used[~active]
        self.unchanged = float(np.sum(model.centre_scale * bins.total[idle] + model.centre_floor * bins.count[idle]))
        self.count, e0_sum = bins.count[self.bins], bins.total[self.bins]
        e0_mean = used_mean[active]
        self.difficulty = model.kappa * e0_sum + model.floor * self.count  # each bin's sums
        self.centre = model.centre_scale * e0_sum + model.centre_floor * self.count
        self.weight = np.power(model.difficulty(e0_mean), 1.0 / (1.0 + ALPHA))
        # Refine a bin where rays^ALPHA exceeds this: where its rays beat its centre rays (never where a
        # centre ray is predicted exact).
        centre_mean = model.centre(e0_mean)
        self.better_at = np.divide(model.difficulty(e0_mean), centre_mean,
                                   out=np.full(centre_mean.shape, np.inf), where=centre_mean > 0.0)

    def rays_at(self, scale: float) -> np.ndarray:
        """Each refinable bin's rays at ``scale``: a step of the ladder, or 0."""
        wanted = scale * self.weight
        step = self.ladder[np.maximum(np.searchsorted(self.ladder, wanted, side="right") - 1, 0)]
        return np.where((wanted >= self.ladder[0]) & (step.astype(float) ** ALPHA > self.better_at), step, 0)

    def predicted(self, rays: np.ndarray) -> float:
        """The predicted sum of squared errors of the image with each refinable bin's ``rays``."""
        return self.unchanged + float(np.sum(np.where(
            rays > 0, self.difficulty / np.maximum(rays, 1.0) ** ALPHA, self.centre)))

    def cost(self, rays: np.ndarray) -> float:
        """The jittered rays of the refinable bins' pixels with each bin's ``rays``."""
        return float(np.sum(rays * self.count))

    def least(self, enough: Callable[[np.ndarray], bool]) -> np.ndarray:
        """Rays per bin at the smallest scale whose rays are ``enough`` (at most the ladder's top)."""
        return self._per_bin(self._bisect(enough)[1])

    def most(self, affordable: Callable[[np.ndarray], bool]) -> np.ndarray:
        """Rays per bin at the largest scale whose rays are ``affordable`` (none, if even the fewest are not)."""
        scale = self._bisect(lambda rays: not affordable(rays))[0]
        if not affordable(self.rays_at(scale)):
            scale = 0.0
        return self._per_bin(scale)

    def _bisect(self, past: Callable[[np.ndarray], bool]) -> tuple[float, float]:
        """(low, high) scales either side of where ``past`` (False at small scales, True at large) turns.
        The scale runs from where the likeliest pixel just takes the fewest rays to where the least likely
        one takes the most; the bins' rays change in steps between, found by bisection of its logarithm."""
        if self.bins.size == 0:
            return 0.0, 0.0
        low = math.log10(float(self.ladder[0]) / float(self.weight.max()))
        high = math.log10(float(self.ladder[-1]) / float(self.weight.min())) + 1.0
        for _ in range(PLAN_STEPS):
            middle = 0.5 * (low + high)
            if past(self.rays_at(10.0 ** middle)):
                high = middle
            else:
                low = middle
        return 10.0 ** low, 10.0 ** high

    def _per_bin(self, scale: float) -> np.ndarray:
        rays = np.zeros(PLAN_BINS + 1, dtype=np.int64)
        if self.bins.size:
            rays[self.bins] = self.rays_at(scale)
        return rays


class _Halves:
    """The two halves' colour sums of every pixel and how many rays each half has."""

    def __init__(self, pixels: int):
        self.sums = np.zeros((2, pixels, 3))
        self.count = np.zeros(pixels, dtype=np.int64)

    def means(self, pixels: np.ndarray) -> np.ndarray:
        return self.sums[:, pixels] / self.count[pixels][None, :, None]

    def squared_error(self, pixels: np.ndarray) -> np.ndarray:
        return halves_squared_error(self.means(pixels))


def halves_squared_error(means: np.ndarray) -> np.ndarray:
    """Per pixel of (2, pixels, 3) means of two independent halves of its rays: (clipped mean of half 0 -
    clipped mean of half 1)² / 4, mean over channels, an unbiased estimate of the squared error of the mean
    of all its rays."""
    means = np.clip(means, 0.0, 1.0)
    return ((means[0] - means[1]) ** 2).mean(axis=1) / 4.0


def half_seed(seed: int, round_index: int, half: int) -> int:
    """The seed of one half's jittered rays in one round: independent of the other half's and of the
    rounds'."""
    return (int(seed) << 16) + 2 * round_index + half


def pilot_pixels(rows: np.ndarray, cols: np.ndarray, seed: int) -> np.ndarray:
    """Which of the pixels (rows[i], cols[i]) are in the pilot: a random PILOT_FRACTION of all pixels,
    whatever their colour, each decided by a hash of (seed, pixel) alone (so a tile can tell its own)."""
    return sampling.pixel_uniforms(rows, cols, 1, seed ^ PILOT_SALT)[0][:, 0] < PILOT_FRACTION


def _trace_halves(camera_rays: CameraRays, rays_for, width: int, halves: _Halves, pixels: np.ndarray,
                  more: np.ndarray, seed: int, round_index: int, cancel) -> None:
    """Give each pixel ``more[i]`` new rays in each half: a jittered set per half, independent of the other
    half and of earlier rounds (its own seed)."""
    for extra in np.unique(more):
        group = pixels[more == extra]
        extra = int(extra)
        step = max(1, MAX_RAYS_PER_CALL // extra)
        for half in (0, 1):
            seed_of_half = half_seed(seed, round_index, half)
            for start in range(0, group.size, step):
                if cancel is not None and cancel():
                    raise RenderCancelled("render cancelled")
                chunk = group[start:start + step]
                rows, cols = np.divmod(chunk, width)
                dy, dx = sampling.offsets(extra, True, rows, cols, seed_of_half)
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
    pilot = np.flatnonzero(pilot_pixels(rows, cols, seed))
    planned = np.maximum(plan_halves(e0, ErrorModel(), PLAN_AIM * budget)[pilot], PILOT_HALF)
    _trace_halves(camera_rays, rays_for, width, halves, pilot, planned, seed, 0, cancel)
    model = fitted_model(film[pilot], e0[pilot], halves.means(pilot), 2.0 * halves.count[pilot])
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


def fitted_model(centre: np.ndarray, e0: np.ndarray, means: np.ndarray, rays: np.ndarray,
                 floor_significance: float = FLOOR_SIGNIFICANCE) -> ErrorModel:
    """The error model fitted to a pilot: per pilot pixel, its centre ray's colour ``centre`` (pixels, 3),
    its ``e0``, the ``means`` (2, pixels, 3) of two independent halves of its jittered rays and how many
    ``rays`` the two have together.  The halves give their own squared error (:func:`halves_squared_error`)
    and the centre ray's, (centre - halves' mean)² less theirs (an unbiased estimate).  A floor under the
    centre rays counts from ``floor_significance`` standard errors above 0."""
    squared = halves_squared_error(means)
    kappa, floor = _fit_line(e0, squared * rays ** ALPHA, (KAPPA_START, 0.0))
    mean = np.clip(0.5 * (means[0] + means[1]), 0.0, 1.0)
    centre_squared = ((np.clip(centre, 0.0, 1.0) - mean) ** 2).mean(axis=1) - squared
    # e0 stays the centre ray's error where an edge is seen (its h²/12 is what an edge crossing the pixel at
    # random gives; a pilot of a few hundred pixels holds too few edges to scale it down safely).  What
    # centre rays do not see is a floor: the mean excess over e0 of the pilot's lower half by e0 (the upper
    # half, edges where e0 overstates, would hide it), counted only when it stands floor_significance
    # standard errors above 0 (for the target, FLOOR_SIGNIFICANCE: one stray edge among flat pixels would
    # otherwise set a floor for all, and the estimate with it).
    lower = np.argsort(e0, kind="stable")[:e0.size // 2]
    excess = centre_squared[lower] - e0[lower]
    centre_floor = 0.0
    if excess.size >= 2:
        mean, spread = float(excess.mean()), float(excess.std(ddof=1)) / math.sqrt(excess.size)
        if mean > floor_significance * spread:
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
