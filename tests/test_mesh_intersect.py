"""Tests of tracer.intersect.mesh: the BVH mesh intersector against a plain-loop reference.

The meshes are built here: a brute-force convex hull of random points (closed, convex, triangles in
general position), an icosphere, a cube of quads (fan triangulation gives shared diagonals), a square
ring and an L-shaped prism (non-convex, closed).
"""
from __future__ import annotations

import itertools
import math
from functools import lru_cache

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tracer.intersect import mesh as mesh_module
from tracer.intersect.mesh import TriangleMesh
from tracer.model import FaceList, MeshData

# ----------------------------------------------------------------------------------------- mesh builders


def convex_hull_mesh(points: np.ndarray, with_normals: bool = False) -> MeshData:
    """The hull of points in general position, by brute force: a triple of points is a face when every
    other point lies strictly on one side of its plane.  Faces are wound counter-clockwise seen from
    outside.  With ``with_normals`` each vertex gets its direction from the centroid as its normal."""
    centre = points.mean(axis=0)
    faces = []
    for i, j, k in itertools.combinations(range(len(points)), 3):
        normal = np.cross(points[j] - points[i], points[k] - points[i])
        side = (points - points[i]) @ normal
        side[[i, j, k]] = 0.0
        if (side <= 0).all() or (side >= 0).all():
            if (centre - points[i]) @ normal > 0:  # wind so the normal points away from the centre
                j, k = k, j
            faces.append(((i, j, k), (i, j, k) if with_normals else ()))
    normals = points - centre if with_normals else np.zeros((0, 3))
    return MeshData(points.copy(), normals, faces, origin="test:hull")


@lru_cache(maxsize=None)
def random_hull(seed: int, with_normals: bool = False) -> MeshData:
    rng = np.random.default_rng(seed)
    directions = rng.normal(size=(14, 3))
    points = directions / np.linalg.norm(directions, axis=1, keepdims=True) * rng.uniform(0.6, 1.2, (14, 1))
    return convex_hull_mesh(points + rng.uniform(-0.2, 0.2, 3), with_normals)


def icosphere(subdivisions: int, with_normals: bool = True) -> MeshData:
    """A unit icosphere with shared vertices (every edge is shared by exactly two triangles)."""
    phi = (1 + 5 ** 0.5) / 2
    vertices = [(-1, phi, 0), (1, phi, 0), (-1, -phi, 0), (1, -phi, 0), (0, -1, phi), (0, 1, phi),
                (0, -1, -phi), (0, 1, -phi), (phi, 0, -1), (phi, 0, 1), (-phi, 0, -1), (-phi, 0, 1)]
    vertices = [tuple(np.array(v) / np.linalg.norm(v)) for v in vertices]
    faces = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
             (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5),
             (2, 4, 11), (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    for _ in range(subdivisions):
        midpoint: dict[tuple[int, int], int] = {}

        def middle(a: int, b: int) -> int:
            key = (min(a, b), max(a, b))
            if key not in midpoint:
                m = (np.array(vertices[a]) + np.array(vertices[b])) / 2
                vertices.append(tuple(m / np.linalg.norm(m)))
                midpoint[key] = len(vertices) - 1
            return midpoint[key]

        new_faces = []
        for a, b, c in faces:
            ab, bc, ca = middle(a, b), middle(b, c), middle(c, a)
            new_faces += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        faces = new_faces
    v = np.array(vertices, dtype=np.float64)
    return MeshData(v, v.copy() if with_normals else np.zeros((0, 3)),
                    [(f, f if with_normals else ()) for f in faces], origin="test:icosphere")


def cube_mesh(reverse_winding: bool = False, with_normals: bool = True) -> MeshData:
    """The generic cube [-1, 1]^3 as six quads with one normal per face (fan: two triangles each)."""
    v = np.array([[x, y, z] for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], dtype=np.float64)
    quads = [((0, 1, 3, 2), 0), ((4, 6, 7, 5), 1), ((0, 4, 5, 1), 2), ((2, 3, 7, 6), 3),
             ((0, 2, 6, 4), 4), ((1, 5, 7, 3), 5)]  # -x, +x, -y, +y, -z, +z, counter-clockwise outside
    normals = np.array([[-1, 0, 0], [1, 0, 0], [0, -1, 0], [0, 1, 0], [0, 0, -1], [0, 0, 1]], dtype=np.float64)
    faces = []
    for quad, n in quads:
        quad = quad[::-1] if reverse_winding else quad
        faces.append((quad, (n,) * 4 if with_normals else ()))
    return MeshData(v, normals if with_normals else np.zeros((0, 3)), faces, origin="test:cube")


def prism_mesh(outline: list[tuple[float, float]], z0: float = -0.5, z1: float = 0.5,
               holes_outline: list[tuple[float, float]] | None = None) -> MeshData:
    """A polygon (counter-clockwise, star-shaped from its first vertex) extruded from z0 to z1."""
    n = len(outline)
    v = np.array([(x, y, z0) for x, y in outline] + [(x, y, z1) for x, y in outline], dtype=np.float64)
    faces = [(tuple(range(n))[::-1], ()), (tuple(range(n, 2 * n)), ())]  # bottom (seen from below), top
    for i in range(n):
        j = (i + 1) % n
        faces.append(((i, j, n + j, n + i), ()))
    return MeshData(v, np.zeros((0, 3)), faces, origin="test:prism")


def ring_mesh(segments: int = 24, inner: float = 1.0, outer: float = 2.0, half_height: float = 0.5) -> MeshData:
    """A square-section ring around the z axis (an annulus extruded), made of quads."""
    angles = 2 * math.pi * np.arange(segments) / segments
    vertices = []
    for radius in (inner, outer):
        for z in (-half_height, half_height):
            vertices += [(radius * math.cos(a), radius * math.sin(a), z) for a in angles]
    index = lambda ring, top, k: (2 * ring + top) * segments + k % segments  # noqa: E731
    faces = []
    for k in range(segments):
        faces.append(((index(1, 0, k), index(1, 0, k + 1), index(1, 1, k + 1), index(1, 1, k)), ()))  # outer
        faces.append(((index(0, 0, k), index(0, 1, k), index(0, 1, k + 1), index(0, 0, k + 1)), ()))  # inner
        faces.append(((index(0, 1, k), index(1, 1, k), index(1, 1, k + 1), index(0, 1, k + 1)), ()))  # top
        faces.append(((index(0, 0, k), index(0, 0, k + 1), index(1, 0, k + 1), index(1, 0, k)), ()))  # bottom
    return MeshData(np.array(vertices), np.zeros((0, 3)), faces, origin="test:ring")


# The L: the reflex corner (1, 1) first, so the fan triangulation of the caps is valid.
L_OUTLINE = [(1, 1), (1, 2), (0, 2), (0, 0), (2, 0), (2, 1)]

# ----------------------------------------------------------------------------------------- reference


def brute_force_hits(mesh: MeshData, origin, direction) -> list[tuple[float, int, float, float, bool]]:
    """Every (t, triangle, b1, b2, entering) of one whole line, by plain loops over all triangles.

    Textbook Möller–Trumbore without any slack; entering uses the winding normal (the test meshes that
    go through here are wound outward)."""
    tri_v, _ = mesh.triangles()
    o = [float(c) for c in origin]
    d = [float(c) for c in direction]

    def sub(a, b):
        return [a[0] - b[0], a[1] - b[1], a[2] - b[2]]

    def cross(a, b):
        return [a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]]

    def dot(a, b):
        return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]

    hits = []
    for index, (i, j, k) in enumerate(tri_v):
        p0, p1, p2 = (list(map(float, mesh.vertices[m])) for m in (i, j, k))
        e1, e2 = sub(p1, p0), sub(p2, p0)
        pvec = cross(d, e2)
        det = dot(e1, pvec)
        if abs(det) <= 1e-13 * math.sqrt(dot(d, d) * dot(e1, e1) * dot(e2, e2)):
            continue
        s = sub(o, p0)
        b1 = dot(s, pvec) / det
        qvec = cross(s, e1)
        b2 = dot(d, qvec) / det
        if b1 < 0 or b2 < 0 or b1 + b2 > 1:
            continue
        t = dot(e2, qvec) / det
        hits.append((t, index, b1, b2, dot(d, cross(e1, e2)) < 0))
    return sorted(hits)


def rays_from(draws) -> tuple[np.ndarray, np.ndarray]:
    """Rays from points on a sphere of radius 4 towards points in [-1.3, 1.3]^3, with varied speed."""
    origins, directions = [], []
    for theta, phi, target, speed in draws:
        o = 4 * np.array([math.sin(theta) * math.cos(phi), math.sin(theta) * math.sin(phi), math.cos(theta)])
        origins.append(o)
        directions.append((np.array(target) - o) * speed)
    return np.array(origins), np.array(directions)


coordinate = st.floats(-1.3, 1.3)
ray_draw = st.tuples(st.floats(0, math.pi), st.floats(0, 2 * math.pi),
                     st.tuples(coordinate, coordinate, coordinate), st.floats(0.05, 20))
ray_batches = st.lists(ray_draw, min_size=1, max_size=12)
hull_seeds = st.integers(0, 7)


@lru_cache(maxsize=None)
def traced(mesh_key) -> tuple[MeshData, TriangleMesh]:
    """Build each test mesh (and its BVH) once; small leaves so that the trees have some depth."""
    kind, *args = mesh_key
    data = {"hull": random_hull, "icosphere": icosphere}[kind](*args)
    return data, TriangleMesh(data, leaf_size=2)


def close(a, b, t_scale=1.0) -> bool:
    return abs(a - b) <= 1e-9 * (t_scale + abs(a) + abs(b))


# ----------------------------------------------------------------------------------------- BVH layout


@pytest.mark.parametrize("mesh_key", [("hull", 0), ("icosphere", 2), ("icosphere", 3)])
def test_bvh_layout(mesh_key):
    data, mesh = traced(mesh_key)
    tri_v, _ = data.triangles()
    corners = data.vertices[tri_v]
    assert mesh.tri_order.dtype == np.int32 and mesh.nodes.dtype.itemsize == 32
    assert sorted(mesh.tri_order.tolist()) == list(range(len(tri_v)))
    leaves = np.flatnonzero(mesh.node_count > 0)
    inner = np.flatnonzero(mesh.node_count == 0)
    assert mesh.node_count.max() <= 2
    # Leaves' ranges tile tri_order exactly once, and their (single-precision) boxes hold their triangles.
    covered = np.zeros(len(tri_v), dtype=int)
    for leaf in leaves:
        first, count = mesh.node_offset[leaf], mesh.node_count[leaf]
        covered[first:first + count] += 1
        tris = corners[mesh.tri_order[first:first + count]].reshape(-1, 3)
        assert (tris >= mesh.node_lo[leaf]).all() and (tris <= mesh.node_hi[leaf]).all()
        assert mesh.node_axis[leaf] == -1
    assert (covered == 1).all()
    # Inner nodes: children allocated together (offset, offset + 1), nested boxes, every node reachable once.
    for node in inner:
        assert mesh.node_axis[node] in (0, 1, 2)
        for child in (mesh.node_offset[node], mesh.node_offset[node] + 1):
            assert (mesh.node_lo[child] >= mesh.node_lo[node]).all()
            assert (mesh.node_hi[child] <= mesh.node_hi[node]).all()
    children = np.concatenate([mesh.node_offset[inner], mesh.node_offset[inner] + 1])
    assert sorted(children.tolist()) == list(range(1, mesh.node_total))
    # Vertex-indexed: the triangles are the mesh's own indices into its own vertices.
    np.testing.assert_array_equal(mesh.tri_vertex, tri_v)
    assert np.shares_memory(mesh.vertices, data.vertices)


def test_boxes_are_rounded_outward_to_single_precision(monkeypatch):
    """Corners that are not floats still lie inside their leaves' boxes (rounded down and up, not to the
    nearest), with the padding switched off."""
    monkeypatch.setattr(mesh_module, "BOX_PADDING", 0.0)
    data = icosphere(1)
    data.vertices = data.vertices * (1 / 3) + 0.1  # coordinates with no exact single-precision value
    mesh = TriangleMesh(data, leaf_size=1)
    corners = data.vertices[data.triangles()[0]]
    for leaf in np.flatnonzero(mesh.node_count > 0):
        tri = corners[mesh.tri_order[mesh.node_offset[leaf]]]
        assert (tri >= mesh.node_lo[leaf]).all() and (tri <= mesh.node_hi[leaf]).all()
    # ... by one step at most: the root's box is the vertices' box, to float32 precision.
    np.testing.assert_allclose(mesh.node_lo[0], corners.reshape(-1, 3).min(axis=0), rtol=2 ** -23)


def test_a_triangle_mesh_keeps_indices_not_copies():
    """A mesh of triangles whose normal indices are its vertex indices (as bench/big_scenes.py's torus and
    most exporters write them) keeps one index array, the FaceList's own, and under 64 bytes a triangle
    with its BVH."""
    n = 40  # a torus-like grid: n * n vertices, 2 n n triangles
    i, j = np.meshgrid(np.arange(n), np.arange(n), indexing="ij")
    u, v = 2 * np.pi * i / n, 2 * np.pi * j / n
    vertices = np.stack([(2 + np.cos(v)) * np.cos(u), (2 + np.cos(v)) * np.sin(u), np.sin(v)], axis=-1).reshape(-1, 3)
    a = (i * n + j).ravel()
    b = (((i + 1) % n) * n + j).ravel()
    c = (((i + 1) % n) * n + (j + 1) % n).ravel()
    d = (i * n + (j + 1) % n).ravel()
    index = np.stack([np.stack([a, b, c], 1), np.stack([a, c, d], 1)], 1).reshape(-1).astype(np.int32)
    data = MeshData(vertices, vertices.copy(), FaceList(np.full(len(index) // 3, 3), index, index))
    mesh = TriangleMesh(data)
    assert np.shares_memory(mesh.tri_vertex, data.faces.vertex_index) and mesh.tri_normal is mesh.tri_vertex
    assert np.shares_memory(mesh.vertices, data.vertices) and np.shares_memory(mesh.normals, data.normals)
    kept = {x.ctypes.data: x.nbytes for x in mesh.kept_arrays() + data.faces.arrays()}
    assert sum(kept.values()) / mesh.triangle_count < 64


def _tree(mesh: TriangleMesh) -> dict:
    return {"nodes": mesh.nodes, "tri_order": mesh.tri_order}


@pytest.mark.parametrize("shape", ["random", "duplicates", "grid", "icosphere"])
@pytest.mark.parametrize("leaf_size, bins", [(1, 2), (2, 4), (8, 16), (4, 64)])
def test_c_builder_builds_the_numpy_builders_tree(shape, leaf_size, bins):
    """bvh_build.h promises the reference builder's tree, node for node and bit for bit."""
    native = pytest.importorskip("tracer.native")
    if native.load_error is not None:
        pytest.skip(f"no C core: {native.load_error}")
    rng = np.random.default_rng(len(shape) * 100 + bins)
    if shape == "icosphere":
        data = icosphere(3)
    else:
        count = {"random": 700, "duplicates": 40, "grid": 400}[shape]
        points = {"random": lambda: rng.normal(size=(count * 3, 3)),
                  "duplicates": lambda: np.tile(rng.normal(size=(3, 3)), (count, 1)),
                  "grid": lambda: rng.integers(0, 3, size=(count * 3, 3)).astype(float)}[shape]()
        data = MeshData(points, np.zeros((0, 3)), [((3 * i, 3 * i + 1, 3 * i + 2), ()) for i in range(count)])
    in_c = TriangleMesh(data, leaf_size=leaf_size, bins=bins, builder=native.build_mesh_bvh)
    in_numpy = TriangleMesh(data, leaf_size=leaf_size, bins=bins)
    a, b = _tree(in_c), _tree(in_numpy)
    for name in a:
        assert a[name].dtype == b[name].dtype and a[name].tobytes() == b[name].tobytes(), name
    assert in_c.node_count.max() <= leaf_size


def test_the_c_builder_builds_the_same_tree_on_any_number_of_threads():
    """Past BVH_PARALLEL_MIN triangles the C builder builds subtrees on several threads and numbers their
    nodes as one thread would: the tree must not depend on the thread count."""
    native = pytest.importorskip("tracer.native")
    if native.load_error is not None:
        pytest.skip(f"no C core: {native.load_error}")
    rng = np.random.default_rng(7)
    count = 70_000  # above bvh_build.h's BVH_PARALLEL_MIN
    vertices = rng.normal(size=(count // 2, 3))
    tri = rng.integers(0, len(vertices), size=(count, 3)).astype(np.int32)
    trees = [native.build_mesh_bvh(vertices, tri, 8, 16, 1e-9, threads) for threads in (1, 2, 3, 8)]
    for nodes, order in trees[1:]:
        assert nodes.tobytes() == trees[0][0].tobytes() and np.array_equal(order, trees[0][1])
    assert sorted(trees[0][1].tolist()) == list(range(count))


# ----------------------------------------------------------------------------------------- against brute force


@settings(max_examples=60, deadline=None)
@given(hull_seeds, ray_batches, st.floats(-6, 3))
def test_closest_hit_matches_brute_force(seed, draws, t_min):
    data, mesh = traced(("hull", seed))
    origins, directions = rays_from(draws)
    result = mesh.closest_hits(origins, directions, t_min)
    assert result.t.shape == (len(origins), 1)
    for r in range(len(origins)):
        reference = [h for h in brute_force_hits(data, origins[r], directions[r]) if h[0] > t_min]
        if not reference:
            assert result.t[r, 0] == np.inf and result.part[r, 0] == -1
            continue
        t, tri, b1, b2, entering = reference[0]
        assert close(result.t[r, 0], t)
        assert result.entering[r, 0] == entering
        # Another triangle may tie only if the ray passes through an edge; random rays do not.
        assert result.part[r, 0] == tri
        np.testing.assert_allclose(result.uv[r, 0], (b1, b2), atol=1e-9)


@settings(max_examples=60, deadline=None)
@given(hull_seeds, ray_batches)
def test_all_hits_match_brute_force(seed, draws):
    data, mesh = traced(("hull", seed))
    origins, directions = rays_from(draws)
    # Start the rays somewhere along their line: all_hits must not care (whole line).
    origins = origins + directions * np.linspace(-0.5, 1.5, len(origins))[:, None]
    result = mesh.all_hits(origins, directions)
    counts = np.isfinite(result.t).sum(axis=1)
    assert result.t.shape[1] == (counts.max() if len(counts) else 0)
    assert not result.inside_at_start.any()
    for r in range(len(origins)):
        reference = brute_force_hits(data, origins[r], directions[r])
        assert counts[r] == len(reference)
        for slot, (t, tri, b1, b2, entering) in enumerate(reference):
            assert close(result.t[r, slot], t)
            assert result.part[r, slot] == tri
            assert result.entering[r, slot] == entering
        assert (np.diff(result.t[r, :counts[r]]) >= 0).all()


@settings(max_examples=60, deadline=None)
@given(st.sampled_from([("hull", 1), ("hull", 5), ("icosphere", 1), ("icosphere", 3)]), ray_batches)
def test_all_hits_from_outside_come_in_enter_exit_pairs(mesh_key, draws):
    data, mesh = traced(mesh_key)
    origins, directions = rays_from(draws)
    result = mesh.all_hits(origins, directions)
    counts = np.isfinite(result.t).sum(axis=1)
    assert (counts % 2 == 0).all()
    assert (counts <= 2).all()  # convex
    for r, count in enumerate(counts):
        expected = np.arange(count) % 2 == 0  # enter, exit, enter, ...
        np.testing.assert_array_equal(result.entering[r, :count], expected)
        assert (result.part[r, count:] == -1).all() and np.isinf(result.t[r, count:]).all()


@settings(max_examples=40, deadline=None)
@given(st.sampled_from([("hull", 2), ("icosphere", 2)]), ray_batches)
def test_hit_points_lie_on_their_triangles(mesh_key, draws):
    data, mesh = traced(mesh_key)
    tri_v, _ = data.triangles()
    origins, directions = rays_from(draws)
    result = mesh.all_hits(origins, directions)
    rows, slots = np.nonzero(np.isfinite(result.t))
    points = origins[rows] + result.t[rows, slots, None] * directions[rows]
    corners = data.vertices[tri_v[result.part[rows, slots]]]
    winding = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    winding /= np.linalg.norm(winding, axis=1, keepdims=True)
    assert np.all(np.abs(np.einsum("ij,ij->i", points - corners[:, 0], winding)) <= 1e-9)
    b1, b2 = result.uv[rows, slots, 0], result.uv[rows, slots, 1]
    rebuilt = (1 - b1 - b2)[:, None] * corners[:, 0] + b1[:, None] * corners[:, 1] + b2[:, None] * corners[:, 2]
    np.testing.assert_allclose(rebuilt, points, atol=1e-9)
    assert (b1 >= -1e-9).all() and (b2 >= -1e-9).all() and (b1 + b2 <= 1 + 1e-9).all()


@settings(max_examples=60, deadline=None)
@given(st.sampled_from([("hull", 3), ("icosphere", 2)]), ray_batches, st.floats(-8, 8), st.floats(0, 8))
def test_any_hit_agrees_with_closest_hits(mesh_key, draws, t_min, length):
    data, mesh = traced(mesh_key)
    origins, directions = rays_from(draws)
    t_max = t_min + length
    blocked = mesh.any_hit(origins, directions, t_min, t_max)
    first = mesh.closest_hits(origins, directions, t_min, t_max)
    np.testing.assert_array_equal(blocked, np.isfinite(first.t[:, 0]))
    assert ((first.t[:, 0] > t_min) & (first.t[:, 0] < t_max))[blocked].all()


# ----------------------------------------------------------------------------------------- t range


def test_t_min_and_t_max_are_honoured_per_ray():
    mesh = TriangleMesh(cube_mesh())
    origins = np.array([[0.2, 0.3, 5.0]] * 6)
    directions = np.array([[0.0, 0.0, -2.0]] * 6)  # hits z = 1 at t = 2, z = -1 at t = 3
    t_min = np.array([0.0, 2.0, 2.5, 3.0, -10.0, 0.0])
    t_max = np.array([np.inf, np.inf, np.inf, np.inf, 1.0, 2.0])
    first = mesh.closest_hits(origins, directions, t_min, t_max)
    np.testing.assert_allclose(first.t[:, 0], [2.0, 3.0, 3.0, np.inf, np.inf, np.inf])
    np.testing.assert_array_equal(first.entering[:, 0], [True, False, False, False, False, False])
    np.testing.assert_array_equal(first.part[:, 0] >= 0, [True, True, True, False, False, False])
    np.testing.assert_array_equal(mesh.any_hit(origins, directions, t_min, t_max),
                                  [True, True, True, False, False, False])
    # Behind the origin counts for all_hits (whole line), and for closest_hits when t_min allows it.
    behind = mesh.closest_hits(origins, -directions, -np.inf)
    np.testing.assert_allclose(behind.t[:, 0], -3.0)
    np.testing.assert_allclose(mesh.all_hits(origins, -directions).t, [[-3.0, -2.0]] * 6)


def test_scalar_and_default_limits():
    mesh = TriangleMesh(cube_mesh())
    first = mesh.closest_hits(np.array([[0.0, 0.0, 0.0]]), np.array([[0.0, 0.0, 1.0]]))  # from inside
    assert first.t[0, 0] == pytest.approx(1.0) and not first.entering[0, 0]
    np.testing.assert_allclose(first.normal[0, 0], [0, 0, 1])


# ----------------------------------------------------------------------------------------- shared edges, vertices


def test_ray_through_shared_diagonal_is_counted_once():
    """The cube's quads are fanned, so the centre of each face lies on the diagonal of two triangles."""
    mesh = TriangleMesh(cube_mesh())
    origins = np.array([[0.0, 0.0, 5.0], [5.0, 0.0, 0.0], [0.0, -5.0, 0.0], [0.5, 0.5, 5.0], [-0.7, 0.7, 5.0]])
    directions = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0]])
    result = mesh.all_hits(origins, directions)
    assert result.t.shape == (5, 2)
    np.testing.assert_allclose(result.t, [[4.0, 6.0]] * 5)
    np.testing.assert_array_equal(result.entering, [[True, False]] * 5)


def test_ray_through_cube_edges_and_corners():
    mesh = TriangleMesh(cube_mesh())
    origins = np.array([[3.0, 0.2, 3.0],  # through the edge x = z = 1 (two front faces) and x = z = -1
                        [3.0, 3.0, 3.0],  # through the corner (1, 1, 1) and (-1, -1, -1): three faces each
                        [-3.0, 3.0, -3.0]])
    directions = np.array([[-1.0, 0.0, -1.0], [-1.0, -1.0, -1.0], [1.0, -1.0, 1.0]])
    result = mesh.all_hits(origins, directions)
    np.testing.assert_allclose(result.t, [[2.0, 4.0]] * 3)
    np.testing.assert_array_equal(result.entering, [[True, False]] * 3)
    first = mesh.closest_hits(origins, directions)
    np.testing.assert_allclose(first.t[:, 0], 2.0)
    assert first.entering.all()


def test_grazing_a_corner_gives_a_touching_pair():
    """A line that touches the cube only at (1, 1, 1): enter and exit there, entering first."""
    mesh = TriangleMesh(cube_mesh())
    result = mesh.all_hits(np.array([[0.0, 2.0, 1.0]]), np.array([[1.0, -1.0, 0.0]]))
    assert result.t.shape == (1, 2)
    np.testing.assert_allclose(result.t, [[1.0, 1.0]])
    np.testing.assert_array_equal(result.entering, [[True, False]])


def rotation(seed: int) -> np.ndarray:
    q, r = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.diag(r))


@pytest.mark.parametrize("seed", range(12))
def test_grazing_a_rotated_corner(seed):
    """As above on a randomly rotated cube, where the two touching times differ by rounding: still one
    enter then one exit, and the times stay sorted (a later stable sort must not undo the order)."""
    data = cube_mesh()
    turn = rotation(seed)
    data.vertices = data.vertices @ turn.T
    data.normals = data.normals @ turn.T
    mesh = TriangleMesh(data)
    origin = np.array([[0.0, 2.0, 1.0]]) @ turn.T
    direction = np.array([[1.0, -1.0, 0.0]]) @ turn.T
    result = mesh.all_hits(origin, direction)
    assert result.t.shape == (1, 2)
    np.testing.assert_allclose(result.t, [[1.0, 1.0]])
    assert result.t[0, 0] <= result.t[0, 1]
    np.testing.assert_array_equal(result.entering, [[True, False]])
    np.testing.assert_array_equal(result.sorted().entering, [[True, False]])


@pytest.mark.parametrize("subdivisions", [0, 1, 2])
def test_rays_through_every_icosphere_vertex(subdivisions):
    """Rays from outside straight through each vertex (shared by 5 or 6 triangles) and out the opposite one."""
    data = icosphere(subdivisions)
    mesh = TriangleMesh(data, leaf_size=4)
    v = data.vertices
    # Aim through the vertex but not through the centre, so the exit is somewhere general too.
    directions = -(v + 0.3 * np.roll(v, 1, axis=0))
    origins = v - 3 * directions
    result = mesh.all_hits(origins, directions)
    counts = np.isfinite(result.t).sum(axis=1)
    assert (counts == 2).all()
    np.testing.assert_allclose(result.t[:, 0], 3.0)
    np.testing.assert_array_equal(result.entering, [[True, False]] * len(v))
    first = mesh.closest_hits(origins, directions)
    np.testing.assert_allclose(first.t[:, 0], 3.0)


@pytest.mark.parametrize("offset", [0.0, 1e-15, 1e-13, 1e-11, 1e-9, 1e-7])
def test_rays_passing_near_vertices_and_edges(offset):
    """Rays through icosphere vertices and edge midpoints, shifted sideways by tiny amounts: whichever
    triangles the slack lets them hit, each crosses the surface exactly once going in and once out."""
    data = icosphere(2)
    mesh = TriangleMesh(data, leaf_size=4)
    tri_v, _ = data.triangles()
    corners = data.vertices[tri_v]
    targets = np.vstack([data.vertices, (corners[:, 0] + corners[:, 1]) / 2, (corners[:, 1] + corners[:, 2]) / 2])
    rng = np.random.default_rng(int(offset * 1e15) % 1000)
    # Into the solid towards points well inside it, so each line crosses the surface at the target.
    aim = rng.uniform(-0.4, 0.4, size=targets.shape)
    sideways = rng.normal(size=targets.shape)
    sideways /= np.linalg.norm(sideways, axis=1, keepdims=True)
    directions = aim - targets
    origins = targets - 4 * directions + offset * sideways
    result = mesh.all_hits(origins, directions)
    counts = np.isfinite(result.t).sum(axis=1)
    assert (counts == 2).all()
    np.testing.assert_array_equal(result.entering, [[True, False]] * len(targets))
    np.testing.assert_allclose(result.t[:, 0], 4.0, atol=1e-6)
    first = mesh.closest_hits(origins, directions)
    np.testing.assert_allclose(first.t[:, 0], result.t[:, 0])


@pytest.mark.parametrize("cosine", [0.3, 0.1, 0.03])
def test_grazing_rays_near_vertices_and_edges(cosine):
    """Lines meeting the icosphere near its vertices and edge midpoints at grazing angles (cosine to
    the sphere normal): at most one entering and one exiting hit, entering first.  Steep incidence
    spreads the times of a shared vertex's hits far beyond 1e-12 relative.  (Lines passing a convex
    edge from outside within the rounding slack may keep a lone hit, so the count may be 1 here.)"""
    data = icosphere(3)
    mesh = TriangleMesh(data)
    tri_v, _ = data.triangles()
    corners = data.vertices[tri_v]
    targets = np.vstack([data.vertices, (corners[:, 0] + corners[:, 1]) / 2])
    normal = targets / np.linalg.norm(targets, axis=1, keepdims=True)
    for seed in range(3):
        rng = np.random.default_rng(seed)
        tangent = rng.normal(size=targets.shape)
        tangent -= np.einsum("ij,ij->i", tangent, normal)[:, None] * normal
        tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
        directions = math.sqrt(1 - cosine ** 2) * tangent - cosine * normal
        for offset in (0.0, 1e-15, 1e-13):
            origins = targets - 3 * directions + offset * rng.normal(size=targets.shape)
            result = mesh.all_hits(origins, directions)
            assert result.t.shape[1] <= 2
            assert (result.entering.sum(axis=1) <= 1).all()
            two = np.isfinite(result.t).sum(axis=1) == 2
            assert result.entering[two, 0].all() and not result.entering[two, 1].any()
            if cosine == 0.3:
                assert two.all()


def test_rays_along_a_quad_diagonal_grid():
    """A grid of axis-aligned rays, many exactly on triangle edges, all hit the cube exactly twice."""
    mesh = TriangleMesh(cube_mesh())
    xs = np.linspace(-0.75, 0.75, 7)
    x, y = np.meshgrid(xs, xs)
    origins = np.stack([x.ravel(), y.ravel(), np.full(x.size, 3.0)], axis=1)
    directions = np.tile([0.0, 0.0, -1.0], (len(origins), 1))
    result = mesh.all_hits(origins, directions)
    np.testing.assert_allclose(result.t, [[2.0, 4.0]] * len(origins))


# ----------------------------------------------------------------------------------------- parallel rays


def test_rays_parallel_to_a_triangle_miss_without_nan():
    single = MeshData(np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]]), np.zeros((0, 3)),
                      [((0, 1, 2), ())])
    mesh = TriangleMesh(single)
    origins = np.array([[-1.0, 0.2, 0.0], [0.2, 0.2, 0.0], [-1.0, 0.2, 1e-3], [0.1, -1.0, 0.0], [0.3, 0.3, 0.0]])
    directions = np.array([[1.0, 0.0, 0.0], [1.0, 1.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0], [0.0, 0.0, 0.0]])
    with np.errstate(all="raise"):
        result = mesh.all_hits(origins, directions)
        first = mesh.closest_hits(origins, directions, -np.inf)
        blocked = mesh.any_hit(origins, directions, -np.inf, np.inf)
    assert result.t.shape == (5, 0)
    assert np.isinf(first.t).all() and not blocked.any()
    assert not np.isnan(first.normal).any() and not np.isnan(first.uv).any()


def test_ray_lying_in_a_cube_face_plane():
    """Rays inside the plane of a face (parallel to it) and with zero direction components, some with
    origins exactly on the BVH's box planes: the face is not hit, the faces across are, once each."""
    mesh = TriangleMesh(cube_mesh(), leaf_size=2)
    origins = np.array([[3.0, 0.0, 1.0], [1.0, 0.3, 5.0], [1.0, 1.0, 5.0], [-1.0, 0.0, 0.0]])
    directions = np.array([[-1.0, 0.0, 0.0], [0.0, 0.0, -1.0], [0.0, 0.0, -1.0], [0.0, 1.0, 0.0]])
    result = mesh.all_hits(origins, directions)
    np.testing.assert_allclose(result.t, [[2.0, 4.0], [4.0, 6.0], [4.0, 6.0], [-1.0, 1.0]])
    np.testing.assert_array_equal(result.entering, [[True, False]] * 4)
    assert not np.isnan(result.normal).any()


def test_rays_on_box_planes_without_padding(monkeypatch):
    """The boxes are padded, so no ray that can hit anything starts exactly on a box plane; without the
    padding, rays lying in the cube's face planes do, and zero direction components meet 0 * inf = NaN
    in the slab test.  The box is closed, so they must still reach the triangles."""
    monkeypatch.setattr(mesh_module, "BOX_PADDING", 0.0)
    mesh = TriangleMesh(cube_mesh(), leaf_size=2)
    assert mesh.node_hi[0].tolist() == [1.0, 1.0, 1.0]
    origins = np.array([[1.0, 0.3, 5.0], [1.0, 1.0, 5.0], [-1.0, -0.5, -5.0], [0.25, -1.0, 3.0]])
    directions = np.array([[0.0, 0.0, -1.0], [-0.0, 0.0, -1.0], [0.0, -0.0, 2.0], [0.0, 0.0, -1.0]])
    result = mesh.all_hits(origins, directions)
    np.testing.assert_allclose(result.t, [[4.0, 6.0], [4.0, 6.0], [2.0, 3.0], [2.0, 4.0]])
    np.testing.assert_array_equal(result.entering, [[True, False]] * 4)
    np.testing.assert_allclose(mesh.closest_hits(origins, directions).t[:, 0], [4.0, 4.0, 2.0, 2.0])


def test_touching_pairs_in_a_batch_with_an_open_surface():
    """The order of a touching enter/exit pair depends on the ray's own earlier hits only, not on those
    of other rays (an open surface leaves a ray's enter/exit count unbalanced)."""
    data = cube_mesh()
    data.vertices = np.vstack([data.vertices, [[3.0, 3.0, 5.0], [4.0, 3.0, 5.0], [3.0, 4.0, 5.0]]])
    data.faces = data.faces + [((8, 9, 10), ())]  # a lone triangle facing +z, no normals
    mesh = TriangleMesh(data)
    origins = np.array([[3.2, 3.2, 10.0], [0.0, 2.0, 1.0]])
    directions = np.array([[0.0, 0.0, -1.0], [1.0, -1.0, 0.0]])
    result = mesh.all_hits(origins, directions)
    np.testing.assert_allclose(result.t, [[5.0, np.inf], [1.0, 1.0]])
    np.testing.assert_array_equal(result.entering, [[True, False], [True, False]])


# ----------------------------------------------------------------------------------------- non-convex


def test_ring_has_four_hits_along_a_diameter():
    mesh = TriangleMesh(ring_mesh(), leaf_size=4)
    origins = np.array([[-5.0, 0.0, 0.1], [0.0, 5.0, -0.2]])
    directions = np.array([[1.0, 0.0, 0.0], [0.0, -0.5, 0.0]])
    result = mesh.all_hits(origins, directions)
    np.testing.assert_allclose(result.t, [[3.0, 4.0, 6.0, 7.0], [6.0, 8.0, 12.0, 14.0]])
    np.testing.assert_array_equal(result.entering, [[True, False, True, False]] * 2)
    # Outward normals: against the ray when entering, with it when leaving.
    facing = np.einsum("nkj,nj->nk", result.normal, directions)
    assert (np.sign(facing) == [[-1, 1, -1, 1]] * 2).all()
    first = mesh.closest_hits(origins, directions, np.array([3.5, 7.0]))
    np.testing.assert_allclose(first.t[:, 0], [4.0, 8.0])
    # Down the hole: no hits at all.
    assert mesh.all_hits(np.array([[0.0, 0.0, 5.0]]), np.array([[0.0, 0.0, -1.0]])).t.shape == (1, 0)


def test_l_prism_has_four_hits_across_the_notch():
    data = prism_mesh(L_OUTLINE)
    mesh = TriangleMesh(data, leaf_size=2)
    # The line x + y = 2.5 enters the lower arm at x = 2, leaves it at y = 1, crosses the notch, enters
    # the upper arm at x = 1 and leaves at y = 2.
    origin = np.array([[3.0, -0.5, 0.1]])
    direction = np.array([[-1.0, 1.0, 0.0]])
    result = mesh.all_hits(origin, direction)
    np.testing.assert_allclose(result.t, [[1.0, 1.5, 2.0, 2.5]])
    np.testing.assert_array_equal(result.entering, [[True, False, True, False]])
    reference = brute_force_hits(data, origin[0], direction[0])
    assert [h[0] for h in reference] == pytest.approx(result.t[0].tolist())


# ----------------------------------------------------------------------------------------- orientation, normals


def test_winding_is_flipped_to_agree_with_the_file_normals():
    origins = np.array([[0.2, 0.1, 5.0], [5.0, 0.3, -0.4]])
    directions = np.array([[0.0, 0.0, -1.0], [-1.0, 0.0, 0.0]])
    outward = TriangleMesh(cube_mesh()).all_hits(origins, directions)
    reversed_with_normals = TriangleMesh(cube_mesh(reverse_winding=True)).all_hits(origins, directions)
    reversed_bare = TriangleMesh(cube_mesh(reverse_winding=True, with_normals=False)).all_hits(origins, directions)
    np.testing.assert_array_equal(outward.entering, [[True, False]] * 2)
    np.testing.assert_array_equal(reversed_with_normals.entering, outward.entering)
    np.testing.assert_allclose(reversed_with_normals.normal, outward.normal)
    # Without normals the winding rules: now the mesh is inside out.
    np.testing.assert_array_equal(reversed_bare.entering, ~outward.entering)
    np.testing.assert_allclose(reversed_bare.normal, -outward.normal)


def test_shading_normals_interpolate_vertex_normals():
    smooth = TriangleMesh(icosphere(2, with_normals=True))
    flat = TriangleMesh(icosphere(2, with_normals=False))
    rng = np.random.default_rng(3)
    targets = rng.uniform(-0.5, 0.5, (200, 3))
    origins = rng.normal(size=(200, 3))
    origins = 4 * origins / np.linalg.norm(origins, axis=1, keepdims=True)
    directions = targets - origins
    a = smooth.closest_hits(origins, directions)
    b = flat.closest_hits(origins, directions)
    np.testing.assert_array_equal(a.part, b.part)
    points = origins + a.t[:, 0, None] * directions
    radial = points / np.linalg.norm(points, axis=1, keepdims=True)
    np.testing.assert_allclose(np.linalg.norm(a.normal[:, 0], axis=1), 1.0)
    np.testing.assert_allclose(np.linalg.norm(b.normal[:, 0], axis=1), 1.0)
    # The interpolated normal follows the sphere much more closely than the facet normal does.
    smooth_error = np.linalg.norm(a.normal[:, 0] - radial, axis=1)
    flat_error = np.linalg.norm(b.normal[:, 0] - radial, axis=1)
    assert smooth_error.max() < 0.05 and smooth_error.mean() < 0.5 * flat_error.mean()
    # The flat normal is the facet's outward winding normal; both point against entering rays.
    tri_v, _ = icosphere(2).triangles()
    corners = icosphere(2).vertices[tri_v[b.part[:, 0]]]
    facet = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    facet /= np.linalg.norm(facet, axis=1, keepdims=True)
    np.testing.assert_allclose(b.normal[:, 0], facet, atol=1e-12)
    assert (np.einsum("ij,ij->i", a.normal[:, 0], facet) > 0).all()
    assert a.entering.all() and b.entering.all()


def test_shading_normal_on_the_wrong_side_falls_back_to_the_facet():
    """A triangle whose vertex normals, though agreeing on average, interpolate to the inner side."""
    vertices = np.array([[0.0, 0.0, 0.0], [1.0, 0.0, 0.0], [0.0, 1.0, 0.0]])
    normals = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, 1.0], [0.0, 0.0, 1.0]])
    mesh = TriangleMesh(MeshData(vertices, normals, [((0, 1, 2), (0, 1, 2))]))
    origins = np.array([[0.05, 0.05, 1.0], [0.45, 0.45, 1.0]])  # near the odd corner, near the others
    result = mesh.closest_hits(origins, np.array([[0.0, 0.0, -1.0]] * 2))
    np.testing.assert_allclose(result.normal[:, 0], [[0, 0, 1], [0, 0, 1]], atol=1e-12)
    assert result.entering.all()


# ----------------------------------------------------------------------------------------- odd inputs


def test_empty_mesh_and_empty_batches():
    empty = TriangleMesh(MeshData(np.zeros((0, 3)), np.zeros((0, 3)), []))
    rays = (np.array([[0.0, 0.0, 5.0]]), np.array([[0.0, 0.0, -1.0]]))
    assert empty.all_hits(*rays).t.shape == (1, 0)
    assert np.isinf(empty.closest_hits(*rays).t).all()
    assert not empty.any_hit(*rays).any()
    mesh = TriangleMesh(cube_mesh())
    nothing = (np.zeros((0, 3)), np.zeros((0, 3)))
    assert mesh.all_hits(*nothing).t.shape == (0, 0)
    assert mesh.closest_hits(*nothing).t.shape == (0, 1)
    assert mesh.any_hit(*nothing).shape == (0,)


def test_hit_times_scale_with_the_direction_and_parts_index_triangles():
    data = icosphere(1)
    mesh = TriangleMesh(data)
    origins = np.array([[0.1, 0.2, 3.0]] * 3)
    directions = np.array([[0.0, 0.0, -1.0], [0.0, 0.0, -2.0], [0.0, 0.0, -0.25]])
    result = mesh.all_hits(origins, directions)
    np.testing.assert_allclose(result.t * [[1.0], [2.0], [0.25]], np.repeat(result.t[:1], 3, axis=0))
    reference = brute_force_hits(data, origins[0], directions[0])
    assert result.part[0].tolist() == [h[1] for h in reference]


def test_bad_indices_are_reported():
    with pytest.raises(ValueError, match="vertex index"):
        TriangleMesh(MeshData(np.zeros((3, 3)), np.zeros((0, 3)), [((0, 1, 3), ())]))
    with pytest.raises(ValueError, match="normal index"):
        TriangleMesh(MeshData(np.eye(3), np.zeros((1, 3)), [((0, 1, 2), (0, 0, 1))]))


def test_large_batch_matches_small_batches():
    """The packet traversal gives each ray the answer it gets alone."""
    data, mesh = traced(("icosphere", 3))
    rng = np.random.default_rng(11)
    origins = rng.uniform(-3, 3, (500, 3))
    directions = rng.normal(size=(500, 3))
    together = mesh.all_hits(origins, directions)
    first = mesh.closest_hits(origins, directions, 0.0)
    for r in range(0, 500, 37):
        alone = mesh.all_hits(origins[r:r + 1], directions[r:r + 1])
        k = alone.t.shape[1]
        np.testing.assert_array_equal(together.t[r, :k], alone.t[0])
        assert np.isinf(together.t[r, k:]).all()
        np.testing.assert_array_equal(first.t[r], mesh.closest_hits(origins[r:r + 1], directions[r:r + 1], 0.0).t[0])
