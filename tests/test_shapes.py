"""The shape registry (tracer/shapes.py) is complete and what its readers derive from it agrees with it."""
from __future__ import annotations

import re

import numpy as np
import pytest

from tracer import compile as compile_module, model, savings, shapes
from tracer.native import contract


@pytest.mark.parametrize("entry", shapes.REGISTRY, ids=lambda e: e.keyword)
def test_every_named_function_exists(entry):
    for field in ("intersect", "uv", "tessellate"):
        if getattr(entry, field) is not None:
            assert callable(entry.function(field)), f"{entry.keyword}.{field}"
    header = contract.HEADER.read_text()
    for name in (entry.c_intersect, entry.c_uv):
        if name is not None:  # the C core defines what the generated dispatch calls
            sources = "".join(p.read_text() for p in contract.HEADER.parent.glob("*.h"))
            assert re.search(rf"static \w+ {name}\(", sources), name
            assert f"K_{entry.c_kind}, {name})" in header


def test_every_registry_dispatched_kind_has_its_c_side():
    # A kind whose NumPy intersection the registry dispatches is traced in C only through c_intersect: without
    # it the C core would find no hits on the shape rather than refuse the scene.
    for entry in shapes.REGISTRY:
        assert (entry.intersect is None) == (entry.c_intersect is None), entry.keyword
        assert (entry.uv is None) == (entry.c_uv is None), entry.keyword


def test_readers_follow_the_registry():
    assert model.SHAPE_KINDS == tuple(e.keyword for e in shapes.REGISTRY)
    assert set(contract.KIND_CODES) == set(model.SHAPE_KINDS)
    assert savings.CLOSED_KINDS == {e.keyword for e in shapes.REGISTRY if e.closed}
    assert set(compile_module.SOLID_ANALYTIC_KINDS) <= {e.keyword for e in shapes.REGISTRY if e.normals_agree}


@pytest.mark.parametrize("entry", [e for e in shapes.REGISTRY if e.tessellate], ids=lambda e: e.keyword)
def test_tessellations_lie_in_the_generic_box(entry):
    mesh = entry.function("tessellate")()
    centre, half = np.asarray(entry.box[0]), np.asarray(entry.box[1])
    assert np.all(np.abs(mesh.vertices - centre) <= half + 1e-12)
