"""Property-based: for random affine placements and random rays, every reported hit lies on the shape.

The hit point is mapped back to generic coordinates and put into the shape's implicit equation; hits
alternate entering/exiting for closed solids.
"""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given, settings
from hypothesis import strategies as st

import tracer
from helpers import scene_of, shape
from tracer.model import TORUS_TUBE_RADIUS

coordinate = st.floats(-3, 3, allow_nan=False)
vector = st.tuples(coordinate, coordinate, coordinate)


@st.composite
def affine(draw):
    """A well-conditioned random affine matrix: random linear part with singular values in [0.2, 5]."""
    a = np.array(draw(st.lists(st.floats(-1, 1), min_size=9, max_size=9))).reshape(3, 3)
    u, _, vt = np.linalg.svd(a + np.eye(3) * 1e-3)
    s = np.array(draw(st.lists(st.floats(0.2, 5), min_size=3, max_size=3)))
    m = np.eye(4)
    m[:3, :3] = u @ np.diag(s) @ vt
    m[:3, 3] = draw(vector)
    return m


def residual(kind: str, p: np.ndarray) -> float:
    """How far generic point p is from the generic surface (0 on it), in generic units."""
    x, y, z = p
    if kind == "sphere":
        return abs(np.linalg.norm(p) - 1)
    if kind == "cube":
        return abs(np.max(np.abs(p)) - 1)
    if kind in ("cylinder", "cone"):
        s = 1.0 if kind == "cylinder" else 0.0
        radius = 1 + (s - 1) * z
        wall = abs(np.hypot(x, y) - radius) if -1e-9 <= z <= 1 + 1e-9 else np.inf
        base = abs(z) if np.hypot(x, y) <= 1 + 1e-9 else np.inf
        cap = abs(z - 1) if np.hypot(x, y) <= s + 1e-9 else np.inf
        return min(wall, base, cap)
    if kind == "torus":
        return abs(np.hypot(np.hypot(x, y) - 1, z) - TORUS_TUBE_RADIUS)
    if kind == "square":
        return abs(z) if max(abs(x), abs(y)) <= 1 + 1e-9 else np.inf
    if kind == "plane":
        return abs(z)
    raise AssertionError(kind)


CLOSED = ["sphere", "cube", "cylinder", "cone", "torus"]


def inside(kind: str, p: np.ndarray) -> bool:
    x, y, z = p
    if kind == "sphere":
        return np.linalg.norm(p) < 1
    if kind == "cube":
        return np.max(np.abs(p)) < 1
    if kind in ("cylinder", "cone"):
        radius = 1.0 if kind == "cylinder" else 1.0 - z
        return 0 < z < 1 and np.hypot(x, y) < radius
    if kind == "torus":
        return np.hypot(np.hypot(x, y) - 1, z) < TORUS_TUBE_RADIUS
    raise AssertionError(kind)


@settings(max_examples=60, deadline=None)
@given(kind=st.sampled_from(CLOSED + ["square", "plane"]), matrix=affine(), start=vector,
       aim=st.tuples(st.floats(-0.9, 0.9), st.floats(-0.9, 0.9), st.floats(-0.9, 0.9)))
def test_hits_lie_on_the_surface(kind, matrix, start, aim):
    # Aim at a point inside the generic shape's bounds so that most rays hit.
    target = matrix[:3, :3] @ np.array(aim) * (0.2 if kind == "torus" else 1.0) + matrix[:3, 3]
    if kind == "torus":
        target = matrix[:3, :3] @ (np.array([1.0, 0.0, 0.0]) + 0.15 * np.array(aim)) + matrix[:3, 3]
    origin = np.array(start) * 4 + matrix[:3, 3] + 8 * matrix[:3, :3] @ np.array([0.3, 0.5, 0.8])
    direction = target - origin
    assume(np.linalg.norm(direction) > 1e-3)
    scene = scene_of(shape(kind, matrix))
    hits = tracer.hits(scene, origin, direction)
    inverse = np.linalg.inv(matrix)
    for h in hits:
        generic = inverse[:3, :3] @ np.array(h.point) + inverse[:3, 3]
        assert residual(kind, generic) < 1e-9 * (1 + np.abs(generic).max())
        assert np.linalg.norm(h.normal) == pytest.approx(1.0)
    if kind in CLOSED:
        # In, out, in, out... starting "out" when the ray starts inside the solid.
        o = inverse[:3, :3] @ origin + inverse[:3, 3]
        starts_inside = inside(kind, o)
        assert [h.entering for h in hits] == [(i % 2 == 0) != starts_inside for i in range(len(hits))]
        assert len(hits) % 2 == int(starts_inside)


@settings(max_examples=40, deadline=None)
@given(matrix=affine(), aim=st.tuples(st.floats(-0.5, 0.5), st.floats(-0.5, 0.5), st.floats(-0.5, 0.5)))
def test_entering_normals_face_the_ray(matrix, aim):
    target = matrix[:3, :3] @ np.array(aim) + matrix[:3, 3]
    origin = matrix[:3, 3] + 10 * matrix[:3, :3] @ np.array([0.2, 0.3, 1.0])
    hits = tracer.hits(scene_of(shape("sphere", matrix)), origin, target - origin)
    assert len(hits) == 2  # the target is inside the ellipsoid
    d = target - origin
    assert np.dot(hits[0].normal, d) < 0 < np.dot(hits[1].normal, d)
