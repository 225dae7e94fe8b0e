"""Built-in polyhedra and the Utah teapot: topology, geometry and data checks."""
from __future__ import annotations

from collections import Counter
from math import sqrt

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from tracer.geometry import teapot as tp
from tracer.geometry.polyhedra import (
    DIAMOND_CROWN_HEIGHT,
    DIAMOND_GIRDLE_RADIUS,
    DIAMOND_GIRDLE_THICKNESS,
    DIAMOND_PAVILION_DEPTH,
    DIAMOND_TABLE_RADIUS,
    face_planes,
    polyhedron_mesh,
)
from tracer.geometry.teapot import teapot_mesh
from tracer.model import POLYHEDRON_KINDS, MeshData

PHI = (1 + sqrt(5)) / 2

# kind: (V, E, F)
COUNTS = {
    "tetrahedron": (4, 6, 4),
    "octahedron": (6, 12, 8),
    "dodecahedron": (20, 30, 12),
    "icosahedron": (12, 30, 20),
    "buckyball": (60, 90, 32),
    "diamond": (57, 128, 73),
}
REGULAR = ["tetrahedron", "octahedron", "dodecahedron", "icosahedron", "buckyball"]


def _edge_length(kind: str) -> float:
    """Edge length at circumradius 1, from the textbook circumradius formulas."""
    return {
        "tetrahedron": 4 / sqrt(6),  # R = a sqrt(6) / 4
        "octahedron": sqrt(2),  # R = a / sqrt(2)
        "dodecahedron": 4 / (sqrt(3) * (1 + sqrt(5))),  # R = a sqrt(3) (1 + sqrt 5) / 4
        "icosahedron": 4 / sqrt(10 + 2 * sqrt(5)),  # R = a sqrt(10 + 2 sqrt 5) / 4
        "buckyball": 4 / sqrt(58 + 18 * sqrt(5)),  # R = a sqrt(58 + 18 sqrt 5) / 4
    }[kind]


def _known_volume(kind: str) -> float:
    a = _edge_length(kind)
    return {
        "tetrahedron": a ** 3 / (6 * sqrt(2)),
        "octahedron": sqrt(2) / 3 * a ** 3,
        "dodecahedron": (15 + 7 * sqrt(5)) / 4 * a ** 3,
        "icosahedron": 5 * (3 + sqrt(5)) / 12 * a ** 3,
        "buckyball": (125 + 43 * sqrt(5)) / 4 * a ** 3,
    }[kind]


def _signed_volume(vertices: np.ndarray, tris: np.ndarray) -> float:
    a, b, c = vertices[tris[:, 0]], vertices[tris[:, 1]], vertices[tris[:, 2]]
    return float(np.einsum("ij,ij->i", a, np.cross(b, c)).sum() / 6.0)


def _directed_edges(faces) -> Counter:
    edges: Counter = Counter()
    for verts in faces:
        for i in range(len(verts)):
            edges[(verts[i], verts[(i + 1) % len(verts)])] += 1
    return edges


def _undirected(edges: Counter) -> Counter:
    out: Counter = Counter()
    for (a, b), k in edges.items():
        out[frozenset((a, b))] += k
    return out


# ---------------------------------------------------------------------------------------------- polyhedra


@pytest.mark.parametrize("kind", POLYHEDRON_KINDS)
def test_counts_and_euler(kind):
    mesh = polyhedron_mesh(kind)
    assert isinstance(mesh, MeshData)
    assert mesh.origin == f"built-in:{kind}"
    edges = _undirected(_directed_edges([f for f, _ in mesh.faces]))
    v, e, f = len(mesh.vertices), len(edges), len(mesh.faces)
    assert (v, e, f) == COUNTS[kind]
    assert v - e + f == 2
    assert mesh.vertices.shape == (v, 3) and mesh.vertices.dtype == np.float64


@pytest.mark.parametrize("kind", POLYHEDRON_KINDS)
def test_closed_and_consistently_wound(kind):
    """Every edge is used twice, once in each direction: a closed surface, all faces wound alike."""
    directed = _directed_edges([f for f, _ in polyhedron_mesh(kind).faces])
    assert all(k == 1 for k in directed.values())
    assert all((b, a) in directed for (a, b) in directed)


def test_face_shapes():
    def shapes(kind):
        return Counter(len(f) for f, _ in polyhedron_mesh(kind).faces)

    assert shapes("tetrahedron") == {3: 4}
    assert shapes("octahedron") == {3: 8}
    assert shapes("dodecahedron") == {5: 12}
    assert shapes("icosahedron") == {3: 20}
    assert shapes("buckyball") == {5: 12, 6: 20}
    assert shapes("diamond") == {8: 1, 4: 32, 3: 40}


@pytest.mark.parametrize("kind", REGULAR)
def test_vertices_on_unit_sphere(kind):
    radii = np.linalg.norm(polyhedron_mesh(kind).vertices, axis=1)
    np.testing.assert_allclose(radii, 1.0, atol=1e-12)


@pytest.mark.parametrize("kind", POLYHEDRON_KINDS)
def test_centred(kind):
    vertices = polyhedron_mesh(kind).vertices
    if kind != "diamond":  # the diamond is centred on its girdle, not on its centroid
        np.testing.assert_allclose(vertices.mean(axis=0), 0.0, atol=1e-12)
    _, offsets = face_planes(kind)
    assert np.all(offsets > 0.05)  # the origin is well inside


@pytest.mark.parametrize("kind", POLYHEDRON_KINDS)
def test_faces_planar_and_normals(kind):
    mesh = polyhedron_mesh(kind)
    normals, offsets = face_planes(kind)
    assert normals.shape == (len(mesh.faces), 3) and offsets.shape == (len(mesh.faces),)
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(mesh.normals, normals, atol=1e-15)
    for k, (verts, norms) in enumerate(mesh.faces):
        assert len(verts) == len(norms) >= 3
        assert len(set(verts)) == len(verts)
        assert set(norms) == {k}  # every normal index points at the face's own normal
        poly = mesh.vertices[list(verts)]
        # Planar, independently of the stored normal: the smallest singular value of the centred points.
        assert np.linalg.svd(poly - poly.mean(axis=0), compute_uv=False)[-1] < 1e-12
        np.testing.assert_allclose(poly @ normals[k], offsets[k], atol=1e-12)
        # Counter-clockwise from outside: Newell's normal of the winding points along the outward normal.
        newell = np.sum(np.cross(poly, np.roll(poly, -1, axis=0)), axis=0)
        np.testing.assert_allclose(newell / np.linalg.norm(newell), normals[k], atol=1e-12)
        # Outward: the face plane is on the far side of the centre.
        assert offsets[k] > 0 and poly.mean(axis=0) @ normals[k] > 0


@pytest.mark.parametrize("kind", POLYHEDRON_KINDS)
def test_convex(kind):
    vertices = polyhedron_mesh(kind).vertices
    normals, offsets = face_planes(kind)
    assert np.all(vertices @ normals.T <= offsets + 1e-12)
    # Each face's own vertices are on its plane and every other vertex strictly inside it: no two faces
    # are coplanar (they would have been merged).
    for k, (verts, _) in enumerate(polyhedron_mesh(kind).faces):
        others = np.setdiff1d(np.arange(len(vertices)), verts)
        assert np.all(vertices[others] @ normals[k] < offsets[k] - 1e-9)


@pytest.mark.parametrize("kind", REGULAR)
def test_volume_matches_formula(kind):
    mesh = polyhedron_mesh(kind)
    tris, _ = mesh.triangles()
    volume = _signed_volume(mesh.vertices, tris)
    assert volume > 0
    assert volume == pytest.approx(_known_volume(kind), rel=1e-12)


def test_known_volume_formulas_sanity():
    # The circumradius/edge formulas above, checked against two independent facts: the octahedron of
    # circumradius 1 is two square pyramids of volume 2/3 each; the tetrahedron inscribed in the cube of
    # circumradius 1 (side 2/sqrt 3) is a third of the cube.
    assert _known_volume("octahedron") == pytest.approx(4 / 3)
    assert _known_volume("tetrahedron") == pytest.approx((2 / sqrt(3)) ** 3 / 3)
    assert _edge_length("dodecahedron") == pytest.approx(2 / (sqrt(3) * PHI))


@pytest.mark.parametrize("kind", POLYHEDRON_KINDS)
def test_volume_two_ways(kind):
    """Divergence theorem over triangles == sum of face pyramids (area * offset / 3)."""
    mesh = polyhedron_mesh(kind)
    tris, _ = mesh.triangles()
    _, offsets = face_planes(kind)
    pyramids = 0.0
    for k, (verts, _) in enumerate(mesh.faces):
        poly = mesh.vertices[list(verts)]
        area = 0.5 * np.linalg.norm(np.sum(np.cross(poly, np.roll(poly, -1, axis=0)), axis=0))
        pyramids += area * offsets[k] / 3.0
    assert _signed_volume(mesh.vertices, tris) == pytest.approx(pyramids, rel=1e-12)


@pytest.mark.parametrize("kind", REGULAR)
def test_edges_equal(kind):
    mesh = polyhedron_mesh(kind)
    edges = _undirected(_directed_edges([f for f, _ in mesh.faces]))
    lengths = [np.linalg.norm(mesh.vertices[a] - mesh.vertices[b]) for a, b in map(tuple, edges)]
    np.testing.assert_allclose(lengths, _edge_length(kind), rtol=1e-12)
    # ...and no two vertices are closer than an edge.
    d = np.linalg.norm(mesh.vertices[:, None] - mesh.vertices[None], axis=2)
    assert np.min(d[d > 0]) == pytest.approx(_edge_length(kind), rel=1e-12)


def test_buckyball_faces():
    """Pentagons touch only hexagons; each vertex is on one pentagon and two hexagons."""
    mesh = polyhedron_mesh("buckyball")
    per_vertex: dict[int, list[int]] = {}
    for verts, _ in mesh.faces:
        for v in verts:
            per_vertex.setdefault(v, []).append(len(verts))
    assert all(sorted(sizes) == [5, 6, 6] for sizes in per_vertex.values())


def test_diamond_dimensions():
    mesh = polyhedron_mesh("diamond")
    v = mesh.vertices
    r = DIAMOND_GIRDLE_RADIUS
    radii = np.linalg.norm(v, axis=1)
    assert np.all(radii <= 1.0 + 1e-12)  # fits in the unit sphere
    assert np.sum(np.abs(radii - 1.0) < 1e-12) == 32  # the girdle corners touch it
    top = r * (DIAMOND_GIRDLE_THICKNESS / 2 + DIAMOND_CROWN_HEIGHT)
    bottom = -r * (DIAMOND_GIRDLE_THICKNESS / 2 + DIAMOND_PAVILION_DEPTH)
    assert v[:, 1].max() == pytest.approx(top) and v[:, 1].min() == pytest.approx(bottom)
    assert top == pytest.approx(0.344 * r) and bottom == pytest.approx(-0.882 * r)
    np.testing.assert_allclose(np.hypot(v[:, 0], v[:, 2]).max(), r)
    # The table: the one octagon, facing straight up, circumradius 0.53 R.
    normals, offsets = face_planes("diamond")
    (table,) = [k for k, (f, _) in enumerate(mesh.faces) if len(f) == 8]
    np.testing.assert_allclose(normals[table], [0, 1, 0], atol=1e-12)
    table_pts = v[list(mesh.faces[table][0])]
    np.testing.assert_allclose(np.hypot(table_pts[:, 0], table_pts[:, 2]), DIAMOND_TABLE_RADIUS * r)
    # The culet: a single lowest vertex on the axis, where the 8 pavilion kites meet.
    culet = int(np.argmin(v[:, 1]))
    np.testing.assert_allclose(v[culet, [0, 2]], 0.0, atol=1e-15)
    at_culet = [len(f) for f, _ in mesh.faces if culet in f]
    assert at_culet == [4] * 8
    # 8-fold symmetry: rotating by 45 degrees about y maps the vertex set to itself.
    c, s = np.cos(np.pi / 4), np.sin(np.pi / 4)
    rot = np.array([[c, 0, -s], [0, 1, 0], [s, 0, c]])
    rotated = v @ rot.T
    d = np.linalg.norm(rotated[:, None] - v[None], axis=2)
    assert np.all(d.min(axis=1) < 1e-12)
    # Bezel (crown) angle and pavilion angle, in degrees, as documented.
    slopes = np.degrees(np.arccos(np.clip(np.abs(normals[:, 1]), 0, 1)))
    assert np.sum(np.isclose(slopes, 34.58, atol=0.01)) == 8
    assert np.sum(np.isclose(slopes, 40.76, atol=0.01)) == 8
    assert np.sum(np.isclose(slopes, 90.0, atol=1e-9)) == 16


def test_unknown_kind():
    with pytest.raises(ValueError):
        polyhedron_mesh("cube")
    with pytest.raises(ValueError):
        face_planes("teapot")


def test_polyhedra_cache_is_protected():
    mesh = polyhedron_mesh("icosahedron")
    mesh.vertices *= 2.0
    mesh.normals[:] = 0.0
    mesh.faces.clear()
    normals, offsets = face_planes("icosahedron")
    normals[:] = 0.0
    offsets[:] = -1.0
    fresh = polyhedron_mesh("icosahedron")
    np.testing.assert_allclose(np.linalg.norm(fresh.vertices, axis=1), 1.0)
    assert len(fresh.faces) == 20
    n2, d2 = face_planes("icosahedron")
    assert np.all(d2 > 0) and np.allclose(np.linalg.norm(n2, axis=1), 1.0)


@settings(max_examples=60, deadline=None)
@given(kind=st.sampled_from(POLYHEDRON_KINDS),
       direction=st.tuples(*[st.floats(-1, 1, allow_nan=False)] * 3).filter(lambda d: np.linalg.norm(d) > 1e-3))
def test_clipping_ray_from_centre(kind, direction):
    """Cyrus-Beck from the centre: the exit point is on the surface, inside the unit sphere, on some face."""
    d = np.asarray(direction) / np.linalg.norm(direction)
    normals, offsets = face_planes(kind)
    denom = normals @ d
    leaving = denom > 1e-12
    t_exit = np.min(offsets[leaving] / denom[leaving])
    p = t_exit * d
    assert np.linalg.norm(p) <= 1.0 + 1e-12
    heights = normals @ p - offsets
    assert np.all(heights <= 1e-12) and np.max(heights) > -1e-12


# ------------------------------------------------------------------------------------------------- teapot

# Newell's original teapot table (the public "teaset" data), to check GLUT's condensed form against: 306
# control points (x,y,z; data frame) and 32 patches of 16 0-based indices.
NEWELL_POINTS = """
1.4,0.0,2.4 1.4,-0.784,2.4 0.784,-1.4,2.4 0.0,-1.4,2.4 1.3375,0.0,2.53125
1.3375,-0.749,2.53125 0.749,-1.3375,2.53125 0.0,-1.3375,2.53125 1.4375,0.0,2.53125 1.4375,-0.805,2.53125
0.805,-1.4375,2.53125 0.0,-1.4375,2.53125 1.5,0.0,2.4 1.5,-0.84,2.4 0.84,-1.5,2.4
0.0,-1.5,2.4 -0.784,-1.4,2.4 -1.4,-0.784,2.4 -1.4,0.0,2.4 -0.749,-1.3375,2.53125
-1.3375,-0.749,2.53125 -1.3375,0.0,2.53125 -0.805,-1.4375,2.53125 -1.4375,-0.805,2.53125 -1.4375,0.0,2.53125
-0.84,-1.5,2.4 -1.5,-0.84,2.4 -1.5,0.0,2.4 -1.4,0.784,2.4 -0.784,1.4,2.4
0.0,1.4,2.4 -1.3375,0.749,2.53125 -0.749,1.3375,2.53125 0.0,1.3375,2.53125 -1.4375,0.805,2.53125
-0.805,1.4375,2.53125 0.0,1.4375,2.53125 -1.5,0.84,2.4 -0.84,1.5,2.4 0.0,1.5,2.4
0.784,1.4,2.4 1.4,0.784,2.4 0.749,1.3375,2.53125 1.3375,0.749,2.53125 0.805,1.4375,2.53125
1.4375,0.805,2.53125 0.84,1.5,2.4 1.5,0.84,2.4 1.75,0.0,1.875 1.75,-0.98,1.875
0.98,-1.75,1.875 0.0,-1.75,1.875 2.0,0.0,1.35 2.0,-1.12,1.35 1.12,-2.0,1.35
0.0,-2.0,1.35 2.0,0.0,0.9 2.0,-1.12,0.9 1.12,-2.0,0.9 0.0,-2.0,0.9
-0.98,-1.75,1.875 -1.75,-0.98,1.875 -1.75,0.0,1.875 -1.12,-2.0,1.35 -2.0,-1.12,1.35
-2.0,0.0,1.35 -1.12,-2.0,0.9 -2.0,-1.12,0.9 -2.0,0.0,0.9 -1.75,0.98,1.875
-0.98,1.75,1.875 0.0,1.75,1.875 -2.0,1.12,1.35 -1.12,2.0,1.35 0.0,2.0,1.35
-2.0,1.12,0.9 -1.12,2.0,0.9 0.0,2.0,0.9 0.98,1.75,1.875 1.75,0.98,1.875
1.12,2.0,1.35 2.0,1.12,1.35 1.12,2.0,0.9 2.0,1.12,0.9 2.0,0.0,0.45
2.0,-1.12,0.45 1.12,-2.0,0.45 0.0,-2.0,0.45 1.5,0.0,0.225 1.5,-0.84,0.225
0.84,-1.5,0.225 0.0,-1.5,0.225 1.5,0.0,0.15 1.5,-0.84,0.15 0.84,-1.5,0.15
0.0,-1.5,0.15 -1.12,-2.0,0.45 -2.0,-1.12,0.45 -2.0,0.0,0.45 -0.84,-1.5,0.225
-1.5,-0.84,0.225 -1.5,0.0,0.225 -0.84,-1.5,0.15 -1.5,-0.84,0.15 -1.5,0.0,0.15
-2.0,1.12,0.45 -1.12,2.0,0.45 0.0,2.0,0.45 -1.5,0.84,0.225 -0.84,1.5,0.225
0.0,1.5,0.225 -1.5,0.84,0.15 -0.84,1.5,0.15 0.0,1.5,0.15 1.12,2.0,0.45
2.0,1.12,0.45 0.84,1.5,0.225 1.5,0.84,0.225 0.84,1.5,0.15 1.5,0.84,0.15
-1.6,0.0,2.025 -1.6,-0.3,2.025 -1.5,-0.3,2.25 -1.5,0.0,2.25 -2.3,0.0,2.025
-2.3,-0.3,2.025 -2.5,-0.3,2.25 -2.5,0.0,2.25 -2.7,0.0,2.025 -2.7,-0.3,2.025
-3.0,-0.3,2.25 -3.0,0.0,2.25 -2.7,0.0,1.8 -2.7,-0.3,1.8 -3.0,-0.3,1.8
-3.0,0.0,1.8 -1.5,0.3,2.25 -1.6,0.3,2.025 -2.5,0.3,2.25 -2.3,0.3,2.025
-3.0,0.3,2.25 -2.7,0.3,2.025 -3.0,0.3,1.8 -2.7,0.3,1.8 -2.7,0.0,1.575
-2.7,-0.3,1.575 -3.0,-0.3,1.35 -3.0,0.0,1.35 -2.5,0.0,1.125 -2.5,-0.3,1.125
-2.65,-0.3,0.9375 -2.65,0.0,0.9375 -2.0,-0.3,0.9 -1.9,-0.3,0.6 -1.9,0.0,0.6
-3.0,0.3,1.35 -2.7,0.3,1.575 -2.65,0.3,0.9375 -2.5,0.3,1.125 -1.9,0.3,0.6
-2.0,0.3,0.9 1.7,0.0,1.425 1.7,-0.66,1.425 1.7,-0.66,0.6 1.7,0.0,0.6
2.6,0.0,1.425 2.6,-0.66,1.425 3.1,-0.66,0.825 3.1,0.0,0.825 2.3,0.0,2.1
2.3,-0.25,2.1 2.4,-0.25,2.025 2.4,0.0,2.025 2.7,0.0,2.4 2.7,-0.25,2.4
3.3,-0.25,2.4 3.3,0.0,2.4 1.7,0.66,0.6 1.7,0.66,1.425 3.1,0.66,0.825
2.6,0.66,1.425 2.4,0.25,2.025 2.3,0.25,2.1 3.3,0.25,2.4 2.7,0.25,2.4
2.8,0.0,2.475 2.8,-0.25,2.475 3.525,-0.25,2.49375 3.525,0.0,2.49375 2.9,0.0,2.475
2.9,-0.15,2.475 3.45,-0.15,2.5125 3.45,0.0,2.5125 2.8,0.0,2.4 2.8,-0.15,2.4
3.2,-0.15,2.4 3.2,0.0,2.4 3.525,0.25,2.49375 2.8,0.25,2.475 3.45,0.15,2.5125
2.9,0.15,2.475 3.2,0.15,2.4 2.8,0.15,2.4 0.0,0.0,3.15 0.0,-0.002,3.15
0.002,0.0,3.15 0.8,0.0,3.15 0.8,-0.45,3.15 0.45,-0.8,3.15 0.0,-0.8,3.15
0.0,0.0,2.85 0.2,0.0,2.7 0.2,-0.112,2.7 0.112,-0.2,2.7 0.0,-0.2,2.7
-0.002,0.0,3.15 -0.45,-0.8,3.15 -0.8,-0.45,3.15 -0.8,0.0,3.15 -0.112,-0.2,2.7
-0.2,-0.112,2.7 -0.2,0.0,2.7 0.0,0.002,3.15 -0.8,0.45,3.15 -0.45,0.8,3.15
0.0,0.8,3.15 -0.2,0.112,2.7 -0.112,0.2,2.7 0.0,0.2,2.7 0.45,0.8,3.15
0.8,0.45,3.15 0.112,0.2,2.7 0.2,0.112,2.7 0.4,0.0,2.55 0.4,-0.224,2.55
0.224,-0.4,2.55 0.0,-0.4,2.55 1.3,0.0,2.55 1.3,-0.728,2.55 0.728,-1.3,2.55
0.0,-1.3,2.55 1.3,0.0,2.4 1.3,-0.728,2.4 0.728,-1.3,2.4 0.0,-1.3,2.4
-0.224,-0.4,2.55 -0.4,-0.224,2.55 -0.4,0.0,2.55 -0.728,-1.3,2.55 -1.3,-0.728,2.55
-1.3,0.0,2.55 -0.728,-1.3,2.4 -1.3,-0.728,2.4 -1.3,0.0,2.4 -0.4,0.224,2.55
-0.224,0.4,2.55 0.0,0.4,2.55 -1.3,0.728,2.55 -0.728,1.3,2.55 0.0,1.3,2.55
-1.3,0.728,2.4 -0.728,1.3,2.4 0.0,1.3,2.4 0.224,0.4,2.55 0.4,0.224,2.55
0.728,1.3,2.55 1.3,0.728,2.55 0.728,1.3,2.4 1.3,0.728,2.4 0.0,0.0,0.0
1.5,0.0,0.15 1.5,0.84,0.15 0.84,1.5,0.15 0.0,1.5,0.15 1.5,0.0,0.075
1.5,0.84,0.075 0.84,1.5,0.075 0.0,1.5,0.075 1.425,0.0,0.0 1.425,0.798,0.0
0.798,1.425,0.0 0.0,1.425,0.0 -0.84,1.5,0.15 -1.5,0.84,0.15 -1.5,0.0,0.15
-0.84,1.5,0.075 -1.5,0.84,0.075 -1.5,0.0,0.075 -0.798,1.425,0.0 -1.425,0.798,0.0
-1.425,0.0,0.0 -1.5,-0.84,0.15 -0.84,-1.5,0.15 0.0,-1.5,0.15 -1.5,-0.84,0.075
-0.84,-1.5,0.075 0.0,-1.5,0.075 -1.425,-0.798,0.0 -0.798,-1.425,0.0 0.0,-1.425,0.0
0.84,-1.5,0.15 1.5,-0.84,0.15 0.84,-1.5,0.075 1.5,-0.84,0.075 0.798,-1.425,0.0
1.425,-0.798,0.0
"""
NEWELL_PATCHES = """
0 1 2 3 4 5 6 7 8 9 10 11 12 13 14 15
3 16 17 18 7 19 20 21 11 22 23 24 15 25 26 27
18 28 29 30 21 31 32 33 24 34 35 36 27 37 38 39
30 40 41 0 33 42 43 4 36 44 45 8 39 46 47 12
12 13 14 15 48 49 50 51 52 53 54 55 56 57 58 59
15 25 26 27 51 60 61 62 55 63 64 65 59 66 67 68
27 37 38 39 62 69 70 71 65 72 73 74 68 75 76 77
39 46 47 12 71 78 79 48 74 80 81 52 77 82 83 56
56 57 58 59 84 85 86 87 88 89 90 91 92 93 94 95
59 66 67 68 87 96 97 98 91 99 100 101 95 102 103 104
68 75 76 77 98 105 106 107 101 108 109 110 104 111 112 113
77 82 83 56 107 114 115 84 110 116 117 88 113 118 119 92
120 121 122 123 124 125 126 127 128 129 130 131 132 133 134 135
123 136 137 120 127 138 139 124 131 140 141 128 135 142 143 132
132 133 134 135 144 145 146 147 148 149 150 151 68 152 153 154
135 142 143 132 147 155 156 144 151 157 158 148 154 159 160 68
161 162 163 164 165 166 167 168 169 170 171 172 173 174 175 176
164 177 178 161 168 179 180 165 172 181 182 169 176 183 184 173
173 174 175 176 185 186 187 188 189 190 191 192 193 194 195 196
176 183 184 173 188 197 198 185 192 199 200 189 196 201 202 193
203 203 203 203 206 207 208 209 210 210 210 210 211 212 213 214
203 203 203 203 209 216 217 218 210 210 210 210 214 219 220 221
203 203 203 203 218 223 224 225 210 210 210 210 221 226 227 228
203 203 203 203 225 229 230 206 210 210 210 210 228 231 232 211
211 212 213 214 233 234 235 236 237 238 239 240 241 242 243 244
214 219 220 221 236 245 246 247 240 248 249 250 244 251 252 253
221 226 227 228 247 254 255 256 250 257 258 259 253 260 261 262
228 231 232 211 256 263 264 233 259 265 266 237 262 267 268 241
269 269 269 269 278 279 280 281 274 275 276 277 270 271 272 273
269 269 269 269 281 288 289 290 277 285 286 287 273 282 283 284
269 269 269 269 290 297 298 299 287 294 295 296 284 291 292 293
269 269 269 269 299 304 305 278 296 302 303 274 293 300 301 270
"""



def test_teapot_data_counts():
    # GLUT's condensed data: 127 control points and 10 patches of 16 indices.  (Newell's full table is 306
    # points for 32 patches; GLUT keeps a quarter/half and mirrors.)
    assert len(tp.CONTROL_POINTS) == 127
    assert all(len(p) == 3 for p in tp.CONTROL_POINTS)
    assert len(tp.PATCHES) == 10 and all(len(p) == 16 for p in tp.PATCHES)
    used = {i for patch in tp.PATCHES for i in patch}
    assert used == set(range(127))  # every point used, none out of range
    nets = tp.expanded_patches()
    assert nets.shape == (32, 4, 4, 3)
    # The data (before GLUT's transform) spans x in [-3, 3.525], |y| <= 2, z in [0, 3.15].
    cp = np.asarray(tp.CONTROL_POINTS)
    assert cp[:, 0].min() == -3.0 and cp[:, 0].max() == 3.525
    assert np.abs(cp[:, 1]).max() == 2.0
    assert cp[:, 2].min() == 0.0 and cp[:, 2].max() == 3.15


def _net_symmetries(net):
    """A bicubic net under the 8 reparametrisations of the unit square (flips and the u/v swap)."""
    for t in (net, net.transpose(1, 0, 2)):
        yield from (t, t[::-1], t[:, ::-1], t[::-1, ::-1])


def test_teapot_patches_are_newells():
    """GLUT's 10 patches, mirrored as GLUT mirrors them, are exactly Newell's 32 patches (306 points)."""
    points = np.array([[float(x) for x in tok.split(",")] for tok in NEWELL_POINTS.split()])
    patches = np.array([[int(i) for i in line.split()] for line in NEWELL_PATCHES.strip().splitlines()])
    assert points.shape == (306, 3) and patches.shape == (32, 16)
    newell = points[patches].reshape(32, 4, 4, 3)
    matched = set()
    for net in tp.expanded_patches():
        hits = [j for j, other in enumerate(newell) if any(np.array_equal(s, other) for s in _net_symmetries(net))]
        assert len(hits) == 1
        matched.add(hits[0])
    assert matched == set(range(32))


def _boundaries(nets):
    """The four boundary control polygons of every net: (patch, side, (4, 3) points)."""
    out = []
    for i, net in enumerate(nets):
        for side, curve in (("v0", net[0]), ("v1", net[3]), ("u0", net[:, 0]), ("u1", net[:, 3])):
            out.append((i, side, curve))
    return out


def test_teapot_patch_seams_match():
    """A Bezier patch's boundary curve is fixed by its 4 boundary control points, so matching control
    polygons (in the same or reverse order) means matching curves.  Every non-degenerate boundary curve
    of the 32 patches is shared with exactly one other patch, except the 16 the data leaves open."""
    nets = tp.expanded_patches()
    bounds = _boundaries(nets)
    open_curves = []
    for i, side, curve in bounds:
        if np.allclose(curve, curve[0], atol=1e-12):
            assert curve[0][0] == 0 and curve[0][1] == 0  # collapsed: the lid knob's top or the bottom centre
            continue
        partners = [(j, s) for j, s, other in bounds if (j, s) != (i, side)
                    and (np.allclose(other, curve, atol=1e-12) or np.allclose(other[::-1], curve, atol=1e-12))]
        assert len(partners) <= 1
        if not partners:
            open_curves.append(curve)
    assert len(open_curves) == 16
    kinds = Counter()
    for curve in open_curves:
        radial = np.hypot(curve[:, 0], curve[:, 1])
        if np.allclose(curve[:, 2], 2.4) and np.allclose(radial[[0, 3]], 1.3):
            kinds["lid edge"] += 1
        elif np.allclose(curve[:, 2], 2.4) and np.allclose(radial[[0, 3]], 1.4):
            kinds["rim inner edge"] += 1
        elif curve[:, 0].min() < 0:
            kinds["handle end"] += 1
        else:
            kinds["spout end"] += 1
    assert kinds == {"lid edge": 4, "rim inner edge": 4, "handle end": 4, "spout end": 4}


def test_teapot_transform_is_gluts():
    def rot_x(deg):
        c, s = np.cos(np.radians(deg)), np.sin(np.radians(deg))
        return np.array([[1, 0, 0, 0], [0, c, -s, 0], [0, s, c, 0], [0, 0, 0, 1.0]])

    scale = np.diag([0.5, 0.5, 0.5, 1.0])
    translate = np.eye(4)
    translate[2, 3] = -1.5
    np.testing.assert_allclose(rot_x(270) @ scale @ translate, tp.TRANSFORM, atol=1e-15)


def test_teapot_bounding_box_value():
    # The spout's outermost curve (column k = 3 of the tip patch) has x control values 3.3, 3.525, 3.45, 3.2;
    # every row of that net is non-decreasing in x, so the maximum over the patch is on this curve.
    x = np.array([3.3, 3.525, 3.45, 3.2])
    d = np.diff(x)  # derivative: 3 [d0 (1-t)^2 + 2 d1 t (1-t) + d2 t^2]
    coeffs = [d[0] - 2 * d[1] + d[2], -2 * d[0] + 2 * d[1], d[0]]
    roots = [t.real for t in np.roots(coeffs) if abs(t.imag) < 1e-12 and 0 <= t.real <= 1]
    candidates = [0.0, 1.0] + roots
    bern = lambda t: np.array([(1 - t) ** 3, 3 * t * (1 - t) ** 2, 3 * t * t * (1 - t), t ** 3])  # noqa: E731
    x_max = max(float(bern(t) @ x) for t in candidates)
    assert x_max == pytest.approx(tp.SPOUT_MAX_X, abs=1e-12)
    lo, hi = tp.BOUNDING_BOX
    np.testing.assert_allclose(lo, [-1.5, -0.75, -1.0])
    np.testing.assert_allclose(hi, [1.7170376, 0.825, 1.0], atol=1e-7)
    # ...and the surface itself, sampled finely, stays in the box and reaches it.
    t = np.linspace(0, 1, 201)
    b = np.stack([bern(s) for s in t])
    pts = np.einsum("aj,bk,pjkc->pabc", b, b, tp.expanded_patches(), optimize=True).reshape(-1, 3)
    world = pts @ tp.TRANSFORM[:3, :3].T + tp.TRANSFORM[:3, 3]
    assert np.all(world >= lo - 1e-12) and np.all(world <= hi + 1e-12)
    np.testing.assert_allclose(world.min(axis=0), lo, atol=1e-12)
    np.testing.assert_allclose(world.max(axis=0), hi, atol=1e-5)


@pytest.mark.parametrize("divisions", [4, 8, 32])
def test_teapot_mesh_bounding_box(divisions):
    v = teapot_mesh(divisions).vertices
    lo, hi = tp.BOUNDING_BOX
    np.testing.assert_allclose(v.min(axis=0), lo, atol=1e-12)  # all patch corners: exact
    np.testing.assert_allclose(v.max(axis=0)[1:], hi[1:], atol=1e-12)
    assert hi[0] - 0.06 / divisions ** 2 <= v[:, 0].max() <= hi[0] + 1e-12


def _teapot_arrays(divisions=8):
    mesh = teapot_mesh(divisions)
    tris = np.array([f for f, _ in mesh.faces])
    return mesh, tris


def test_teapot_faces_and_normals():
    mesh, tris = _teapot_arrays()
    assert mesh.origin == "built-in:teapot"
    assert all(len(f) == 3 and tuple(f) == tuple(n) for f, n in mesh.faces)
    assert len(mesh.normals) == len(mesh.vertices)
    assert np.all(np.isfinite(mesh.vertices)) and np.all(np.isfinite(mesh.normals))
    np.testing.assert_allclose(np.linalg.norm(mesh.normals, axis=1), 1.0, atol=1e-12)
    a, b, c = (mesh.vertices[tris[:, i]] for i in range(3))
    cross = np.cross(b - a, c - a)
    area = 0.5 * np.linalg.norm(cross, axis=1)
    assert np.all(area > 1e-12)  # no zero-area triangles
    assert np.all((tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2]))
    face_n = cross / np.linalg.norm(cross, axis=1, keepdims=True)
    dots = np.concatenate([np.einsum("ij,ij->i", face_n, mesh.normals[tris[:, i]]) for i in range(3)])
    assert np.mean(dots > 0) > 0.99
    assert np.mean(dots > 0.5) > 0.95


def test_teapot_pole_normals():
    mesh = teapot_mesh(8)
    v, n = mesh.vertices, mesh.normals
    knob = np.flatnonzero(np.all(np.isclose(v, [0, 0.825, 0], atol=1e-12), axis=1))
    bottom = np.flatnonzero(np.all(np.isclose(v, [0, -0.75, 0], atol=1e-12), axis=1))
    assert len(knob) == 1 and len(bottom) == 1  # welded into one vertex each
    np.testing.assert_allclose(n[knob[0]], [0, 1, 0], atol=1e-9)
    np.testing.assert_allclose(n[bottom[0]], [0, -1, 0], atol=1e-9)


@pytest.mark.parametrize("divisions", [2, 8, 16])
def test_teapot_topology(divisions):
    """Welded seams: only the 16 open curves of the data stay open; winding is consistent."""
    mesh, tris = _teapot_arrays(divisions)
    directed = _directed_edges(map(tuple, tris.tolist()))
    assert all(k == 1 for k in directed.values())  # consistent winding: no edge used twice the same way
    undirected = _undirected(directed)
    assert max(undirected.values()) == 2  # manifold
    boundary = sum(1 for k in undirected.values() if k == 1)
    assert boundary == 16 * divisions
    # No two vertices coincide (welding done).
    v = mesh.vertices
    order = np.lexsort(v.T)
    gaps = np.linalg.norm(np.diff(v[order], axis=0), axis=1)
    assert np.all(gaps > 1e-9)


def test_teapot_volume():
    mesh, tris = _teapot_arrays(8)
    volume = _signed_volume(mesh.vertices, tris)
    assert volume > 0  # outward winding
    fine_mesh, fine_tris = _teapot_arrays(32)
    fine = _signed_volume(fine_mesh.vertices, fine_tris)
    assert fine == pytest.approx(volume, rel=0.02)
    # A sanity bracket: the body lies between the cylinder of radius 0.75 (the bottom) and that of radius 1
    # (the widest), over the body height 0.6 + 0.75 = 1.35 (Y from -0.75 to the rim at 0.45).
    assert np.pi * 0.75 ** 2 * 1.35 < fine < np.pi * 1.0 ** 2 * 1.575


def test_teapot_bad_divisions():
    for bad in (0, -1, 2.5, True, "8"):
        with pytest.raises(ValueError):
            teapot_mesh(bad)


def test_teapot_cache_is_protected():
    mesh = teapot_mesh(4)
    mesh.vertices[:] = 0.0
    mesh.normals[:] = 0.0
    mesh.faces.clear()
    fresh = teapot_mesh(4)
    assert len(fresh.faces) > 0 and np.ptp(fresh.vertices[:, 0]) > 3.0
    np.testing.assert_allclose(np.linalg.norm(fresh.normals, axis=1), 1.0)
