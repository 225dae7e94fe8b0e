"""The built-in convex polyhedra (the book loads them from ``.3vn`` files).

Every solid is centred at the origin.  The five regular/semi-regular ones have circumradius 1 (every vertex
lies on the unit sphere):

``tetrahedron``   4 vertices,  6 edges,  4 triangles
``octahedron``    6 vertices, 12 edges,  8 triangles
``dodecahedron`` 20 vertices, 30 edges, 12 pentagons
``icosahedron``  12 vertices, 30 edges, 20 triangles
``buckyball``    60 vertices, 90 edges, 32 faces (12 pentagons, 20 hexagons): the truncated icosahedron,
                 made by cutting every edge of the icosahedron into thirds and keeping the middle third.

``diamond`` is a convex round-brilliant-like gem (8-fold symmetric about the +y axis, table up), with the
classical Tolkowsky proportions given in units of the girdle radius ``R``:

* table: a regular octagon of circumradius ``0.53 R`` (corners at azimuths 0, 45, ..., 315 degrees,
  azimuth measured in the x-z plane from +x towards +z), ``0.344 R`` above the girdle's middle plane;
* crown (height ``0.324 R`` from the girdle top to the table): 8 *star* triangles on the table edges, whose
  tips reach half-way down the crown at the mid azimuths (22.5 + 45 k degrees); 8 planar *bezel* kites
  (table corner, two star tips, girdle point below the table corner); 16 *upper girdle* triangles;
* girdle: a 16-sided prism ``0.04 R`` thick (16 vertical rectangles, corners every 22.5 degrees, radius R);
* pavilion (depth ``0.862 R`` below the girdle bottom, down to the culet point on the -y axis): 8 planar
  *pavilion main* kites (culet, two lower-girdle tips, girdle point) and 16 *lower girdle* triangles; the
  lower-girdle tips sit at the mid azimuths, 77.5 % of the way from the culet up to the girdle.

Facet slopes (angle to the table plane): star 25.6, bezel 34.6 (the crown angle), upper girdle 43.9, pavilion
main 40.8 (the pavilion angle), lower girdle 50.8 degrees; girdle facets are vertical.

The origin is the centre of the girdle, and ``R = 1 / sqrt(1 + 0.02**2)`` so that the 32 girdle corners lie
on the unit sphere; the table is at ``y = 0.344 R ~ 0.344`` and the culet at ``y = -0.882 R ~ -0.882``, so the
whole gem fits in the unit sphere.  It has 57 vertices, 128 edges and 73 faces: 1 octagon, 32 quadrilaterals
(8 bezel kites, 8 pavilion kites, 16 girdle rectangles) and 40 triangles (8 stars, 16 upper and 16 lower
girdle facets).

Faces are the polygons of the solid, not triangulated, with their vertices counter-clockwise seen from outside,
and one unit outward normal per face (each face's normal indices all point at its own normal).  They are found
as the facets of the convex hull of the vertices, so every face is planar and the solid is convex by
construction; :func:`face_planes` gives the planes ``n . p <= offset`` for Cyrus-Beck clipping.
"""
from __future__ import annotations

from functools import lru_cache
from itertools import combinations

import numpy as np

from ..errors import SceneError
from ..meshdata import MeshData
from ..shapes import keywords

POLYHEDRON_KINDS = keywords("polyhedron")

_PHI = (1.0 + 5.0 ** 0.5) / 2.0

# Diamond proportions, in units of the girdle radius R (see the module docstring).
DIAMOND_TABLE_RADIUS = 0.53
DIAMOND_CROWN_HEIGHT = 0.324
DIAMOND_GIRDLE_THICKNESS = 0.04
DIAMOND_PAVILION_DEPTH = 0.862
DIAMOND_STAR_FRACTION = 0.5  # star tips: this fraction of the way down from the table to the girdle
DIAMOND_LOWER_GIRDLE_FRACTION = 0.775  # lower-girdle tips: this fraction of the way up from culet to girdle
DIAMOND_GIRDLE_RADIUS = 1.0 / np.sqrt(1.0 + (DIAMOND_GIRDLE_THICKNESS / 2.0) ** 2)


def _normalise_rows(points: np.ndarray) -> np.ndarray:
    return points / np.linalg.norm(points, axis=1, keepdims=True)


def _cyclic(triples) -> list[tuple[float, float, float]]:
    """Each (a, b, c) and its cyclic shifts (b, c, a), (c, a, b)."""
    out = []
    for a, b, c in triples:
        out += [(a, b, c), (b, c, a), (c, a, b)]
    return out


def _signs(values: tuple[float, ...]) -> list[tuple[float, ...]]:
    """Every sign combination of the non-zero entries of ``values`` (zeros stay single)."""
    results: list[tuple[float, ...]] = [()]
    for v in values:
        choices = (v,) if v == 0 else (v, -v)
        results = [r + (c,) for r in results for c in choices]
    return results


def _tetrahedron() -> np.ndarray:
    return _normalise_rows(np.array([(1, 1, 1), (1, -1, -1), (-1, 1, -1), (-1, -1, 1)], dtype=float))


def _octahedron() -> np.ndarray:
    return np.array([(1, 0, 0), (-1, 0, 0), (0, 1, 0), (0, -1, 0), (0, 0, 1), (0, 0, -1)], dtype=float)


def _icosahedron() -> np.ndarray:
    pts = _cyclic(_signs((0.0, 1.0, _PHI)))
    return _normalise_rows(np.array(pts, dtype=float))


def _dodecahedron() -> np.ndarray:
    pts = _signs((1.0, 1.0, 1.0)) + _cyclic(_signs((0.0, 1.0 / _PHI, _PHI)))
    return _normalise_rows(np.array(pts, dtype=float))


def _buckyball() -> np.ndarray:
    ico = _icosahedron()
    d = np.linalg.norm(ico[:, None, :] - ico[None, :, :], axis=2)
    edge = np.min(d[d > 1e-9])
    pts = []
    for i, j in combinations(range(len(ico)), 2):
        if abs(d[i, j] - edge) < 1e-9 * edge + 1e-12:
            a, b = ico[i], ico[j]
            pts.append(a + (b - a) / 3.0)
            pts.append(b + (a - b) / 3.0)
    return _normalise_rows(np.array(pts, dtype=float))


def _ring(count: int, radius: float, y: float, start_degrees: float) -> np.ndarray:
    angles = np.radians(start_degrees + 360.0 / count * np.arange(count))
    return np.column_stack([radius * np.cos(angles), np.full(count, y), radius * np.sin(angles)])


def _diamond() -> np.ndarray:
    r = DIAMOND_GIRDLE_RADIUS
    half = DIAMOND_GIRDLE_THICKNESS / 2.0 * r
    girdle_top, girdle_bottom = half, -half
    table_y = girdle_top + DIAMOND_CROWN_HEIGHT * r
    table_r = DIAMOND_TABLE_RADIUS * r
    culet_y = girdle_bottom - DIAMOND_PAVILION_DEPTH * r
    cos_half = np.cos(np.radians(22.5))
    # Star tips: on the bezel kites' plane, i.e. the midpoint of two neighbouring star tips (at the main
    # azimuth, radius r_s cos 22.5) lies on the line from the table corner down to the girdle point.
    star_y = table_y - DIAMOND_STAR_FRACTION * (table_y - girdle_top)
    star_mid_r = table_r + (r - table_r) * (table_y - star_y) / (table_y - girdle_top)
    # Lower-girdle tips: likewise on the line from the culet to the girdle-bottom point below them.
    lower_y = culet_y + DIAMOND_LOWER_GIRDLE_FRACTION * (girdle_bottom - culet_y)
    lower_mid_r = r * (lower_y - culet_y) / (girdle_bottom - culet_y)
    parts = [
        _ring(8, table_r, table_y, 0.0),
        _ring(8, star_mid_r / cos_half, star_y, 22.5),
        _ring(16, r, girdle_top, 0.0),
        _ring(16, r, girdle_bottom, 0.0),
        _ring(8, lower_mid_r / cos_half, lower_y, 22.5),
        np.array([[0.0, culet_y, 0.0]]),
    ]
    return np.vstack(parts)


_BUILDERS = {
    "tetrahedron": _tetrahedron,
    "octahedron": _octahedron,
    "dodecahedron": _dodecahedron,
    "icosahedron": _icosahedron,
    "buckyball": _buckyball,
    "diamond": _diamond,
}
assert set(_BUILDERS) == set(POLYHEDRON_KINDS)


def _hull_faces(points: np.ndarray, tol: float = 1e-9):
    """Facets of the convex hull of ``points`` (which must contain the origin strictly inside).

    Returns a list of (vertex indices counter-clockwise from outside, unit outward normal, offset).  Every
    triple of points spans a candidate plane; the planes with every point on their inner side are facets, and
    all points on such a plane (within ``tol``) are that facet's vertices.
    """
    n_pts = len(points)
    triples = np.array(list(combinations(range(n_pts), 3)), dtype=np.int64)
    a, b, c = points[triples[:, 0]], points[triples[:, 1]], points[triples[:, 2]]
    normals = np.cross(b - a, c - a)
    lengths = np.linalg.norm(normals, axis=1)
    keep = lengths > tol
    triples, normals, a = triples[keep], normals[keep] / lengths[keep, None], a[keep]
    offsets = np.einsum("ij,ij->i", normals, a)
    flip = offsets < 0
    normals[flip] *= -1.0
    offsets[flip] *= -1.0
    heights = normals @ points.T - offsets[:, None]  # (candidates, points)
    supporting = np.all(heights <= tol, axis=1)
    faces = []
    seen: set[tuple[int, ...]] = set()
    for normal, offset, h in zip(normals[supporting], offsets[supporting], heights[supporting]):
        members = np.flatnonzero(np.abs(h) <= tol)
        key = tuple(members.tolist())
        if key in seen:
            continue
        seen.add(key)
        centre = points[members].mean(axis=0)
        e1 = points[members[0]] - centre
        e1 /= np.linalg.norm(e1)
        e2 = np.cross(normal, e1)
        rel = points[members] - centre
        angles = np.arctan2(rel @ e2, rel @ e1)
        ordered = members[np.argsort(angles)]
        # Refit the plane to all of the face's vertices (Newell's method) for a clean normal and offset.
        poly = points[ordered]
        newell = np.sum(np.cross(poly, np.roll(poly, -1, axis=0)), axis=0)
        unit = newell / np.linalg.norm(newell)
        faces.append((tuple(int(i) for i in ordered), unit, float(np.mean(poly @ unit))))
    return faces


@lru_cache(maxsize=None)
def _build(kind: str):
    if kind not in _BUILDERS:
        raise SceneError(f"unknown polyhedron {kind!r}; expected one of {', '.join(POLYHEDRON_KINDS)}")
    vertices = _BUILDERS[kind]()
    faces = _hull_faces(vertices)
    if len({i for f, _, _ in faces for i in f}) != len(vertices):  # pragma: no cover - construction check
        raise AssertionError(f"{kind}: some vertices are not on the hull")
    normals = np.array([n for _, n, _ in faces])
    offsets = np.array([d for _, _, d in faces])
    face_list = [(verts, (k,) * len(verts)) for k, (verts, _, _) in enumerate(faces)]
    for arr in (vertices, normals, offsets):
        arr.flags.writeable = False
    return vertices, normals, offsets, tuple(face_list)


def polyhedron_mesh(kind: str) -> MeshData:
    """The built-in polyhedron ``kind`` (one of :data:`tracer.model.POLYHEDRON_KINDS`) as a fresh MeshData."""
    vertices, normals, _, faces = _build(kind)
    return MeshData(vertices=vertices.copy(), normals=normals.copy(), faces=list(faces),
                    origin=f"built-in:{kind}")


def face_planes(kind: str) -> tuple[np.ndarray, np.ndarray]:
    """The face planes of polyhedron ``kind``: unit outward normals (F, 3) and offsets (F,).

    A point ``p`` is inside (or on) the solid exactly when ``normals @ p <= offsets`` for every face; row k
    belongs to ``polyhedron_mesh(kind).faces[k]``.
    """
    _, normals, offsets, _ = _build(kind)
    return normals.copy(), offsets.copy()
