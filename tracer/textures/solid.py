"""Solid textures: colours defined everywhere in space, evaluated at a hit's *generic* coordinates, so a
texture moves, turns and scales with its object.

Each function takes (N, 3) generic points and the material's ``parameters`` tuple and returns (N, 3)
colours.  Missing parameters take the defaults below (docs/textures.md lists them).
"""
from __future__ import annotations

import numpy as np

from .noise import noise, turbulence

CHECKER_DEFAULTS = (0.5, 1.0, 1.0, 1.0, 0.1, 0.1, 0.1)  # cell size, colour 1, colour 2
WOOD_DEFAULTS = (0.2, 0.1, 0.85, 0.6, 0.35, 0.45, 0.25, 0.1)  # ring spacing, turbulence, light, dark
MARBLE_DEFAULTS = (4.0, 4.0, 5.0, 0.95, 0.95, 0.92, 0.25, 0.25, 0.3)  # stripes, turbulence, octaves, base, vein


def with_defaults(parameters: tuple, defaults: tuple) -> tuple:
    return tuple(parameters[:len(defaults)]) + tuple(defaults[len(parameters):])


def _mix(a, b, weight: np.ndarray) -> np.ndarray:
    a, b = np.asarray(a, float), np.asarray(b, float)
    return a + (b - a) * weight[:, None]


def checkerboard(points: np.ndarray, parameters: tuple = ()) -> np.ndarray:
    """3D checkerboard of cubes of side ``size``, centred on the lattice so that the faces of the generic
    shapes (at ±1, 0) lie inside cells, not on their boundaries."""
    size, *colours = with_defaults(parameters, CHECKER_DEFAULTS)
    cells = np.floor(points / size + 0.5).astype(np.int64).sum(axis=1)
    odd = (cells % 2).astype(float)
    return _mix(colours[:3], colours[3:6], odd)


def wood(points: np.ndarray, parameters: tuple = ()) -> np.ndarray:
    """Concentric rings about the generic z axis, wobbled by noise: light wood with dark late-wood rings."""
    spacing, wobble, *colours = with_defaults(parameters, WOOD_DEFAULTS)
    radius = np.hypot(points[:, 0], points[:, 1]) + wobble * noise(points * np.array([2.0, 2.0, 0.5]))
    phase = radius / spacing
    ring = (phase - np.floor(phase))  # 0 at a ring's start, rising through the year
    dark = np.clip((ring - 0.65) / 0.35, 0.0, 1.0) ** 2  # a sharp dark edge at the end of each year
    return _mix(colours[:3], colours[3:6], dark)


def marble(points: np.ndarray, parameters: tuple = ()) -> np.ndarray:
    """Veins: a sine across x made irregular by turbulence (sum of |noise| over octaves)."""
    stripes, strength, octaves, *colours = with_defaults(parameters, MARBLE_DEFAULTS)
    wave = np.sin(stripes * np.pi * points[:, 0] + strength * turbulence(points * 2.0, octaves))
    vein = (1.0 - np.abs(wave)) ** 3  # thin dark veins where the sine crosses zero
    return _mix(colours[:3], colours[3:6], vein)


SOLID_TEXTURES = {-1: checkerboard, -2: wood, -3: marble}
#: Each solid texture's parameter defaults, by texture number (the C core fills them in from here too).
SOLID_DEFAULTS = {-1: CHECKER_DEFAULTS, -2: WOOD_DEFAULTS, -3: MARBLE_DEFAULTS}
#: The most parameters a texture reads (marble's defaults; an image reads 2): the C core's slots per material.
MAX_PARAMETERS = max(len(defaults) for defaults in SOLID_DEFAULTS.values())
