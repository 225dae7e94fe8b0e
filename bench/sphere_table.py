"""The scene of bench/run.py's ``sphere_scene(count)`` made directly as a ShapeTable with NumPy: the same
shapes, matrices, materials and places that reading the SDL text gives, without writing or reading it (for
benchmarks of what comes after reading: compile, flatten, the object hierarchy).

    from sphere_table import sphere_table_scene
    scene = sphere_table_scene(1_000_000)          # a Scene whose objects are a ShapeTable
"""
from __future__ import annotations

import numpy as np

#: The lines before the spheres (as in sphere_scene), and the state the spheres are read in.
_HEADER = """! written by bench/run.py
camera 0 28 52  0 2 0  0 1 0  40
light 30 60 40  1 1 1
light -40 30 30  0.4 0.4 0.4
background 0.1 0.1 0.15
globalAmbient 0.2 0.2 0.2
push diffuse 0.5 0.5 0.5 specular 0 0 0 rotate -90 1 0 0 plane pop
specular 0.4 0.4 0.4 specularExponent 30
"""
#: Where the first sphere's keyword stands on its line (``diffuse r g b push translate x y z scale ...``
#: with three decimals for colours and four for places and sizes): its column depends on the widths.
_FIRST_LINE = 9


def _decimal(values: np.ndarray, places: int) -> np.ndarray:
    """The values as the SDL text writes them and reading gives them back (f"{v:.{places}f}")."""
    return np.array([float(f"{v:.{places}f}") for v in values.tolist()]) if len(values) else values


def sphere_table_scene(count: int, seed: int = 1):
    """sphere_scene(count, seed) read, made without the text (a material per sphere, as the reader's
    ``diffuse`` statements make them, kept as rows as the C reader keeps them)."""
    from dataclasses import replace

    from tracer.model import MaterialRows, ShapeTable
    from tracer.sdl.parser import parse_sdl

    rng = np.random.default_rng(seed)
    size = 2.2 * (1000.0 / max(count, 1000)) ** (1.0 / 3.0)
    # sphere_scene draws, per sphere: x and z, y, r, then the colour: 7 uniform numbers in a row
    u = rng.random((count, 7))
    x, z = _decimal(-18 + 36 * u[:, 0], 4), _decimal(-18 + 36 * u[:, 1], 4)
    y = _decimal(0.5 + 7.5 * u[:, 2], 4)
    r = _decimal(size * (0.25 + 0.35 * u[:, 3]), 4)
    colours = _decimal((0.2 + 0.8 * u[:, 4:]).reshape(-1), 3).reshape(-1, 3)
    head = parse_sdl(_HEADER + "sphere\n", file=None)
    plane, probe = head.objects
    first = ShapeTable.of_shapes([plane]).columns
    kinds = np.concatenate([first.kinds, np.full(count, ShapeTable.of_shapes([probe]).columns.kinds[0])])
    affines = np.zeros((count + 1, 3, 4))
    affines[0] = plane.matrix[:3]
    affines[1:, 0, 0] = affines[1:, 1, 1] = affines[1:, 2, 2] = r
    affines[1:, 0, 3], affines[1:, 1, 3], affines[1:, 2, 3] = x, y, z
    # (as rows, as the C reader hands them over: a row per material, the plane's then one per sphere)
    rows = np.repeat(MaterialRows.row_of(probe.material)[None], count + 1, axis=0)
    rows[0] = MaterialRows.row_of(plane.material)
    start, width = MaterialRows.SLOTS["diffuse"]
    rows[1:, start:start + width] = colours
    materials = MaterialRows(rows)
    # the columns of each sphere's keyword: after "diffuse r g b push translate x y z scale r r r "
    widths = sum(np.char.str_len(np.char.mod("%.4f", v)) for v in (x, y, z)) + 3 * np.char.str_len(
        np.char.mod("%.4f", r)) + np.char.str_len(np.char.mod("%.3f", colours)).sum(axis=1)
    fixed = len("diffuse " + "  " + " push translate " + "  " + " scale " + "  " + " ")
    columns = np.concatenate([[first.columns[0]], widths + fixed + 1])
    lines = np.concatenate([[first.lines[0]], np.arange(_FIRST_LINE, _FIRST_LINE + count)])
    table = ShapeTable(kinds, affines.reshape(-1, 12), np.arange(count + 1, dtype=np.int32), materials,
                       np.ones(count + 1), lines, columns)
    return replace(head, objects=table)
