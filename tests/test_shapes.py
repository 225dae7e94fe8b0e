"""The shape registry (tracer/shapes.py) is complete and what its readers derive from it agrees with it."""
from __future__ import annotations

import re

import numpy as np
import pytest

from tracer import compile as compile_module, model, savings, shapes
from tracer.native import contract


@pytest.mark.parametrize("entry", shapes.REGISTRY, ids=lambda e: e.keyword)
def test_every_named_function_exists(entry):
    for field in ("intersect", "uv", "tessellate", "bounds"):
        if getattr(entry, field) is not None:
            assert callable(entry.function(field)), f"{entry.keyword}.{field}"
    header = contract.HEADER.read_text()
    sources = "".join(p.read_text() for p in contract.HEADER.parent.glob("*.h"))
    for name in (entry.c_intersect, entry.c_uv):  # the C core defines what the generated dispatch calls
        assert re.search(rf"static \w+ {name}\(", sources), name
    assert f"K_{entry.c_kind}, {entry.c_uv})" in header
    if entry.family != "mesh":  # (meshes: the BVH traversal, mesh_all)
        assert f"K_{entry.c_kind}, {entry.c_intersect}(o, d, " in header


def test_every_kind_is_dispatched_by_the_registry_on_both_sides():
    # Every keyword names its intersection and mapping, in NumPy and in C: no kind is left to a hand-written
    # branch, and a kind without its C side would find no hits there rather than refuse the scene.
    for entry in shapes.REGISTRY:
        for field in ("intersect", "c_intersect", "uv", "c_uv"):
            assert getattr(entry, field) is not None, (entry.keyword, field)
        if entry.family == "analytic" and entry.bounded:  # (polyhedra and meshes are bound by their vertices)
            assert (entry.box is None) != (entry.bounds is None), entry.keyword


def test_a_kind_takes_its_parameters_in_sdl_order_with_their_defaults():
    tapered = shapes.KINDS["taperedCylinder"]
    assert [p.usage for p in tapered.parameters] == ["s"] and tapered.usage == "s"
    assert model.Shape("taperedCylinder").parameters == tapered.defaults == (1.0,)
    assert model.Shape("taperedCylinder", parameters=[0.5]).parameters == (0.5,)
    with pytest.raises(model.SceneError):
        model.Shape("taperedCylinder", parameters=(0.5, 2.0))
    # cylinder and cone read no number but trace as tapered cylinders of top radius 1 and 0
    assert shapes.KINDS["cylinder"].traced(()) == (1.0,) and shapes.KINDS["cone"].traced(()) == (0.0,)
    assert shapes.MAX_PARAMETERS >= max(len(e.traced(e.defaults)) for e in shapes.REGISTRY)


def test_readers_follow_the_registry():
    assert model.SHAPE_KINDS == tuple(e.keyword for e in shapes.REGISTRY)
    assert set(contract.KIND_CODES) == set(model.SHAPE_KINDS)
    assert savings.CLOSED_KINDS == {e.keyword for e in shapes.REGISTRY if e.closed}
    assert set(compile_module.SOLID_ANALYTIC_KINDS) <= {e.keyword for e in shapes.REGISTRY if e.normals_agree}


@pytest.mark.parametrize("entry", [e for e in shapes.REGISTRY if e.tessellate], ids=lambda e: e.keyword)
def test_tessellations_lie_in_the_generic_bounds(entry):
    for parameters in ((entry.defaults,) + tuple((p.add_value,) for p in entry.parameters[:1])):
        values = entry.traced(parameters)
        mesh = entry.function("tessellate")(*values)
        if entry.box is not None:
            centre, half = np.asarray(entry.box[0]), np.asarray(entry.box[1])
        else:
            rows = np.zeros((1, shapes.MAX_PARAMETERS))
            rows[0, :len(values)] = values
            points = entry.function("bounds")(rows)[0]
            centre, half = 0.5 * (points.max(0) + points.min(0)), 0.5 * (points.max(0) - points.min(0))
        assert np.all(np.abs(mesh.vertices - centre) <= half + 1e-12)
