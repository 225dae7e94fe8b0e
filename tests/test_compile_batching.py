"""The per-scene batching in compile_scene and the parser's quick singularity check give what the per-shape
NumPy calls give: the same inverse matrices and bounding spheres (to rounding: a stacked product may round
differently in the last place, depending on the NumPy build), and the same answer from is_singular for every
matrix, near-singular and extreme ones included."""
from __future__ import annotations

import numpy as np
import pytest

import tracer
from helpers import rotation, scaling, scene_of, shape, translation
from tracer.compile import Primitive, compile_scene
from tracer.errors import TracerError
from tracer.model import CSG
from tracer.sdl.parser import _clearly_invertible, _numpy_is_singular, is_singular


def _random_matrix(rng, spread=1e3):
    return (translation(*rng.uniform(-spread, spread, 3)) @ rotation(rng.uniform(0, 360), *rng.normal(size=3))
            @ scaling(*np.exp(rng.uniform(-5, 5, 3))))


def test_batched_inverses_and_bounds_equal_the_per_shape_ones():
    rng = np.random.default_rng(1)
    kinds = ["sphere", "cube", "square", "plane", "cylinder", "cone", "torus", "taperedCylinder"]
    objects = []
    for i in range(300):
        s = shape(kinds[i % len(kinds)], _random_matrix(rng))
        s.parameters = (float(rng.uniform(0, 2)),) * len(s.parameters)
        objects.append(s)
    ico = tracer.parse_sdl("icosahedron").shapes()[0]
    ico.matrix = _random_matrix(rng)
    objects.append(CSG("difference", ico, shape("sphere", _random_matrix(rng))))
    compiled = compile_scene(scene_of(*objects))
    for prim in compiled.primitives:
        alone = Primitive(prim.shape, prim.index, prim.material_id)  # each computed on its own, as before
        np.testing.assert_allclose(prim.inverse, alone.inverse, rtol=1e-12,
                                   atol=1e-15 * np.abs(alone.inverse).max())
        assert prim.radius == pytest.approx(alone.radius, rel=1e-13)
        if alone.center is None:
            assert prim.center is None
        else:
            # The 1e-9 padding of the radius covers any last-place difference in the centre.
            assert np.linalg.norm(prim.center - alone.center) < 1e-12 * alone.radius


@pytest.mark.parametrize("bad", ["singular", "not finite", "not affine"])
def test_a_bad_matrix_still_names_the_first_bad_shape(bad):
    good = shape("sphere", translation(1, 2, 3))
    broken = shape("cube", scaling(1, 0, 1))
    if bad == "not finite":
        broken.matrix = broken.matrix.copy()
        broken.matrix[0, 3] = np.inf
    elif bad == "not affine":
        broken.matrix = broken.matrix.copy()
        broken.matrix[3, 0] = 0.5
        broken.matrix[1, 1] = 1.0
    with pytest.raises(TracerError, match="cube"):
        compile_scene(scene_of(good, broken, shape("cone", scaling(0, 0, 0))))


def test_quick_singularity_check_agrees_with_numpy():
    rng = np.random.default_rng(2)
    matrices = [_random_matrix(rng) for _ in range(2000)]
    # Near the condition limit, rank-deficient, tiny and huge scales, non-finite entries.
    for exponent in range(0, 20):
        matrices.append(scaling(1, 1, 10.0 ** -exponent))
        matrices.append(rotation(37, 1, 2, 3) @ scaling(1, 10.0 ** exponent, 1))
    for scale in (1e-120, 1e-100, 1e-80, 1e-60, 1e60, 1e80, 1e100, 1e120):
        matrices.append(scaling(scale, scale, scale))
        matrices.append(scaling(scale, 1.0, 1.0))
    u, v = rng.normal(size=3), rng.normal(size=3)
    rank_one = np.eye(4)
    rank_one[:3, :3] = np.outer(u, v)
    rank_two = np.eye(4)
    rank_two[:3, :3] = np.outer(u, v) + np.outer(v, u)
    matrices += [rank_one, rank_two, np.zeros((4, 4)), translation(np.inf, 0, 0), scaling(np.nan, 1, 1)]
    quick = 0
    for m in matrices:
        with np.errstate(all="ignore"):  # NumPy's det overflows for the huge scales, with a warning
            assert is_singular(m) == _numpy_is_singular(m), m
        quick += _clearly_invertible(m)
    assert quick >= 1900  # the quick answer is the one taken for ordinary transforms


def test_batched_rounding_equals_the_per_primitive_one():
    rng = np.random.default_rng(4)
    objects = [shape(kind, _random_matrix(rng)) for kind in ["sphere", "cube", "torus", "cone"] * 50]
    compiled = compile_scene(scene_of(*objects))
    for prim in compiled.primitives:
        assert prim.inverse_error is not None  # computed by compile_scene for all at once
        alone = Primitive(prim.shape, prim.index, prim.material_id)
        assert prim.rounding == pytest.approx(alone.rounding, rel=1e-6, abs=1e-18)
        assert prim.generic_size == alone.generic_size
