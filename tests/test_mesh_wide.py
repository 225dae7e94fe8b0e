"""The C core's four-wide mesh walk (tracer/native/mesh_wide.h) finds exactly what its binary walk finds.

Each mesh is traced four ways, each made by the environment switch read when a scene is handed to the core:
the binary tree (SDL_TRACER_MESH_BVH=binary, the walk the NumPy reference's tests pin down), the wide tree
with the box test the CPU allows (the default: AVX2 where the CPU has it, else SSE2 on x86-64), the wide tree
with SSE2 box tests (SDL_TRACER_SIMD=sse2, the path of a CPU without AVX2), and the wide tree with its scalar
box tests (SDL_TRACER_SIMD=0, the path of builds without SSE2).  First hits (time, normal, shape, object, entering), shadow feelers and
whole-line hit lists (time, normal, part, barycentrics, error bound) must be equal bit for bit, on rays in
general position, rays along the axes and through edges and vertices, rays with zero direction components,
and rays that start inside the mesh's boxes; and so must rendered images of the bundled scenes with meshes.
"""
from __future__ import annotations

import numpy as np
import pytest

import tracer
from helpers import scene_of
from tracer import native
from tracer.compile import compile_scene
from tracer.meshio import read_3vn
from tracer.model import Material, MeshData, Shape
from tracer.render import render
from test_native import PAWN, ROOT, _cube_quads, _rays_at

pytestmark = pytest.mark.skipif(native.load_error is not None, reason=f"C core not available: {native.load_error}")

MODES = {"binary": {"SDL_TRACER_MESH_BVH": "binary"}, "best": {}, "sse2": {"SDL_TRACER_SIMD": "sse2"},
         "scalar": {"SDL_TRACER_SIMD": "0"}}
WIDE = ("best", "sse2", "scalar")


def _cpu_has_avx2():
    """What the default box test should be on this machine (Linux's /proc/cpuinfo; elsewhere not known)."""
    try:
        flags = next(line for line in open("/proc/cpuinfo") if line.startswith("flags")).split()
    except (OSError, StopIteration):
        return None
    return "avx2" in flags


def _torus(triangles: int) -> MeshData:
    import sys
    sys.path.insert(0, str(ROOT / "bench"))
    from big_scenes import torus_arrays

    vertices, normals, faces = torus_arrays(triangles)
    return MeshData(vertices, normals, [(tuple(f), tuple(f)) for f in faces.tolist()], origin="test:torus")


def _one_triangle() -> MeshData:
    v = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    return MeshData(v, np.array([[0.0, 0.0, 1.0]] * 3), [((0, 1, 2), (0, 1, 2))], origin="test:triangle")


def _mesh_shape(mesh: MeshData, matrix=None) -> Shape:
    return Shape("mesh", np.eye(4) if matrix is None else matrix, Material(), mesh=mesh, mesh_file="test")


MESHES = {
    "torus": lambda: _torus(20_000),
    "pawn": lambda: read_3vn(PAWN),
    "cube quads": _cube_quads,
    "one triangle": _one_triangle,
}


def _set_mode(monkeypatch, name: str) -> None:
    for var in ("SDL_TRACER_MESH_BVH", "SDL_TRACER_SIMD"):
        monkeypatch.delenv(var, raising=False)
    for var, value in MODES[name].items():
        monkeypatch.setenv(var, value)


def _tracers(monkeypatch, make_scene):
    """A C tracer per mode of the scene make_scene() makes (each its own scene: the core is made once per
    compiled scene, compile_scene compiles a scene once, and the core reads the switches when it is made)."""
    from tracer.native.tracer import NativeTracer

    made = {}
    for name in MODES:
        _set_mode(monkeypatch, name)
        made[name] = NativeTracer(compile_scene(make_scene()), threads=1)
    return made


def _rays(center, size, seed):
    starts, dirs = _rays_at(center, size, 3000, seed)
    rng = np.random.default_rng(seed)
    # along the axes, on a grid through the mesh's vertices, edges and faces (zero components: the binary walk)
    grid = np.linspace(-1.0, 1.0, 9) * size
    axis_o, axis_d = [], []
    for a in grid:
        for b in grid:
            for k in range(3):
                o = center + np.insert(np.array([a, b]), k, -4.0 * size)
                axis_o += [o, o]
                axis_d += [np.eye(3)[k], np.eye(3)[k] + 0.25 * np.eye(3)[(k + 1) % 3] + 1e-3 * np.eye(3)[(k + 2) % 3]]
    # from inside the boxes, every direction
    inside = center + rng.uniform(-0.5, 0.5, (500, 3)) * size
    inside_d = rng.normal(size=(500, 3))
    origins = np.concatenate([starts, np.array(axis_o), inside])
    directions = np.concatenate([dirs, np.array(axis_d), inside_d])
    return origins, directions


def _assert_equal(a: dict, b: dict, what: str):
    for key in a:
        assert np.array_equal(a[key], b[key], equal_nan=True), f"{what}: {key} differs"


@pytest.mark.parametrize("mesh_kind", list(MESHES))
def test_wide_walks_find_what_the_binary_walk_finds(monkeypatch, mesh_kind):
    mesh = MESHES[mesh_kind]()
    rng = np.random.default_rng(3)
    axis = rng.normal(size=3)
    from tracer.transforms import rotation, scaling, translation
    matrix = translation(0.3, -0.2, 0.1) @ rotation(37.0, *axis) @ scaling(1.2, 0.8, 1.0)
    tracers = _tracers(monkeypatch, lambda: scene_of(_mesh_shape(mesh, matrix)))
    assert tracers["binary"].mesh_wide_nodes(0) == 0
    assert all(tracers[name].mesh_wide_nodes(0) > 0 for name in WIDE)
    origins, directions = _rays(matrix[:3, 3], 1.5, seed=5)
    first = {name: t.first_hits(origins, directions) for name, t in tracers.items()}
    assert np.isfinite(first["binary"]["t"]).mean() > 0.01  # (the rays do meet the mesh)
    blocked = {name: t.occluded(origins, directions, t_max=2.0) for name, t in tracers.items()}
    for name in WIDE:
        _assert_equal(first["binary"], first[name], f"first hits, {name}")
        assert np.array_equal(blocked["binary"], blocked[name]), f"shadow feelers, {name}"
    for o, d in zip(origins[::10], directions[::10]):
        reference = tracers["binary"].object_hits(0, o, d)
        for name in WIDE:
            got = tracers[name].object_hits(0, o, d)
            for field in ("t", "normal", "part", "uv", "entering", "error"):
                assert np.array_equal(getattr(reference, field), getattr(got, field)), f"all hits, {name}: {field}"


def _two_triangulations(cells: int, coarse: int = 4) -> MeshData:
    """A square of cells x cells unit cells at z = 0 triangulated twice, the two layers with different vertex
    normals: finely (two triangles a cell) and coarsely (two triangles per block of coarse x coarse cells,
    listed first, so that they win the ties within a leaf).  Every ray from z = 1 meets a triangle of each at
    t = 1 exactly (the arithmetic on these integers is exact), and which the walk reaches first decides the
    normal."""
    side = cells + 1
    x, y = np.meshgrid(np.arange(side, dtype=float), np.arange(side, dtype=float), indexing="ij")
    vertices = np.stack([x.ravel(), y.ravel(), np.zeros(side * side)], axis=1)
    normals = np.array([[0.0, 0.0, 1.0], [0.3, -0.2, 1.0]])
    faces = []
    for step, normal in ((coarse, 1), (1, 0)):
        for i in range(0, cells, step):
            for j in range(0, cells, step):
                a, b = i * side + j, (i + step) * side + j
                c, d = (i + step) * side + j + step, i * side + j + step
                faces += [((a, b, c), (normal,) * 3), ((a, c, d), (normal,) * 3)]
    return MeshData(vertices, normals, faces, origin="test:two triangulations")


def test_ties_go_to_the_triangle_the_binary_walk_reaches_first(monkeypatch):
    cells = 24
    tracers = _tracers(monkeypatch, lambda: scene_of(_mesh_shape(_two_triangulations(cells))))
    rng = np.random.default_rng(8)
    n = 20_000
    origins = np.column_stack([rng.uniform(0.0, cells, (n, 2)), np.ones(n)])
    directions = np.column_stack([rng.uniform(-2.0, 2.0, (n, 2)), -np.ones(n)])
    first = {name: t.first_hits(origins, directions) for name, t in tracers.items()}
    hit = np.isfinite(first["binary"]["t"])
    assert hit.mean() > 0.5 and np.all(first["binary"]["t"][hit] == 1.0)
    # (both layers win somewhere: the order decides)
    tilted = first["binary"]["normal"][hit, 0] != 0.0
    assert 0.05 < tilted.mean() < 0.95
    for name in WIDE:
        _assert_equal(first["binary"], first[name], f"first hits, {name}")
    # whole-line hits keep the first of coincident crossings in the binary walk's (left first) order
    for o, d in zip(origins[:400], directions[:400]):
        reference = tracers["binary"].object_hits(0, o, d)
        for name in WIDE:
            got = tracers[name].object_hits(0, o, d)
            for field in ("t", "normal", "part", "uv"):
                assert np.array_equal(getattr(reference, field), getattr(got, field)), f"all hits, {name}: {field}"


def test_a_large_mesh_is_walked_four_wide_in_fewer_nodes(monkeypatch):
    """The wide tree collapses the binary one: each wide node stands for a binary inner node and, where
    there is room, for up to two more below it (none where both children are leaves): on a mesh about two
    binary inner nodes a wide node (0.46 to 0.51 of them from 2,000 to 10^6 triangles)."""
    from tracer.native.tracer import NativeTracer

    compiled = compile_scene(scene_of(_mesh_shape(_torus(20_000))))
    mesh = next(p.triangle_mesh for p in compiled.primitives if p.triangle_mesh is not None)
    inner = int((mesh.nodes["count"] == 0).sum())
    _set_mode(monkeypatch, "sse2")
    wide = NativeTracer(compiled, threads=1).mesh_wide_nodes(0)
    assert inner / 3 <= wide < 0.6 * inner


@pytest.mark.parametrize("scene_file", ["polyhedra.sdl", "shapes.sdl"])
def test_bundled_scenes_with_meshes_render_the_same_images(monkeypatch, scene_file):
    images = {}
    for name in MODES:
        _set_mode(monkeypatch, name)
        scene = tracer.load(ROOT / "scenes" / scene_file)
        images[name] = render(compile_scene(scene), 160, 120, backend="c", threads=1).image
    for name in WIDE:
        assert np.array_equal(images["binary"], images[name]), name


def test_the_box_test_is_the_best_the_cpu_has_unless_the_environment_says_otherwise(monkeypatch):
    """AVX2 is chosen at run time where the CPU has it (this is what makes "best" above the AVX2 walk on such a
    machine), SSE2 otherwise; SDL_TRACER_SIMD=sse2 and =0 force the others, whatever the CPU."""
    import platform

    tracers = _tracers(monkeypatch, lambda: scene_of(_mesh_shape(_one_triangle())))
    if platform.machine().lower() not in ("x86_64", "amd64", "i386", "i686"):  # (no SSE2: scalar box tests)
        assert [tracers[name].mesh_box_test() for name in MODES] == ["binary", "scalar", "scalar", "scalar"]
        return
    expected = {"binary": "binary", "sse2": "sse2", "scalar": "scalar"}
    assert {name: tracers[name].mesh_box_test() for name in expected} == expected
    has_avx2 = _cpu_has_avx2()
    if has_avx2 is None:
        assert tracers["best"].mesh_box_test() in ("avx2", "sse2")
    else:
        assert tracers["best"].mesh_box_test() == ("avx2" if has_avx2 else "sse2")
