"""Anti-aliasing: where inside a pixel its rays go.

* ``regular``: an a x b grid of sub-pixel centres (a * b = samples, as square as samples allows);
* ``jittered``: the same strata, one random point in each (stratified sampling).  The random numbers are
  a function of (seed, pixel, sample) alone (a counter-based hash, no generator state), so a render is
  repeatable and any cut into tiles, in any order, on any number of machines, gives the same bytes;
* ``adaptive``: one ray through each pixel centre first, then jittered rays where an error model says they
  lower the image's error most, about ``samples`` rays per pixel on average in all (:mod:`tracer.adaptive`).

One sample means one ray through the pixel centre, whatever the mode.
"""
from __future__ import annotations

import math

import numpy as np

from .errors import TracerError

MODES = ("regular", "jittered", "adaptive")
MAX_SAMPLES = 1024


def check(samples: int, mode: str) -> None:
    if not 1 <= samples <= MAX_SAMPLES:
        raise TracerError(f"samples must be between 1 and {MAX_SAMPLES}, not {samples}")
    if mode not in MODES:
        raise TracerError(f"unknown sampling mode {mode!r} (use one of {', '.join(MODES)})")


def grid_shape(samples: int) -> tuple[int, int]:
    """Rows and columns of strata: the divisor pair of ``samples`` closest to square."""
    rows = max(d for d in range(1, math.isqrt(samples) + 1) if samples % d == 0)
    return rows, samples // rows


def offsets(samples: int, jitter: bool, rows: np.ndarray, cols: np.ndarray, seed: int = 0):
    """Sub-pixel offsets (dy, dx) in [0, 1), shape (count, samples) each, for the pixels (rows[i], cols[i]).

    Jittered offsets depend only on ``seed``, the pixel and the sample's number (see :func:`pixel_uniforms`)."""
    rows, cols = np.asarray(rows), np.asarray(cols)
    count = rows.size
    grid_rows, grid_cols = grid_shape(samples)
    j, i = np.meshgrid(np.arange(grid_rows), np.arange(grid_cols), indexing="ij")
    base_y = np.broadcast_to(j.ravel(), (count, samples)).astype(float)
    base_x = np.broadcast_to(i.ravel(), (count, samples)).astype(float)
    if jitter:
        fy, fx = pixel_uniforms(rows, cols, samples, seed)
    else:
        fy = fx = np.full((count, samples), 0.5)
    return (base_y + fy) / grid_rows, (base_x + fx) / grid_cols


_MASK64 = (1 << 64) - 1
_GOLDEN = 0x9E3779B97F4A7C15  # SplitMix64's increment: 2^64 / the golden ratio, odd


def _mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64's finaliser on uint64 arrays (wrapping arithmetic): every input bit flips about half of the
    output bits, so consecutive counters give independent-looking numbers."""
    x = (x ^ (x >> np.uint64(30))) * np.uint64(0xBF58476D1CE4E5B9)
    x = (x ^ (x >> np.uint64(27))) * np.uint64(0x94D049BB133111EB)
    return x ^ (x >> np.uint64(31))


def _mix64_int(x: int) -> int:
    """The same finaliser on a Python int (for the seed; NumPy warns on overflowing scalars)."""
    x &= _MASK64
    x = ((x ^ (x >> 30)) * 0xBF58476D1CE4E5B9) & _MASK64
    x = ((x ^ (x >> 27)) * 0x94D049BB133111EB) & _MASK64
    return x ^ (x >> 31)


def pixel_uniforms(rows: np.ndarray, cols: np.ndarray, samples: int, seed: int = 0):
    """Two (count, samples) arrays of numbers in [0, 1) for the pixels (rows[i], cols[i]): number k of pixel
    (r, c) is SplitMix64's output k of a stream that starts at a hash of (seed, r, c).  Counter-based: no state
    is carried from one pixel to the next, so the numbers do not depend on which pixels are drawn together."""
    key = (np.asarray(rows, dtype=np.int64).astype(np.uint64) << np.uint64(32)) | \
        np.asarray(cols, dtype=np.int64).astype(np.uint64)
    start = _mix64(key.ravel() ^ np.uint64(_mix64_int(int(seed) ^ _GOLDEN)))
    counters = np.arange(1, 2 * samples + 1, dtype=np.uint64) * np.uint64(_GOLDEN)
    bits = _mix64(start[:, None] + counters[None, :])  # (count, 2 * samples), wrapping add
    uniforms = (bits >> np.uint64(11)).astype(np.float64) * (1.0 / (1 << 53))
    return uniforms[:, :samples], uniforms[:, samples:]
