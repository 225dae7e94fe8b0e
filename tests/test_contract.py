"""The contract between the NumPy reference and the C core (tracer/native/contract.py).

* contract.h is what the generator writes now (a stale header fails here, whatever changed: a code, a
  constant's value in its NumPy module, a SceneDesc field);
* the C compiler lays out every SceneDesc field at the offset and with the size ctypes gives it (two fields
  swapped by hand in the header, or a type changed on one side, fail here);
* the codes and constants in the table are the NumPy modules' (ray kinds, effects, shape kinds).
"""
from __future__ import annotations

import ctypes

import numpy as np
import pytest

from tracer import model, native, numerics
from tracer.native import contract
from tracer.trace import RAY_KINDS

requires_core = pytest.mark.skipif(native.load_error is not None,
                                   reason=f"C core not available: {native.load_error}")


def test_generated_header_is_current():
    assert contract.stale_reason() is None


def test_a_changed_table_makes_the_header_stale(tmp_path, monkeypatch):
    header = tmp_path / "contract.h"
    header.write_text(contract.header_text())
    assert contract.stale_reason(header) is None
    swapped = list(contract.SCENE_DESC)
    swapped[1], swapped[2] = swapped[2], swapped[1]
    monkeypatch.setattr(contract, "SCENE_DESC", tuple(swapped))
    assert "stale" in contract.stale_reason(header)


def test_the_header_carries_the_numpy_constants():
    text = contract.header_text()
    from tracer.textures.solid import SOLID_DEFAULTS
    from tracer.trace import MEDIA_DEPTH
    assert f"#define TORUS_TUBE {model.TORUS_TUBE_RADIUS!r}\n" in text
    # Tolerances are the compiled scene's (tracer.numerics.Tolerances), fields of SceneDesc, not constants.
    assert "TOLERANCE" not in text.split("typedef struct")[0]
    tolerance_fields = {f"tol_{name}" for name in numerics.Tolerances.__dataclass_fields__}
    assert tolerance_fields <= {f.name for f in contract.SCENE_DESC}
    assert f"#define MEDIA_DEPTH {MEDIA_DEPTH}\n" in text
    assert f"#define TEX_PARAMS {max(len(d) for d in SOLID_DEFAULTS.values())}\n" in text


def test_codes_cover_the_model_and_the_ray_counters():
    assert set(contract.KIND_CODES) == set(model.SHAPE_KINDS)
    assert contract.RAY_KINDS == RAY_KINDS
    assert sorted(contract.EFFECT_BITS.values()) == [1 << k for k in range(len(contract.EFFECTS))]


@requires_core
def test_every_field_has_the_same_offset_and_size_in_c_and_ctypes():
    c = native.c_layout(native._lib)
    py = native.ctypes_layout()
    assert len(c) == len(contract.SCENE_DESC)
    mismatched = [f.name for f, a, b in zip(contract.SCENE_DESC, c, py) if a != b]
    assert mismatched == []
    assert native.layout_mismatch(native._lib) is None


@requires_core
def test_a_swapped_ctypes_mirror_is_caught(monkeypatch):
    # Two pointer fields of one type swapped on the Python side: same total size, different offsets.
    fields = contract.ctypes_fields()
    fields[1], fields[2] = fields[2], fields[1]

    class Swapped(ctypes.Structure):
        _fields_ = fields

    monkeypatch.setattr(contract, "SceneDesc", Swapped)
    assert ctypes.sizeof(Swapped) == native._lib.rt_desc_size()
    reason = native.layout_mismatch(native._lib)
    assert reason is not None and "offset" in reason


@requires_core
def test_a_library_from_another_contract_is_refused(monkeypatch):
    monkeypatch.setattr(contract, "digest", lambda: "0000000000000000")
    assert "another contract" in native.layout_mismatch(native._lib)


def test_ctypes_fields_follow_the_table():
    names = [name for name, _ in contract.SceneDesc._fields_]
    assert names == [f.name for f in contract.SCENE_DESC]
    for f in contract.SCENE_DESC:
        if f.is_pointer:
            assert np.dtype(f.dtype).itemsize == ctypes.sizeof(f.ctype._type_) or f.type.startswith("**")
