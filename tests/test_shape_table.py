"""ShapeTable: a scene's shapes kept as columns, reading as the list of Shapes the Python reader makes."""
from __future__ import annotations

import copy
import dataclasses
import pickle

import numpy as np
import pytest

from tracer.model import Scene, Shape, ShapeTable, SourceLocation
from tracer.sdl.parser import parse_sdl

#: Shapes of several kinds (a tapered cylinder, a polyhedron, the teapot), materials, names and places.
TEXT = """\
light 5 5 5 1 1 1
diffuse 1 0 0
! name: first ball
translate 1 2 3 sphere
push scale 2 1 1 rotate 30 0 0 1 cube pop
reflectivity 0.6 diffuse 0 1 0
taperedCylinder 0.25
  octahedron
push translate -2 0 0 scale 0.3 0.3 0.3 teapot pop
diffuse 1 0 0 torus
"""


def parsed(text: str = TEXT, file: str = "s.sdl") -> Scene:
    return parse_sdl(text, file=file)


def table_of(text: str = TEXT) -> ShapeTable:
    return ShapeTable.of_shapes(parsed(text).objects)


def test_len_and_columns_without_making_shapes():
    table = table_of()
    assert len(table) == 6
    columns = table.columns
    assert columns is not None and columns.affines.shape == (6, 12) and columns.kinds.dtype == np.int16
    assert len(columns.materials) == 3  # shapes sharing a material object share its row
    assert repr(table) == "<ShapeTable of 6 shapes>"
    assert table.columns is columns  # still nothing made
    with pytest.raises(ValueError):
        columns.affines[0, 0] = 2.0  # the arrays are read-only


def test_reads_as_the_python_readers_list():
    shapes = parsed().objects
    table = table_of()
    assert table == shapes and shapes == table
    assert table.columns is None  # == made the Shapes
    for mine, theirs in zip(table, shapes):
        assert mine.kind == theirs.kind and mine.matrix.tobytes() == theirs.matrix.tobytes()
        assert mine.material == theirs.material and mine.source == theirs.source and mine.name == theirs.name
        assert mine.parameters == theirs.parameters and mine.mesh is theirs.mesh
        assert mine.matrix.flags.owndata  # a matrix of its own, as the reader gives
    assert table[0].name == "first ball" and table[0].source == SourceLocation("s.sdl", 4, 17)
    assert table[3].mesh is not None and table[4].mesh is not None  # octahedron, teapot: built-in meshes
    assert table[2].material is table[3].material  # shared material object, as read
    changed = parse_sdl(TEXT.replace("translate 1 2 3", "translate 1 2 4"), file="s.sdl").objects
    assert table != changed


def test_indexing_negative_and_slices():
    shapes = parsed().objects
    table = table_of()
    assert table[-1] == shapes[-1] and table[2] == shapes[2]
    assert table[1:4] == shapes[1:4] and isinstance(table[1:4], list)
    assert table[::-2] == shapes[::-2]
    with pytest.raises(IndexError):
        table[6]
    with pytest.raises(IndexError):
        table[-7]


def test_iteration_makes_each_shape_once():
    table = table_of()
    first = list(table)
    assert table.columns is None
    assert all(a is b for a, b in zip(first, table)) and table[0] is first[0]
    assert list(reversed(table)) == first[::-1]
    assert first[2] in table and table.index(first[2]) == 2 and table.count(first[2]) == 1


def test_shape_at_makes_one_shape():
    shapes = parsed().objects
    table = table_of()
    assert table.shape_at(2) == shapes[2] and table.shape_at(-1) == shapes[-1]
    assert table.shape_at(0).name == "first ball" and table.shape_at(1).name is None
    assert table.columns is not None  # the others were not made
    with pytest.raises(IndexError):
        table.shape_at(6)
    list(table)
    assert table.shape_at(1) is table[1]  # once made: the list's own element


@pytest.mark.parametrize("change", [
    lambda t: t.append(Shape("sphere")),
    lambda t: t.insert(0, Shape("sphere")),
    lambda t: t.__delitem__(1),
    lambda t: t.__setitem__(2, Shape("sphere")),
    lambda t: t.pop(),
    lambda t: t.extend([Shape("cube")]),
    lambda t: t.reverse(),
    lambda t: t.clear(),
])
def test_changes_make_it_a_plain_list(change):
    table, expected = table_of(), list(parsed().objects)
    change(table)
    change(expected)
    assert table.columns is None
    assert len(table) == len(expected) and table == expected


def test_plus_and_copy_give_lists():
    table, shapes = table_of(), parsed().objects
    extra = [Shape("sphere")]
    assert table + extra == shapes + extra and extra + table == extra + shapes
    assert table.copy() == shapes and table.copy() is not table.copy()


def test_pickle_and_deepcopy_are_the_arrays():
    text = "".join(f"translate {i} 0 0 sphere\n" for i in range(2000))
    table = table_of(text)
    as_list = pickle.dumps(list(parsed(text).objects))
    data = pickle.dumps(table)
    # (N, 12) matrices, kinds, ids, tapers, places: 118 bytes a row, half of what the Shapes pickle to
    assert len(data) < 2000 * 125 and len(data) < 0.6 * len(as_list)
    back = pickle.loads(data)
    assert back.columns is not None and len(back) == 2000 and table.columns is not None
    assert back == table
    copied = copy.deepcopy(table_of(text))
    assert copied.columns is not None and copied == parsed(text).objects
    shallow = copy.copy(table_of(text))
    assert shallow.columns is not None and len(shallow) == 2000


def test_made_table_copies_and_pickles_as_its_list():
    table = table_of()
    table.append(Shape("sphere"))
    back = pickle.loads(pickle.dumps(table))
    assert back.columns is None and back == table
    shallow = copy.copy(table)
    shallow.append(Shape("cube"))
    assert len(shallow) == len(table) + 1  # a list of its own


def test_bad_columns_are_refused():
    ok = dict(kinds=[0], affines=np.eye(4)[:3].reshape(1, 12), material_ids=[0], materials=[parsed().objects[0].material],
              parameters=[1.0], lines=[1], columns=[1])
    ShapeTable(**ok)
    with pytest.raises(ValueError, match="kind"):
        ShapeTable(**(ok | {"kinds": [999]}))
    with pytest.raises(ValueError, match="material"):
        ShapeTable(**(ok | {"material_ids": [1]}))
    with pytest.raises(ValueError, match="affines"):
        ShapeTable(**(ok | {"affines": np.zeros((1, 16))}))
    with pytest.raises(ValueError):
        ShapeTable.of_shapes([dataclasses.replace(parsed().objects[0], groups=("g",))])


def test_scene_with_a_table_compares_and_replaces():
    scene = parsed()
    other = parsed()
    other.objects = table_of()
    assert other == scene
    moved = dataclasses.replace(other, lights=[])
    assert moved.objects is other.objects and moved != scene
    assert scene.shapes() == other.shapes()


def test_sdl_writer_reads_a_table():
    from tracer.sdl.writer import write_sdl

    scene, tabled = parsed(), parsed()
    tabled.objects = table_of()
    assert write_sdl(tabled) == write_sdl(scene)
    back = parse_sdl(write_sdl(tabled))
    assert [s.kind for s in back.objects] == [s.kind for s in scene.objects]


def test_usd_writer_reads_a_table(tmp_path):
    pytest.importorskip("pxr")
    from tracer.usd import save_usd

    scene, tabled = parsed(), parsed()
    tabled.objects = table_of()
    save_usd(scene, tmp_path / "list.usda")
    save_usd(tabled, tmp_path / "table.usda")
    assert (tmp_path / "list.usda").read_text() == (tmp_path / "table.usda").read_text()


def test_cli_info_reads_a_table(monkeypatch, tmp_path, capsys):
    from tracer import cli
    from tracer.sdl import parser

    path = tmp_path / "s.sdl"
    path.write_text(TEXT)
    cli.main(["info", str(path)])
    expected = capsys.readouterr().out
    real_load = parser.load

    def load_as_table(*args, **kwargs):
        scene = real_load(*args, **kwargs)
        scene.objects = ShapeTable.of_shapes(scene.objects)
        return scene

    monkeypatch.setattr(parser, "load", load_as_table)
    cli.main(["info", str(path)])
    assert capsys.readouterr().out == expected


def test_the_table_holds_arrays_nobody_can_change():
    """compile_scene knows a table by its identity: what it holds must never change under it.  It takes the
    arrays over (they and the arrays they are views of become read-only); a writable buffer is copied."""
    c = table_of().columns
    owner = np.array(c.affines).reshape(-1, 3, 4).copy()
    table = ShapeTable(c.kinds, owner.reshape(-1, 12), c.material_ids, c.materials, c.parameters, c.lines,
                       c.columns)
    assert np.shares_memory(table.columns.affines, owner)  # (no copy)
    with pytest.raises(ValueError):
        owner[0, 0, 3] = 5.0
    buffer = bytearray(np.array(c.affines).tobytes())
    table = ShapeTable(c.kinds, np.frombuffer(buffer).reshape(-1, 12), c.material_ids, c.materials,
                       c.parameters, c.lines, c.columns)
    buffer[:8] = np.float64(7.0).tobytes()
    assert np.array_equal(table.columns.affines, c.affines)
