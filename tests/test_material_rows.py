"""MaterialRows: materials kept as rows of numbers (what the C reader hands over), read as Materials."""
import pickle

import numpy as np
import pytest

from tracer.compile import MaterialTable, compile_scene
from tracer.model import Material, MaterialRows, ShapeTable
from tracer.render import render
from tracer.sdl import fastread, parser

MATERIALS = [
    Material(),
    Material(ambient=(0.2, 0.1, 0.0), diffuse=(0.25, 0.5, 0.75), specular=(1.0, 0.9, 0.8),
             emissive=(0.0, 0.05, 0.0), specular_exponent=30.0, reflectivity=0.4, transparency=0.3,
             speed_of_light=0.7, specular_fraction=0.2, surface_roughness=0.35),
    Material(texture=-2, parameters=(1.0, 2.5, -3.0)),
    Material(texture=3, parameters=tuple(float(k) for k in range(10))),
    Material(diffuse=(-0.0, 0.0, 1e-300)),
]


def rows_of(materials):
    return MaterialRows(np.stack([MaterialRows.row_of(m) for m in materials]))


def test_each_row_reads_as_its_material_once_made():
    rows = rows_of(MATERIALS)
    assert len(rows) == len(MATERIALS)
    assert list(rows) == MATERIALS
    assert rows[-1] == MATERIALS[-1] and rows[1] is rows[1]
    assert rows[1:3] == MATERIALS[1:3]
    assert isinstance(rows[3].texture, int) and rows[3].parameters == MATERIALS[3].parameters
    with pytest.raises(IndexError):
        rows[len(MATERIALS)]


def test_the_columns_give_the_material_table_of_the_materials():
    from_rows, from_list = MaterialTable(rows_of(MATERIALS)), MaterialTable(list(MATERIALS))
    for name in ("ambient", "diffuse", "specular", "emissive", "specular_exponent", "specular_fraction",
                 "surface_roughness", "reflectivity", "transparency", "speed_of_light", "texture"):
        got, want = getattr(from_rows, name), getattr(from_list, name)
        assert got.dtype == want.dtype and np.array_equal(got, want), name


def test_rows_pickle_as_their_array():
    rows = rows_of(MATERIALS)
    again = pickle.loads(pickle.dumps(rows))
    assert again == rows and list(again) == MATERIALS
    assert len(pickle.dumps(rows)) < 400 * len(MATERIALS)


def big_text(count: int) -> str:
    """``count`` spheres, each of its own colour (as bench/run.py's sphere scenes)."""
    lines = ["light 4 6 8 1 1 1", "camera 0 0 12 0 0 0 0 1 0 40"]
    for k in range(count):
        lines.append(f"diffuse {k / count:.6f} 0.5 {1 - k / count:.6f} push translate {k % 10 - 5} "
                     f"{k // 10 % 10 - 5} {-(k // 100)} scale 0.3 0.3 0.3 sphere pop")
    return "\n".join(lines) + "\n"


@pytest.mark.skipif(not fastread.available(), reason="the C core is not built")
def test_a_scene_of_its_own_colours_compiles_and_renders_without_making_its_materials():
    text = big_text(3000)
    fast = parser.parse_sdl(text, fast=True)
    assert isinstance(fast.objects, ShapeTable)
    rows = fast.objects.columns.materials
    assert isinstance(rows, MaterialRows) and len(rows) == 3000
    image = render(compile_scene(fast), 48, 36, backend="c").image
    assert not rows._made  # no Material object was made for compiling or tracing
    python = parser.parse_sdl(text, fast=False)
    assert np.array_equal(image, render(compile_scene(python), 48, 36, backend="c").image)
