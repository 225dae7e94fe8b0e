"""Anti-aliasing: where inside a pixel its rays go.

* ``regular``: an a x b grid of sub-pixel centres (a * b = samples, as square as samples allows);
* ``jittered``: the same strata, one random point in each (stratified sampling), from a fixed seed, so a
  render is repeatable;
* ``adaptive``: one ray through each pixel centre first; then only pixels that differ from a neighbour by
  more than a threshold (in any channel) are traced again with ``samples`` jittered rays.

One sample means one ray through the pixel centre, whatever the mode.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import TracerError

MODES = ("regular", "jittered", "adaptive")
DEFAULT_THRESHOLD = 0.05
MAX_SAMPLES = 1024


def check(samples: int, mode: str, threshold: float = DEFAULT_THRESHOLD) -> None:
    if not 1 <= samples <= MAX_SAMPLES:
        raise TracerError(f"samples must be between 1 and {MAX_SAMPLES}, not {samples}")
    if mode not in MODES:
        raise TracerError(f"unknown sampling mode {mode!r} (use one of {', '.join(MODES)})")
    if not (math.isfinite(threshold) and threshold >= 0.0):  # NaN would refine nothing, silently
        raise TracerError(f"the adaptive threshold must be a number 0 or more, not {threshold}")


def grid_shape(samples: int) -> tuple[int, int]:
    """Rows and columns of strata: the divisor pair of ``samples`` closest to square."""
    rows = max(d for d in range(1, math.isqrt(samples) + 1) if samples % d == 0)
    return rows, samples // rows


def offsets(samples: int, jitter: bool, count: int, rng: np.random.Generator | None = None):
    """Sub-pixel offsets (dy, dx) in [0, 1), shape (count, samples) each, for ``count`` pixels."""
    rows, cols = grid_shape(samples)
    j, i = np.meshgrid(np.arange(rows), np.arange(cols), indexing="ij")
    base_y = np.broadcast_to(j.ravel(), (count, samples)).astype(float)
    base_x = np.broadcast_to(i.ravel(), (count, samples)).astype(float)
    if jitter:
        rng = rng or np.random.default_rng(0)
        fy, fx = rng.random((count, samples)), rng.random((count, samples))
    else:
        fy = fx = np.full((count, samples), 0.5)
    return (base_y + fy) / rows, (base_x + fx) / cols


def contrast_mask(image: np.ndarray, threshold: float) -> np.ndarray:
    """Pixels whose colour differs from a 4-neighbour's by more than ``threshold`` in some channel."""
    mask = np.zeros(image.shape[:2], dtype=bool)
    vertical = np.abs(np.diff(image, axis=0)).max(axis=2) > threshold
    horizontal = np.abs(np.diff(image, axis=1)).max(axis=2) > threshold
    mask[:-1] |= vertical
    mask[1:] |= vertical
    mask[:, :-1] |= horizontal
    mask[:, 1:] |= horizontal
    return mask
