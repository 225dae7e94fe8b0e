"""The contract between the NumPy reference and the C core (tracer/native/contract.py).

* contract.h is what the generator writes now (a stale header fails here, whatever changed: a code, a
  constant's value in its NumPy module, a SceneDesc field);
* the C compiler lays out every field of every struct that crosses the boundary (SceneDesc, SdlResult) at the
  offset and with the size ctypes gives it (two fields swapped by hand in the header, or a type changed on
  one side, fail here);
* every function the library exports is declared to ctypes from the table, and to the C compiler by the
  generated prototypes (a definition that differs does not compile);
* the codes and constants in the table are the NumPy modules' (ray kinds, effects, shape kinds).
"""
from __future__ import annotations

import ctypes
import dataclasses
import re
from pathlib import Path

import numpy as np
import pytest

from tracer import model, native, numerics
from tracer.native import contract, flatten
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
    scene_desc = dataclasses.replace(contract.STRUCTS[0], fields=tuple(swapped))
    monkeypatch.setattr(contract, "STRUCTS", (scene_desc, *contract.STRUCTS[1:]))
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
@pytest.mark.parametrize("which", range(len(contract.STRUCTS)), ids=lambda k: contract.STRUCTS[k].name)
def test_every_field_has_the_same_offset_and_size_in_c_and_ctypes(which):
    struct = contract.STRUCTS[which]
    c = native.c_layout(native._lib, which)
    py = native.ctypes_layout(which)
    assert len(c) == len(struct.fields)
    mismatched = [f.name for f, a, b in zip(struct.fields, c, py) if a != b]
    assert mismatched == []
    assert native._lib.rt_struct_size(which) == ctypes.sizeof(contract.CTYPES[struct.name])
    assert native.layout_mismatch(native._lib) is None


@requires_core
@pytest.mark.parametrize("which, first", [(0, 1), (1, 0)], ids=["SceneDesc", "SdlResult"])
def test_a_swapped_ctypes_mirror_is_caught(monkeypatch, which, first):
    # Two fields of one size swapped on the Python side: same total size, different offsets.
    struct = contract.STRUCTS[which]
    fields = contract.ctypes_fields(struct.fields)
    fields[first], fields[first + 1] = fields[first + 1], fields[first]
    swapped = type("Swapped", (ctypes.Structure,), {"_fields_": fields})
    monkeypatch.setitem(contract.CTYPES, struct.name, swapped)
    assert ctypes.sizeof(swapped) == native._lib.rt_struct_size(which)
    reason = native.layout_mismatch(native._lib)
    assert reason is not None and "offset" in reason and struct.name in reason


def test_every_exported_function_is_in_the_table_and_nothing_declares_one_by_hand():
    # The C sources' exported (non-static) functions are the table's, whose prototypes contract.h carries.
    sources = "".join(p.read_text() for p in sorted(contract.HEADER.parent.glob("*.[ch]")) if p != contract.HEADER)
    exported = set(re.findall(r"^(?!static)[A-Za-z][\w \*]*?\b(rt_\w+)\(", sources, re.MULTILINE))
    assert exported == {f.name for f in contract.FUNCTIONS}
    header = contract.HEADER.read_text()
    assert all(f.c_prototype() in header for f in contract.FUNCTIONS)
    # ctypes declarations come from the table only: no argtypes or restype written anywhere else.
    root = Path(contract.__file__).resolve().parents[2]
    by_hand = [str(p.relative_to(root)) for folder in ("tracer", "addon") for p in (root / folder).rglob("*.py")
               if p.name != "contract.py" and re.search(r"\.(argtypes|restype)\b", p.read_text())]
    assert by_hand == []


@requires_core
def test_the_library_functions_have_the_tables_types():
    for f in contract.FUNCTIONS:
        function = getattr(native._lib, f.name)
        assert function.restype == f.restype and list(function.argtypes) == f.argtypes, f.name


@requires_core
def test_a_library_from_another_contract_is_refused(monkeypatch):
    monkeypatch.setattr(contract, "digest", lambda: "0000000000000000")
    assert "another contract" in native.layout_mismatch(native._lib)


def test_ctypes_fields_follow_the_table():
    names = [name for name, _ in flatten.SceneDesc._fields_]
    assert flatten.SceneDesc is contract.CTYPES["SceneDesc"]
    assert names == [f.name for f in contract.SCENE_DESC]
    for f in contract.SCENE_DESC:
        if f.is_pointer:
            assert np.dtype(f.dtype).itemsize == ctypes.sizeof(f.ctype._type_) or f.type.startswith("**")
