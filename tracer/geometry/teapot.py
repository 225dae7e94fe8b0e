"""The Utah teapot, as GLUT's ``glutSolidTeapot(1.0)`` draws it, as a triangle mesh.

Data: GLUT's condensed form of Newell's teapot, 127 control points and 10 bicubic Bezier patches of 16
control-point indices each (rim, two body patches, two lid patches, bottom, two handle patches, two spout
patches).  (Newell's original table lists 306 control points for 32 patches; GLUT stores only the quarter
or half it needs and mirrors it.)  GLUT draws each patch as given (``p``), mirrored in y with its columns
reversed (``q``), and the first six patches (rim, body, lid, bottom) also mirrored in x with the columns
reversed (``r``) and mirrored in both x and y (``s``): 6 * 4 + 4 * 2 = 32 patches.  Column reversal keeps every
mirrored copy wound the same way as the original.

In the data's own frame the teapot stands on z = 0 with its lid knob at z = 3.15, the spout along +x and the
handle along -x.  GLUT then applies ``glRotatef(270, 1, 0, 0); glScalef(s/2, s/2, s/2);
glTranslatef(0, 0, -1.5)`` (size ``s`` = 1 here), so a data point (x, y, z) lands at

    (X, Y, Z) = (0.5 x, 0.5 (z - 1.5), -0.5 y)

i.e. the teapot stands up along +Y, spout towards +X, handle towards -X.  The bounding box of the surface is

    X in [-1.5, 1.7170376]   (handle outer edge x = -3; spout lip, the maximum of the cubic with
                              coefficients 3.3, 3.525, 3.45, 3.2 at t ~ 0.41, is x ~ 3.4340751)
    Y in [-0.75, 0.825]      (bottom centre z = 0; lid knob z = 3.15)
    Z in [-1, 1]             (body radius 2)

Every extreme except the spout's is a patch corner, so the mesh reaches it exactly at any ``divisions``; the
mesh's +X extent approaches 1.7170376 from below as ``divisions`` grows (1.7165772 at the default 8).

Each patch is evaluated on a ``(divisions + 1)^2`` grid of (u, v); P_u x P_v points outwards on every patch
of this data set, so the triangles (u0 v0, u1 v0, u1 v1) and (u0 v0, u1 v1, u0 v1) wind counter-clockwise
seen from outside.  Normals come from the patch derivatives.  At the lid knob and the bottom centre a whole
row of control points collapses to one point and P_u vanishes; there P_u is replaced by the mixed derivative
P_uv (P_u ~ v P_uv near v = 0), which gives the limiting normal.  Coincident vertices along patch seams are
welded and their normals averaged; triangles that collapse (at the two poles) are dropped.  What stays open
is what the data leaves open: the spout's mouth and its base inside the body, the handle's two ends inside the
body, and the annular gap between the lid's edge (radius 1.3) and the rim's inner edge (radius 1.4), i.e.
16 boundary curves, ``16 * divisions`` boundary edges.
"""
from __future__ import annotations

from functools import lru_cache
from itertools import product

import numpy as np

from ..errors import SceneError
from ..meshdata import MeshData

#: GLUT's teapot control points (x, y, z), data frame (z up).
CONTROL_POINTS: tuple[tuple[float, float, float], ...] = (
    # 0-3: lid, inner ring near the knob
    (0.2, 0.0, 2.7), (0.2, -0.112, 2.7), (0.112, -0.2, 2.7), (0.0, -0.2, 2.7),
    # 4-15: rim
    (1.3375, 0.0, 2.53125), (1.3375, -0.749, 2.53125), (0.749, -1.3375, 2.53125), (0.0, -1.3375, 2.53125),
    (1.4375, 0.0, 2.53125), (1.4375, -0.805, 2.53125), (0.805, -1.4375, 2.53125), (0.0, -1.4375, 2.53125),
    (1.5, 0.0, 2.4), (1.5, -0.84, 2.4), (0.84, -1.5, 2.4), (0.0, -1.5, 2.4),
    # 16-40: body (28 is used by the handle)
    (1.75, 0.0, 1.875), (1.75, -0.98, 1.875), (0.98, -1.75, 1.875), (0.0, -1.75, 1.875),
    (2.0, 0.0, 1.35), (2.0, -1.12, 1.35), (1.12, -2.0, 1.35), (0.0, -2.0, 1.35),
    (2.0, 0.0, 0.9), (2.0, -1.12, 0.9), (1.12, -2.0, 0.9), (0.0, -2.0, 0.9),
    (-2.0, 0.0, 0.9),
    (2.0, 0.0, 0.45), (2.0, -1.12, 0.45), (1.12, -2.0, 0.45), (0.0, -2.0, 0.45),
    (1.5, 0.0, 0.225), (1.5, -0.84, 0.225), (0.84, -1.5, 0.225), (0.0, -1.5, 0.225),
    (1.5, 0.0, 0.15), (1.5, -0.84, 0.15), (0.84, -1.5, 0.15), (0.0, -1.5, 0.15),
    # 41-67: handle
    (-1.6, 0.0, 2.025), (-1.6, -0.3, 2.025), (-1.5, -0.3, 2.25), (-1.5, 0.0, 2.25),
    (-2.3, 0.0, 2.025), (-2.3, -0.3, 2.025), (-2.5, -0.3, 2.25), (-2.5, 0.0, 2.25),
    (-2.7, 0.0, 2.025), (-2.7, -0.3, 2.025), (-3.0, -0.3, 2.25), (-3.0, 0.0, 2.25),
    (-2.7, 0.0, 1.8), (-2.7, -0.3, 1.8), (-3.0, -0.3, 1.8), (-3.0, 0.0, 1.8),
    (-2.7, 0.0, 1.575), (-2.7, -0.3, 1.575), (-3.0, -0.3, 1.35), (-3.0, 0.0, 1.35),
    (-2.5, 0.0, 1.125), (-2.5, -0.3, 1.125), (-2.65, -0.3, 0.9375), (-2.65, 0.0, 0.9375),
    (-2.0, -0.3, 0.9), (-1.9, -0.3, 0.6), (-1.9, 0.0, 0.6),
    # 68-95: spout
    (1.7, 0.0, 1.425), (1.7, -0.66, 1.425), (1.7, -0.66, 0.6), (1.7, 0.0, 0.6),
    (2.6, 0.0, 1.425), (2.6, -0.66, 1.425), (3.1, -0.66, 0.825), (3.1, 0.0, 0.825),
    (2.3, 0.0, 2.1), (2.3, -0.25, 2.1), (2.4, -0.25, 2.025), (2.4, 0.0, 2.025),
    (2.7, 0.0, 2.4), (2.7, -0.25, 2.4), (3.3, -0.25, 2.4), (3.3, 0.0, 2.4),
    (2.8, 0.0, 2.475), (2.8, -0.25, 2.475), (3.525, -0.25, 2.49375), (3.525, 0.0, 2.49375),
    (2.9, 0.0, 2.475), (2.9, -0.15, 2.475), (3.45, -0.15, 2.5125), (3.45, 0.0, 2.5125),
    (2.8, 0.0, 2.4), (2.8, -0.15, 2.4), (3.2, -0.15, 2.4), (3.2, 0.0, 2.4),
    # 96-101: lid knob
    (0.0, 0.0, 3.15), (0.8, 0.0, 3.15), (0.8, -0.45, 3.15), (0.45, -0.8, 3.15), (0.0, -0.8, 3.15),
    (0.0, 0.0, 2.85),
    # 102-105: rim, inner edge
    (1.4, 0.0, 2.4), (1.4, -0.784, 2.4), (0.784, -1.4, 2.4), (0.0, -1.4, 2.4),
    # 106-117: lid, outer part
    (0.4, 0.0, 2.55), (0.4, -0.224, 2.55), (0.224, -0.4, 2.55), (0.0, -0.4, 2.55),
    (1.3, 0.0, 2.55), (1.3, -0.728, 2.55), (0.728, -1.3, 2.55), (0.0, -1.3, 2.55),
    (1.3, 0.0, 2.4), (1.3, -0.728, 2.4), (0.728, -1.3, 2.4), (0.0, -1.3, 2.4),
    # 118-126: bottom
    (0.0, 0.0, 0.0), (1.425, -0.798, 0.0), (1.5, 0.0, 0.075), (1.425, 0.0, 0.0),
    (0.798, -1.425, 0.0), (0.0, -1.5, 0.075), (0.0, -1.425, 0.0), (1.5, -0.84, 0.075),
    (0.84, -1.5, 0.075),
)

#: GLUT's 10 patches: 16 indices into CONTROL_POINTS each, row-major (4 rows j of 4 columns k); u runs along
#: a row (k), v down the rows (j).
PATCHES: tuple[tuple[int, ...], ...] = (
    (102, 103, 104, 105, 4, 5, 6, 7, 8, 9, 10, 11, 12, 13, 14, 15),  # rim
    (12, 13, 14, 15, 16, 17, 18, 19, 20, 21, 22, 23, 24, 25, 26, 27),  # body, upper
    (24, 25, 26, 27, 29, 30, 31, 32, 33, 34, 35, 36, 37, 38, 39, 40),  # body, lower
    (96, 96, 96, 96, 97, 98, 99, 100, 101, 101, 101, 101, 0, 1, 2, 3),  # lid, knob
    (0, 1, 2, 3, 106, 107, 108, 109, 110, 111, 112, 113, 114, 115, 116, 117),  # lid, outer
    (118, 118, 118, 118, 124, 122, 119, 121, 123, 126, 125, 120, 40, 39, 38, 37),  # bottom
    (41, 42, 43, 44, 45, 46, 47, 48, 49, 50, 51, 52, 53, 54, 55, 56),  # handle, upper
    (53, 54, 55, 56, 57, 58, 59, 60, 61, 62, 63, 64, 28, 65, 66, 67),  # handle, lower
    (68, 69, 70, 71, 72, 73, 74, 75, 76, 77, 78, 79, 80, 81, 82, 83),  # spout, base
    (80, 81, 82, 83, 84, 85, 86, 87, 88, 89, 90, 91, 92, 93, 94, 95),  # spout, tip
)

#: The first this many patches (rim, body, lid, bottom) are mirrored four ways, the rest two ways.
FOUR_WAY_PATCHES = 6

#: Data frame -> GLUT's frame for size 1: X = 0.5 x, Y = 0.5 (z - 1.5), Z = -0.5 y.
TRANSFORM = np.array([
    [0.5, 0.0, 0.0, 0.0],
    [0.0, 0.0, 0.5, -0.75],
    [0.0, -0.5, 0.0, 0.0],
    [0.0, 0.0, 0.0, 1.0],
])

#: The exact bounding box of the (size 1) surface, (min corner, max corner); see the module docstring.
SPOUT_MAX_X = 3.4340751254710953  # data frame; checked in the tests from the cubic's stationary point
BOUNDING_BOX = (np.array([-1.5, -0.75, -1.0]), np.array([0.5 * SPOUT_MAX_X, 0.825, 1.0]))


def expanded_patches() -> np.ndarray:
    """The 32 control nets GLUT draws, in the data frame: (32, 4, 4, 3), indexed [patch, row j, column k]."""
    cp = np.asarray(CONTROL_POINTS, dtype=np.float64)
    nets = []
    for number, indices in enumerate(PATCHES):
        p = cp[np.asarray(indices)].reshape(4, 4, 3)
        reversed_cols = p[:, ::-1, :]
        nets.append(p)
        nets.append(reversed_cols * np.array([1.0, -1.0, 1.0]))  # q: mirrored in y
        if number < FOUR_WAY_PATCHES:
            nets.append(reversed_cols * np.array([-1.0, 1.0, 1.0]))  # r: mirrored in x
            nets.append(p * np.array([-1.0, -1.0, 1.0]))  # s: mirrored in x and y
    return np.array(nets)


def _bernstein(t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cubic Bernstein values and derivatives at parameters t: two (len(t), 4) arrays."""
    s = 1.0 - t
    values = np.stack([s ** 3, 3.0 * t * s ** 2, 3.0 * t ** 2 * s, t ** 3], axis=1)
    derivs = np.stack([-3.0 * s ** 2, 3.0 * s ** 2 - 6.0 * t * s, 6.0 * t * s - 3.0 * t ** 2, 3.0 * t ** 2], axis=1)
    return values, derivs


def _evaluate(net: np.ndarray, params: np.ndarray):
    """Points, P_u, P_v and P_uv of one patch on the grid params x params: each (n, n, 3), indexed [v, u]."""
    b, db = _bernstein(params)
    point = np.einsum("vj,uk,jkc->vuc", b, b, net)
    du = np.einsum("vj,uk,jkc->vuc", b, db, net)
    dv = np.einsum("vj,uk,jkc->vuc", db, b, net)
    duv = np.einsum("vj,uk,jkc->vuc", db, db, net)
    return point, du, dv, duv


def _patch_normals(net: np.ndarray, params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Grid points and unit normals (P_u x P_v, with the pole fix-up) of one patch, in the data frame."""
    point, du, dv, duv = _evaluate(net, params)
    scale = max(1.0, float(np.max(np.abs(net))))
    tiny = 1e-9 * scale
    u = params[None, :, None]
    v = params[:, None, None]
    # Where a derivative vanishes (a collapsed row or column of the net), P_u ~ (v - v0) P_uv near it:
    # use P_uv, signed so that it points the way P_u does just inside the patch.
    du_small = np.linalg.norm(du, axis=2, keepdims=True) < tiny
    dv_small = np.linalg.norm(dv, axis=2, keepdims=True) < tiny
    du = np.where(du_small, np.where(v < 0.5, duv, -duv), du)
    dv = np.where(dv_small, np.where(u < 0.5, duv, -duv), dv)
    normal = np.cross(du, dv)
    length = np.linalg.norm(normal, axis=2, keepdims=True)
    bad = length[..., 0] < tiny * tiny
    if np.any(bad):
        # Still degenerate: take the normal of a sample nudged towards the patch centre.
        rows, cols = np.nonzero(bad)
        for j, k in zip(rows, cols):
            uu = params[k] + (1e-4 if params[k] < 0.5 else -1e-4)
            vv = params[j] + (1e-4 if params[j] < 0.5 else -1e-4)
            _, pu, pv, _ = _evaluate(net, np.array([vv, uu]))
            normal[j, k] = np.cross(pu[0, 1], pv[0, 1])  # [v index 0 = vv, u index 1 = uu]
        length = np.linalg.norm(normal, axis=2, keepdims=True)
    return point, normal / np.maximum(length, 1e-300)


def _weld(points: np.ndarray, tol: float) -> tuple[np.ndarray, np.ndarray]:
    """Merge points closer than ``tol`` (in every coordinate).

    Returns the indices of the kept representatives and, for every point, the number of its representative.
    Points are bucketed in cells much larger than ``tol``; only a point within ``tol`` of a cell wall needs
    to look into the neighbouring cell too.
    """
    cell = 1000.0 * tol
    scaled = points / cell
    keys = np.floor(scaled).astype(np.int64)
    frac = scaled - keys
    margin = tol / cell
    low, high = frac < margin, frac > 1.0 - margin
    buckets: dict[tuple[int, int, int], list[int]] = {}
    reps: list[int] = []
    remap = np.empty(len(points), dtype=np.int64)
    for i, key in enumerate(map(tuple, keys.tolist())):
        steps = [(0,) + ((-1,) if low[i, a] else ()) + ((1,) if high[i, a] else ()) for a in range(3)]
        found = next((r for step in product(*steps)
                      for r in buckets.get((key[0] + step[0], key[1] + step[1], key[2] + step[2]), ())
                      if np.max(np.abs(points[reps[r]] - points[i])) <= tol), -1)
        if found < 0:
            found = len(reps)
            reps.append(i)
            buckets.setdefault(key, []).append(found)
        remap[i] = found
    return np.asarray(reps, dtype=np.int64), remap


@lru_cache(maxsize=16)
def _build(divisions: int):
    params = np.linspace(0.0, 1.0, divisions + 1)
    n = divisions + 1
    all_points, all_normals, triangles = [], [], []
    grid = np.arange(n * n).reshape(n, n)  # [v, u]
    v00, v10 = grid[:-1, :-1].ravel(), grid[:-1, 1:].ravel()
    v01, v11 = grid[1:, :-1].ravel(), grid[1:, 1:].ravel()
    local = np.concatenate([np.stack([v00, v10, v11], axis=1), np.stack([v00, v11, v01], axis=1)])
    for number, net in enumerate(expanded_patches()):
        point, normal = _patch_normals(net, params)
        all_points.append(point.reshape(-1, 3))
        all_normals.append(normal.reshape(-1, 3))
        triangles.append(local + number * n * n)
    points = np.concatenate(all_points)
    normals = np.concatenate(all_normals)
    tris = np.concatenate(triangles)

    # To GLUT's frame: the linear part is a rotation times 0.5, so normals just rotate.
    linear = TRANSFORM[:3, :3]
    points = points @ linear.T + TRANSFORM[:3, 3]
    normals = normals @ (linear / 0.5).T

    reps, remap = _weld(points, 1e-9)
    vertices = points[reps]
    summed = np.zeros_like(vertices)
    np.add.at(summed, remap, normals)
    vertex_normals = summed / np.linalg.norm(summed, axis=1, keepdims=True)
    tris = remap[tris]

    distinct = (tris[:, 0] != tris[:, 1]) & (tris[:, 1] != tris[:, 2]) & (tris[:, 0] != tris[:, 2])
    tris = tris[distinct]
    a, b, c = vertices[tris[:, 0]], vertices[tris[:, 1]], vertices[tris[:, 2]]
    area2 = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    tris = tris[area2 > 1e-14]
    for arr in (vertices, vertex_normals, tris):
        arr.flags.writeable = False
    return vertices, vertex_normals, tris


def teapot_mesh(divisions: int = 8) -> MeshData:
    """GLUT's solid teapot of size 1 as triangles: each of its 32 Bezier patches on a (divisions+1)^2 grid.

    Vertices are welded along the seams, normals are smooth per-vertex normals (normal index = vertex index).
    See the module docstring for the frame and the bounding box.
    """
    if isinstance(divisions, bool) or not isinstance(divisions, (int, np.integer)) or divisions < 1:
        raise SceneError(f"teapot divisions must be a positive integer, not {divisions!r}")
    vertices, normals, tris = _build(int(divisions))
    faces = [(t, t) for t in map(tuple, tris.tolist())]
    return MeshData(vertices=vertices.copy(), normals=normals.copy(), faces=faces, origin="built-in:teapot")
