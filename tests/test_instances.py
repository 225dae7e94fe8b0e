"""Instance rows (tracer.instances, compile.InstancedTable): mesh rows of a table of float32 matrices hold no
inverse, rounding or bounds of their own; both backends compute them from the row's affine and box."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tracer import instances, numerics
from tracer.compile import InstancedTable, PrimitiveTable, compile_scene
from tracer.errors import TracerError
from tracer.meshio import read_3vn
from tracer.model import Camera, Light, Material, Scene, TableRows, matrices_of_affines
from tracer.render import render

ROOT = Path(__file__).resolve().parent.parent
PAWN = ROOT / "scenes" / "meshes" / "pawn.3vn"


def _affines(count: int, seed: int, scale=(0.15, 0.5)) -> np.ndarray:
    """float32 (count, 4, 4): turned, scaled and sheared, spread over a few units."""
    rng = np.random.default_rng(seed)
    out = np.zeros((count, 4, 4), dtype=np.float32)
    for k in range(count):
        turn = np.linalg.qr(rng.normal(size=(3, 3)))[0]
        shear = np.eye(3)
        shear[0, 1], shear[2, 0] = rng.uniform(-0.6, 0.6, 2)
        out[k, :3, :3] = turn @ np.diag(rng.uniform(*scale, 3)) @ shear
        out[k, :3, 3] = rng.uniform(-4, 4), rng.uniform(0.3, 1.2), rng.uniform(-4, 2)
        out[k, 3, 3] = 1.0
    return out


def _scene(matrices: np.ndarray, floor: bool = True) -> Scene:
    rows = TableRows()
    if floor:
        rows.add_block(np.diag([6.0, 0.1, 6.0, 1.0]).astype(np.float32)[None],
                       [rows.part("cube", None, Material(diffuse=(0.4, 0.4, 0.5), reflectivity=0.5))])
    pawn = rows.part("mesh", read_3vn(PAWN), Material(diffuse=(0.8, 0.3, 0.2), specular=(0.5, 0.5, 0.5)))
    rows.add_block(matrices, np.full(len(matrices), pawn))
    return Scene(objects=rows.table(), lights=[Light((3, 8, 5), (1, 1, 1))],
                 camera=Camera((0, 4, 10), (0, 0.5, 0), (0, 1, 0), 50))


def test_cofactor_inverses_are_inverses_and_their_rounding_bounds_the_residual():
    affines = _affines(200, 3).reshape(-1, 16)[:, :12]
    inverse = instances.affine_inverses(affines)
    matrices = np.zeros((200, 4, 4))
    matrices[:, :3] = affines.astype(np.float64).reshape(-1, 3, 4)
    matrices[:, 3, 3] = 1.0
    lapack = np.linalg.inv(matrices)
    assert np.allclose(inverse, lapack, rtol=1e-12, atol=1e-12)
    error = instances.affine_inverse_rounding(inverse, affines)
    # (the same measure as the stored rows' numerics.inverse_rounding, summed in another order)
    assert np.allclose(error, numerics.inverse_rounding(inverse, matrices), rtol=0.5, atol=2e-16)
    assert (error > 0).any() and error.max() < 1e-14
    linear, translation = instances.inverse_norms(inverse)
    assert np.array_equal(linear, np.abs(inverse[:, :3, :3]).sum(axis=2).max(axis=1))
    assert np.array_equal(translation, np.abs(inverse[:, :3, 3]).max(axis=1))


def test_spheres_hold_their_boxes():
    boxes = np.array([[-1, -2, -3, 1, 2, 3], [5, 5, 5, 5, 5, 5]], dtype=np.float32)
    spheres = instances.spheres_of_boxes(boxes)
    corners = np.array([[x, y, z] for x in (-1, 1) for y in (-2, 2) for z in (-3, 3)])
    assert np.all(np.linalg.norm(corners - spheres[0, :3], axis=1) <= spheres[0, 3])
    assert spheres[1].tolist() == [5, 5, 5, 0]


def test_mesh_rows_of_float32_tables_are_instance_rows_and_others_stored():
    scene = _scene(_affines(30, 7))
    table = compile_scene(scene).table
    assert isinstance(table, InstancedTable)
    assert table.slot.tolist() == [0] + [-1] * 30  # (the floor cube is stored)
    assert len(table.stored) == 1 and "inverses" not in vars(table)
    # what the NumPy path reads of every row: the instance rows' computed, the stored rows' own
    assert np.array_equal(table.inverses[0], table.stored.inverses[0])
    assert np.allclose(table.inverses[1:], np.linalg.inv(matrices_of_affines(table.affines[1:])), rtol=1e-12,
                       atol=1e-12)
    boxes = table.boxes[1:]
    centers, radii = table.centers[1:], table.radii[1:]
    assert np.all(np.linalg.norm(np.maximum(np.abs(boxes[:, :3] - centers), np.abs(boxes[:, 3:] - centers)),
                                 axis=1) <= radii)
    # a table of float64 matrices stays a PrimitiveTable, as every list of Shapes does
    rows = TableRows()
    rows.add_block(_affines(3, 7).astype(np.float64) / 3.0, np.full(3, rows.part("mesh", read_3vn(PAWN), Material())))
    assert type(compile_scene(Scene(objects=rows.table())).table) is PrimitiveTable


def test_instance_rows_render_as_the_same_shapes_under_lapack_inverses():
    """The cofactor inverse and its rounding change no pixel against the same instances made Shapes."""
    matrices = _affines(25, 11)
    rows_image = render(_scene(matrices), 64, 48, backend="c").image
    shapes = _scene(matrices)
    shapes.objects = list(shapes.objects)  # (Shapes: float64 matrices, inverted by LAPACK)
    assert type(compile_scene(shapes).table) is PrimitiveTable
    shapes_image = render(shapes, 64, 48, backend="c").image
    assert np.abs(rows_image.astype(int) - shapes_image.astype(int)).max() <= 1


@pytest.mark.parametrize("bad, message", [(0.0, "singular"), (np.nan, "not a finite")])
def test_a_bad_instance_matrix_is_refused_naming_its_shape(bad, message):
    matrices = _affines(5, 2)
    matrices[3, :3, :3] = matrices[3, :3, :3] * bad if bad == 0.0 else bad
    with pytest.raises(TracerError, match=message):
        compile_scene(_scene(matrices))


def test_many_instances_hold_no_per_row_inverse_in_the_c_core():
    """What the C core is handed for 2,000 instance rows: a stored row's tables for the floor alone."""
    from tracer.native.tracer import NativeTracer, _flat_scene

    compiled = compile_scene(_scene(_affines(2000, 5)))
    NativeTracer(compiled, threads=1)
    arrays = _flat_scene(compiled).arrays
    assert len(arrays["prim_inverse"]) == 16 and len(arrays["prim_rounding"]) == 4
    assert arrays["prim_slot"].base is compiled.table.slot or arrays["prim_slot"] is compiled.table.slot
    assert np.shares_memory(arrays["object_box"], compiled.table.object_boxes)


@pytest.mark.parametrize("scale", [1e-30, 1e-6, 1.0, 1e6, 1e30])
def test_instance_rows_at_the_extremes_trace_alike_in_both_backends(scale):
    """Instances squashed nearly flat, turned, and the whole scene at scales from 1e-30 to 1e30 (float32's
    range): the C core's per-visit numbers are the NumPy path's, bit for bit (the same image and rays)."""
    matrices = _affines(12, 17, scale=(0.8, 1.6))
    matrices[::3, :3, 1] *= np.float32(1e-5)  # (nearly singular: a condition number of ~10^5)
    matrices[:, :3, :] *= np.float32(scale)
    scene = _scene(matrices, floor=False)
    scene.camera = Camera((0, 4 * scale, 10 * scale), (0, 0.5 * scale, 0), (0, 1, 0), 50)
    scene.lights = [Light((3 * scale, 8 * scale, 5 * scale), (1, 1, 1))]
    table = compile_scene(scene).table
    assert isinstance(table, InstancedTable) and (table.slot < 0).all()
    c = render(scene, 48, 36, backend="c")
    n = render(scene, 48, 36, backend="numpy")
    assert np.array_equal(c.image, n.image) and c.rays.as_dict() == n.rays.as_dict()
    assert c.rays.shadow > 100  # (a shadow ray from each point the camera sees on an instance)


def test_one_row_asked_for_computes_that_row_alone():
    """A query or a pass that makes one primitive (Primitive.of_row) gets the numbers every row would have,
    without the table making and keeping them for all its rows."""
    table = compile_scene(_scene(_affines(50, 9))).table
    one = {i: table.numbers_of(i) for i in (0, 7, 50)}
    many = table.numbers_of(np.array([50, 0, 7]))
    assert "_every_row_arrays" not in vars(table)
    every = {name: getattr(table, name) for name in ("inverses", "rounding_terms", "spheres", "boxes")}
    for name, column in every.items():
        for i in (0, 7, 50):
            assert np.array_equal(one[i][name], column[i]), (name, i)
        assert np.array_equal(many[name], column[[50, 0, 7]]), name


def test_a_singular_float32_matrix_is_refused_as_from_a_shape():
    """Matrices whose third row is 0.5 r0 + 0.25 r1 exactly (float32 rows where that sum needs no rounding): the
    cofactor determinant often rounds to a tiny non-zero number and gives a finite inverse, yet the table
    refuses (by name) exactly the matrices that LAPACK refuses as a Shape's, and accepts the others."""
    rng = np.random.default_rng(0)
    refused = finite_cofactors = 0
    for _ in range(600):
        r0, r1 = rng.uniform(-1, 1, 3).astype(np.float32), rng.uniform(-1, 1, 3).astype(np.float32)
        r2 = 0.5 * r0.astype(np.float64) + 0.25 * r1.astype(np.float64)
        if not np.array_equal(r2.astype(np.float32), r2):
            continue  # (not exactly dependent once in float32)
        matrices = _affines(3, 8)
        matrices[1, :3, :3] = [r0, r1, r2]
        shapes = _scene(matrices)
        shapes.objects = list(shapes.objects)
        try:
            compile_scene(shapes)
        except TracerError:
            refused += 1
            finite_cofactors += bool(np.isfinite(instances.affine_inverses(matrices[1:2, :3].reshape(1, 12))).all())
            with pytest.raises(TracerError, match="singular"):
                compile_scene(_scene(matrices))
        else:
            compile_scene(_scene(matrices))
    assert refused >= 20 and finite_cofactors >= 10


def test_a_textured_instance_scene_compiles_without_making_a_primitive_per_row():
    rows = TableRows()
    checks = Material(diffuse=(0.8, 0.8, 0.8), texture=-1, parameters=(2.0,))
    rows.add_block(_affines(300, 1), np.full(300, rows.part("mesh", read_3vn(PAWN), checks)))
    compiled = compile_scene(Scene(objects=rows.table(), lights=[Light((3, 8, 5), (1, 1, 1))]))
    assert "textures" in compiled.effects and isinstance(compiled.table, InstancedTable)
    assert not compiled.primitives._made and "_every_row_arrays" not in vars(compiled.table)


def test_a_whole_numpy_trace_computes_every_row_once():
    """A few primitives asked for are computed alone; past _ROWS_ALONE the table computes all rows at once."""
    from tracer.compile import _ROWS_ALONE

    compiled = compile_scene(_scene(_affines(_ROWS_ALONE + 20, 6)))
    for i in range(_ROWS_ALONE):
        compiled.primitives[i]
    assert "_every_row_arrays" not in vars(compiled.table)
    render(compiled, 16, 12, backend="numpy")
    assert "_every_row_arrays" in vars(compiled.table)
