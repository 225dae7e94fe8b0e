"""The NumPy path traces many primitives of one kind at once (tracer.batches) and must find the very hits it
finds one object at a time: the same t, normal, object and primitive to the bit, the same ties, the same
shadow feelers, the same image.  A 2,048-sphere boolean with 2,048 coincident spheres beside it took 88 s on
this path at 32 x 24 (a fuzz input); the regression file tests/fuzz/regressions/numpy_2048_coincident_spheres.sdl
runs it within the fuzz run's limits."""
from __future__ import annotations

import numpy as np
import pytest

import tracer
from tracer import batches
from tracer.compile import compile_scene
from tracer.render import render
from tracer.trace import first_hits, occluded

#: Spheres, some coincident (ties), cubes, tapered cylinders of two parameters, squares (thin), planes
#: (unbounded), a tetrahedron, and a boolean of 25 sphere leaves; spheres, cubes and squares past BATCH_MIN.
SCENE = """
camera 0 2 9  0 0.5 0  0 1 0  40
light 3 6 5  1 1 1
light -4 5 2  0.5 0.5 0.5
background 0.1 0.1 0.2
push rotate -90 1 0 0 plane pop
push translate 0 0 -3 plane pop
def eight { push rotate 0 1 2 3 sphere pop push rotate 17 1 2 3 sphere pop push rotate 33 3 -1 2 sphere pop
             push rotate 71 0 1 0 sphere pop push rotate 5 1 1 1 sphere pop push rotate 123 2 0 1 sphere pop
             push rotate 250 1 -3 1 sphere pop push rotate 301 0 0 1 sphere pop }
push translate 0 1 0 use eight pop
push translate 0.5 1.2 0.3 scale 0.7 0.7 0.7 use eight pop
reflectivity 0.3
push translate -2 0.5 0 scale 0.4 0.4 0.4 cube pop
push translate -2.2 1.5 0.2 rotate 30 0 1 1 scale 0.3 0.3 0.3 cube pop
push translate 2 0.5 0 rotate 45 0 1 0 scale 0.4 0.4 0.4 cube pop
push translate 2 1.5 0.5 scale 0.3 0.5 0.3 cube pop
push translate -1 2.4 0 scale 0.2 0.2 0.2 cube pop
push translate 1 2.4 0 scale 0.2 0.2 0.2 cube pop
push translate 0 2.8 -1 scale 0.2 0.2 0.2 cube pop
push translate 0 0.2 1.5 scale 0.2 0.2 0.2 cube pop
reflectivity 0
transparency 0.6 speedOfLight 0.8
push translate -3 0 1 rotate -90 1 0 0 scale 0.3 0.3 0.8 taperedCylinder 0.5 pop
push translate -2.4 0 1.3 rotate -90 1 0 0 scale 0.3 0.3 0.8 taperedCylinder 0.5 pop
push translate -1.8 0 1.6 rotate -90 1 0 0 scale 0.3 0.3 0.8 taperedCylinder 0.5 pop
push translate 1.8 0 1.6 rotate -90 1 0 0 scale 0.3 0.3 0.8 taperedCylinder 0.25 pop
push translate 2.4 0 1.3 rotate -90 1 0 0 scale 0.3 0.3 0.8 taperedCylinder 0.25 pop
push translate 3 0 1 rotate -90 1 0 0 scale 0.3 0.3 0.8 taperedCylinder 0.25 pop
transparency 0
def tile { push scale 0.3 0.3 0.3 square pop }
def tiles { push translate -1.5 0.01 2 use tile pop push translate -0.5 0.01 2 use tile pop
            push translate 0.5 0.01 2 use tile pop push translate 1.5 0.01 2 use tile pop }
use tiles push translate 0 0 0.8 use tiles pop
push translate 0 3 0 scale 0.5 0.5 0.5 tetrahedron pop
difference
  push translate 0 0.6 2 scale 0.5 0.5 0.5 sphere pop
  union union union union union union union union union union union union union union union union union union
  union union union union union
    push translate 0.1 0.6 2.4 scale 0.1 0.1 0.1 sphere pop push translate -0.1 0.6 2.4 scale 0.1 0.1 0.1 sphere pop
    push translate 0.2 0.7 2.4 scale 0.1 0.1 0.1 sphere pop push translate -0.2 0.7 2.4 scale 0.1 0.1 0.1 sphere pop
    push translate 0.3 0.5 2.4 scale 0.1 0.1 0.1 sphere pop push translate -0.3 0.5 2.4 scale 0.1 0.1 0.1 sphere pop
    push translate 0.1 0.4 2.4 scale 0.1 0.1 0.1 sphere pop push translate -0.1 0.4 2.4 scale 0.1 0.1 0.1 sphere pop
    push translate 0 0.8 2.4 scale 0.1 0.1 0.1 sphere pop push translate 0 0.9 2.3 scale 0.1 0.1 0.1 sphere pop
    push translate 0.35 0.65 2.2 scale 0.1 0.1 0.1 sphere pop push translate -0.35 0.65 2.2 scale 0.1 0.1 0.1 sphere pop
    push translate 0.1 0.6 2.45 scale 0.1 0.1 0.1 sphere pop push translate -0.1 0.6 2.45 scale 0.1 0.1 0.1 sphere pop
    push translate 0.2 0.7 2.45 scale 0.1 0.1 0.1 sphere pop push translate -0.2 0.7 2.45 scale 0.1 0.1 0.1 sphere pop
    push translate 0.3 0.5 2.45 scale 0.1 0.1 0.1 sphere pop push translate -0.3 0.5 2.45 scale 0.1 0.1 0.1 sphere pop
    push translate 0.1 0.4 2.45 scale 0.1 0.1 0.1 sphere pop push translate -0.1 0.4 2.45 scale 0.1 0.1 0.1 sphere pop
    push translate 0 0.8 2.45 scale 0.1 0.1 0.1 sphere pop push translate 0 0.9 2.35 scale 0.1 0.1 0.1 sphere pop
    push translate 0.05 0.6 2.5 scale 0.1 0.1 0.1 sphere pop push translate -0.05 0.6 2.5 scale 0.1 0.1 0.1 sphere pop
"""


@pytest.fixture(scope="module")
def compiled():
    return compile_scene(tracer.parse_sdl(SCENE))


def _one_by_one(monkeypatch, compiled):
    monkeypatch.setattr(batches, "BATCH_MIN", 10 ** 9)
    monkeypatch.setattr(compiled.objects, "batches", None)  # (the grouping made again, and put back after)


def _rays(count: int, seed: int):
    """Rays from around the scene towards its objects, and feelers that end on its surfaces."""
    rng = np.random.default_rng(seed)
    origins = rng.uniform(-4, 4, (count, 3)) + np.array([0, 3, 6])
    targets = rng.uniform(-2.5, 2.5, (count, 3)) + np.array([0, 1, 1])
    return origins, targets - origins


def test_the_scene_is_traced_in_batches(compiled):
    found, alone = batches.batches_of(compiled.objects, compiled.table)
    kinds = sorted({compiled.table.shapes[int(b.rows[0])].kind for b in found})
    assert kinds == ["cube", "sphere", "square"]  # (2 planes, 3 + 3 cylinders, 1 tetrahedron: too few)
    assert sum(len(b.objects) for b in found) == 16 + 8 + 8
    assert set(alone.tolist()).isdisjoint(np.concatenate([b.objects for b in found]).tolist())
    boolean = compiled.objects[int(alone[-1])]
    assert len(batches.LeafHits(list(boolean.leaves()), *_rays(4, 0))) == 25  # (the ball and its 24 dents)


@pytest.mark.parametrize("count, pairs_at_once", [(4000, None), (300, 7)])
def test_first_hits_and_feelers_are_the_same_bits(compiled, monkeypatch, count, pairs_at_once):
    """(With 7 pairs at a time, a ray's pairs fall in several chunks: each chunk's finds must respect the
    earlier ones'.)"""
    if pairs_at_once:
        monkeypatch.setattr(batches, "PAIRS_AT_ONCE", pairs_at_once)
    origins, directions = _rays(count, 1)
    t_min = np.where(np.arange(count) % 3 == 0, 0.0, 0.3)
    together = first_hits(compiled, origins, directions, t_min)
    blocked_together = occluded(compiled, origins, directions, 0.9)
    assert together.hit.sum() > count / 2
    assert np.isin(together.obj, np.concatenate([b.objects for b in batches.batches_of(
        compiled.objects, compiled.table)[0]])).sum() > count / 8  # (batched objects won many rays)
    _one_by_one(monkeypatch, compiled)
    alone = first_hits(compiled, origins, directions, t_min)
    for name in ("hit", "t", "normal", "entering", "shape", "obj", "part", "uv", "error", "offset"):
        np.testing.assert_array_equal(getattr(together, name), getattr(alone, name), err_msg=name)
    np.testing.assert_array_equal(blocked_together, occluded(compiled, origins, directions, 0.9))


def test_coincident_spheres_tie_to_the_first(compiled):
    """Eight spheres in one place, each turned its own way: every ray that meets them meets all eight at t
    that differ by their rounding; the first in the scene wins, as it does one object at a time."""
    origins, directions = _rays(2000, 2)
    hits = first_hits(compiled, origins, directions)
    spheres = [b for b in batches.batches_of(compiled.objects, compiled.table)[0]
               if compiled.table.shapes[int(b.rows[0])].kind == "sphere"]
    first_ball = int(spheres[0].objects.min())
    group = (hits.obj >= first_ball) & (hits.obj < first_ball + 8)
    assert group.sum() > 50
    assert set(hits.obj[group].tolist()) == {first_ball}


def test_a_booleans_leaves_in_blocks_give_the_same_hits(compiled, monkeypatch):
    """Leaves intersected a block of 8 at a time (LEAF_ROWS bounds what is held) and all at once, against one
    by one: the boolean's hits are the same."""
    boolean = compiled.objects[int(batches.batches_of(compiled.objects, compiled.table)[1][-1])]
    rng = np.random.default_rng(4)
    origins = rng.uniform(-4, 4, (500, 3)) + np.array([0, 3, 6])
    directions = rng.uniform(-0.5, 0.5, (500, 3)) + np.array([0, 0.6, 2.2]) - origins  # (at the boolean)
    whole = boolean.intersect(origins, directions)
    monkeypatch.setattr(batches, "LEAF_ROWS", 8 * 500)
    blocks = batches.LeafHits(list(boolean.leaves()), origins, directions)
    assert len({id(block) for block in blocks.waiting.values()}) == 4  # (25 leaves: 8 + 8 + 8 + 1)
    in_blocks = boolean.intersect(origins, directions)
    monkeypatch.setattr(batches, "BATCH_MIN", 10 ** 9)
    alone = boolean.intersect(origins, directions)
    assert np.isfinite(whole.t).sum() > 100
    for name in ("t", "normal", "entering", "shape", "part", "error", "offset"):
        np.testing.assert_array_equal(getattr(whole, name), getattr(alone, name), err_msg=name)
        np.testing.assert_array_equal(getattr(in_blocks, name), getattr(alone, name), err_msg=name)


def test_the_image_is_the_same(compiled, monkeypatch):
    options = dict(backend="numpy", samples=2, seed=3)
    together = render(compiled, 48, 36, **options).image
    _one_by_one(monkeypatch, compiled)
    np.testing.assert_array_equal(together, render(compiled, 48, 36, **options).image)
