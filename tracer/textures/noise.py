"""Gradient noise (Perlin's improved noise) and turbulence, vectorised, for solid textures.

The lattice hash works on integer cell coordinates reduced modulo 256, so it is exact for any float64
coordinate (negative ones and 10^6 included), and the fade curve 6t^5 - 15t^4 + 10t^3 makes noise and its
first two derivatives continuous across lattice planes.  The permutation comes from a fixed integer
recipe (below), so every run — and the C core — sees the same noise.
"""
from __future__ import annotations

import numpy as np


def _permutation() -> np.ndarray:
    """A fixed permutation of 0..255: Fisher–Yates driven by a 32-bit linear congruential generator."""
    perm = list(range(256))
    state = 12345
    for i in range(255, 0, -1):
        state = (1664525 * state + 1013904223) % (1 << 32)
        j = state % (i + 1)
        perm[i], perm[j] = perm[j], perm[i]
    return np.array(perm + perm, dtype=np.int64)


PERM = _permutation()
# The 12 edge directions of a cube: gradients with no preferred axis.
GRADIENTS = np.array([[1, 1, 0], [-1, 1, 0], [1, -1, 0], [-1, -1, 0], [1, 0, 1], [-1, 0, 1],
                      [1, 0, -1], [-1, 0, -1], [0, 1, 1], [0, -1, 1], [0, 1, -1], [0, -1, -1]], dtype=float)


def _fade(t: np.ndarray) -> np.ndarray:
    return t * t * t * (t * (t * 6.0 - 15.0) + 10.0)


def noise(points: np.ndarray) -> np.ndarray:
    """Gradient noise in about [-1, 1] at (..., 3) points; 0 at every lattice point."""
    p = np.asarray(points, dtype=np.float64)
    cell = np.floor(p)
    f = p - cell  # in [0, 1)
    i = np.mod(cell, 256.0).astype(np.int64)  # exact: cell is an integer-valued float
    u = _fade(f)
    result = 0.0
    for dx in (0, 1):
        for dy in (0, 1):
            for dz in (0, 1):
                h = PERM[PERM[PERM[(i[..., 0] + dx) % 256] + (i[..., 1] + dy) % 256] + (i[..., 2] + dz) % 256]
                g = GRADIENTS[h % 12]
                offset = f - np.array([dx, dy, dz], dtype=float)
                dot = np.sum(g * offset, axis=-1)
                wx = u[..., 0] if dx else 1.0 - u[..., 0]
                wy = u[..., 1] if dy else 1.0 - u[..., 1]
                wz = u[..., 2] if dz else 1.0 - u[..., 2]
                result = result + wx * wy * wz * dot
    return result


#: Octaves beyond this add less than 2^-32 of the first one's amplitude (far below what an 8-bit image shows),
#: so a larger count is read as this one: a marble with 10^308 octaves would otherwise never finish.
MAX_OCTAVES = 32


def turbulence(points: np.ndarray, octaves: float = 5) -> np.ndarray:
    """Sum of |noise| over octaves of doubling frequency and halving amplitude (>= 0); ``octaves`` is
    truncated to a whole number in 1..MAX_OCTAVES."""
    p = np.asarray(points, dtype=np.float64)
    total = np.zeros(p.shape[:-1])
    scale = 1.0
    for _ in range(max(1, int(min(octaves, MAX_OCTAVES)))):
        total += np.abs(noise(p * scale)) / scale
        scale *= 2.0
    return total
