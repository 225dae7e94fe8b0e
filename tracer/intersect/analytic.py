"""Rays against the closed-form generic shapes, in generic coordinates, vectorised over rays.

Each function takes origins and directions of shape (N, 3) and returns :class:`HitArrays` with every
crossing of the *whole line*.  The generic shapes (SDL.md):

* sphere: ``|p| = 1``;  cube: ``[-1, 1]^3``;  square: ``z = 0, |x|, |y| <= 1`` (no inside: a thin sheet);
* plane: ``z = 0``, the boundary of the half-space ``z <= 0`` (its inside, for CSG);
* tapered cylinder with top radius s: wall ``x^2 + y^2 = (1 + (s - 1) z)^2`` for ``0 <= z <= 1``, base disc
  at z = 0 (radius 1) and cap disc at z = 1 (radius s);
* convex polyhedra: intersection of half-spaces ``n . p <= d`` (Cyrus–Beck clipping).
"""
from __future__ import annotations

import numpy as np

from ..numerics import TOLERANCES, Tolerances, crossing_shift, dot3, gamma
from .hits import HitArrays
from .quadratic import solve_quadratic


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return dot3(a, b)  # (summed as the C core sums)


def _two_hits(t_in, t_out, n_in, n_out, part_in, part_out, hit) -> HitArrays:
    """Pack one entering and one exiting hit per ray (where ``hit``) into a 2-slot HitArrays."""
    n = t_in.shape[0]
    out = HitArrays.empty(n, 2)
    out.t[:, 0] = np.where(hit, t_in, np.inf)
    out.t[:, 1] = np.where(hit, t_out, np.inf)
    out.entering[:, 0] = hit
    out.normal[:, 0] = np.where(hit[:, None], n_in, 0.0)
    out.normal[:, 1] = np.where(hit[:, None], n_out, 0.0)
    out.part[:, 0] = np.where(hit, part_in, -1)
    out.part[:, 1] = np.where(hit, part_out, -1)
    return out


def intersect_sphere(origin: np.ndarray, direction: np.ndarray) -> HitArrays:
    """The unit sphere: roots ``-b/a -+ sqrt(disc)/a`` about the line's point nearest the centre.

    The caller has moved the origin there, so ``b`` is rounding noise and ``-b/a`` never cancels; the
    half chord comes from the distance of that point to the centre, ``disc = a (1 - |o_perp|^2)``.  The
    ``c/q`` form of the general quadratic would divide one noise term by another at tangency.
    """
    a = _dot(direction, direction)
    b = _dot(origin, direction)
    with np.errstate(divide="ignore", invalid="ignore"):
        mid = -(b / a)
        perp = origin + mid[:, None] * direction
        disc = a * (1.0 - _dot(perp, perp))
        hit = (disc >= 0.0) & (a > 0.0) & np.isfinite(mid)
        half = np.sqrt(np.where(hit, disc, 0.0)) / a
    t_lo = np.where(hit, mid - half, np.nan)
    t_hi = np.where(hit, mid + half, np.nan)
    p_lo = origin + np.nan_to_num(t_lo)[:, None] * direction
    p_hi = origin + np.nan_to_num(t_hi)[:, None] * direction
    out = _two_hits(t_lo, t_hi, p_lo, p_hi, 0, 0, hit)
    out.bend = np.repeat(np.where(hit, a, 0.0)[:, None], 2, axis=1)  # G = (|p|^2 - 1) / 2: n = p, G'' = |d|^2
    return out


def agree_with_crossing(hits: HitArrays, direction: np.ndarray) -> None:
    """Make each normal agree with its entering flag (n . d <= 0 entering, >= 0 leaving), in place.

    Where a shape is nearly degenerate (scaled by 1e-9 along one axis) or the ray grazes it, the computed
    normal can lean, by rounding, to the wrong side of the ray; its component along the ray is then
    removed, which is the least change that makes it a normal of a grazing crossing.
    """
    along = dot3(hits.normal, direction[:, None, :])  # (summed as the C core sums)
    wrong = np.isfinite(hits.t) & np.where(hits.entering, along > 0.0, along < 0.0)
    if wrong.any():
        speed2 = dot3(direction, direction)
        hits.normal -= np.where(wrong, along / speed2[:, None], 0.0)[..., None] * direction[:, None, :]


def _slab_interval(o: np.ndarray, d: np.ndarray, lo: float, hi: float):
    """Entry and exit parameters of a line with the slab lo <= x <= hi (±inf for parallel lines)."""
    with np.errstate(divide="ignore", invalid="ignore"):
        t_a = (lo - o) / d
        t_b = (hi - o) / d
    parallel = d == 0.0
    inside = (o >= lo) & (o <= hi)
    near = np.where(parallel, np.where(inside, -np.inf, np.inf), np.fmin(t_a, t_b))
    far = np.where(parallel, np.where(inside, np.inf, -np.inf), np.fmax(t_a, t_b))
    return near, far


def intersect_cube(origin: np.ndarray, direction: np.ndarray) -> HitArrays:
    near, far = _slab_interval(origin, direction, -1.0, 1.0)  # (N, 3) each
    axis_in = np.argmax(near, axis=1)
    axis_out = np.argmin(far, axis=1)
    rows = np.arange(origin.shape[0])
    t_in = near[rows, axis_in]
    t_out = far[rows, axis_out]
    hit = (t_in <= t_out) & np.isfinite(t_in) & np.isfinite(t_out)
    sign = np.sign(direction)
    n_in = np.zeros_like(origin)
    n_out = np.zeros_like(origin)
    n_in[rows, axis_in] = -sign[rows, axis_in]
    n_out[rows, axis_out] = sign[rows, axis_out]
    # Faces numbered 2*axis + (1 on the + side): the entering face is on the - side when d > 0.
    part_in = 2 * axis_in + (sign[rows, axis_in] < 0)
    part_out = 2 * axis_out + (sign[rows, axis_out] > 0)
    return _two_hits(t_in, t_out, n_in, n_out, part_in, part_out, hit)


def _z_plane_crossing(origin: np.ndarray, direction: np.ndarray, z: float = 0.0):
    dz = direction[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (z - origin[:, 2]) / dz
    crosses = dz != 0.0
    point = origin + np.where(crosses, t, 0.0)[:, None] * direction
    return np.where(crosses, t, np.nan), crosses, point


def _one_hit(t, hit, entering, normal, part=0) -> HitArrays:
    out = HitArrays.empty(t.shape[0], 1)
    out.t[:, 0] = np.where(hit, t, np.inf)
    out.entering[:, 0] = hit & entering
    out.normal[:, 0] = np.where(hit[:, None], normal, 0.0)
    out.part[:, 0] = np.where(hit, part, -1)
    return out


def intersect_square(origin: np.ndarray, direction: np.ndarray, tol: Tolerances = TOLERANCES) -> HitArrays:
    """Crossings ``tol.square_edge`` (relative) outside the rim still count, so that edges do not leak."""
    t, crosses, p = _z_plane_crossing(origin, direction)
    limit = 1.0 + tol.square_edge
    hit = crosses & (np.abs(p[:, 0]) <= limit) & (np.abs(p[:, 1]) <= limit)
    out = _one_hit(t, hit, direction[:, 2] < 0.0, np.array([0.0, 0.0, 1.0]))
    out.uv[:, 0] = np.where(hit[:, None], p[:, :2], 0.0)
    return out


def intersect_plane(origin: np.ndarray, direction: np.ndarray) -> HitArrays:
    t, crosses, p = _z_plane_crossing(origin, direction)
    out = _one_hit(t, crosses, direction[:, 2] < 0.0, np.array([0.0, 0.0, 1.0]))
    out.uv[:, 0] = np.where(crosses[:, None], p[:, :2], 0.0)
    # The half-space z <= 0 holds the line at t = -inf when it rises, or when it runs inside, parallel.
    dz = direction[:, 2]
    out.inside_at_start = (dz > 0.0) | ((dz == 0.0) & (origin[:, 2] < 0.0))
    return out


def _convex_hits(candidates_t: np.ndarray, candidates_n: np.ndarray, valid: np.ndarray) -> HitArrays:
    """A convex solid is entered at its first valid crossing and left at its last."""
    t_min = np.where(valid, candidates_t, np.inf)
    t_max = np.where(valid, candidates_t, -np.inf)
    i_in = np.argmin(t_min, axis=1)
    i_out = np.argmax(t_max, axis=1)
    rows = np.arange(candidates_t.shape[0])
    hit = valid.any(axis=1)
    return _two_hits(t_min[rows, i_in], t_max[rows, i_out], candidates_n[rows, i_in],
                     candidates_n[rows, i_out], i_in, i_out, hit)


def tapered_cylinder_normal(points: np.ndarray, small_radius: float) -> np.ndarray:
    """Outward normal of the wall at the azimuth of (N, 3) points, scaled by their distance rho from the axis:
    (x, y, -k rho), the gradient of G = (x^2 + y^2 - (1 + k z)^2) / 2 at the wall point of that azimuth and
    height.  Every point of a generator has the same normal, so it is known however far the point is off
    the wall along it (near a cone's apex 1 - z cancels); on the axis itself the axis is the only sensible
    direction."""
    k = small_radius - 1.0
    rho = np.sqrt(points[:, 0] * points[:, 0] + points[:, 1] * points[:, 1])
    normal = np.stack([points[:, 0], points[:, 1], -k * rho], axis=1)
    degenerate = dot3(normal, normal) < 1e-300
    normal[degenerate] = (0.0, 0.0, 1.0)
    return normal


def wall_term_sizes(origin: np.ndarray, direction: np.ndarray, k: float):
    """The sizes of the terms of G = (x^2 + y^2 - (1 + k z)^2) / 2 along the lines, which is (a t^2 + 2 b t +
    c) / 2 with a, b, c computed from the origin: G's rounding at t is gamma times :func:`wall_terms_at`
    (shapes.h's wall_term_sizes).  (w = 1 + k z at the origin is off by its terms' size times the rounding,
    which near the apex is not small.)"""
    ox, oy, oz = origin.T
    dx, dy, dz = direction.T
    w0, terms = np.abs(1.0 + k * oz), 1.0 + np.abs(k * oz)
    return (dx * dx + dy * dy + k * k * dz * dz,
            np.abs(ox * dx) + np.abs(oy * dy) + np.abs(k * dz) * (w0 + terms),
            ox * ox + oy * oy + w0 * (w0 + 2.0 * terms))


def wall_terms_at(sizes, t: np.ndarray) -> np.ndarray:
    am, bm, cm = sizes
    at = np.abs(t)
    return 0.5 * ((am * at + 2.0 * bm) * at + cm)


def wall_error_terms(origin: np.ndarray, direction: np.ndarray, k: float, a: np.ndarray, b: np.ndarray,
                     t: np.ndarray, sizes, rounding: float):
    """(bend, own root error, residual) of wall hits at local times t (shapes.h's wall_hit).

    G bends by a; the root's own error is how far G's rounding moves it (crossing_shift of ``rounding``
    times its terms, which near a cone's apex, where |grad G| is as small as the distance to the apex, the
    point error no longer covers).  The residual is the point's distance from the wall times |n| =
    rho sqrt(1 + k^2): that of (rho, z) from the line rho = 1 + k z in the plane through the axis, or, where
    its foot (rho, z) - (rho - w) (1, -k) / (1 + k^2) is past a cone's apex, its distance from the apex."""
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        own = crossing_shift(rounding * wall_terms_at(sizes, t), np.abs(a * t + b), np.abs(a))
    p = origin + t[:, None] * direction
    rho = np.sqrt(p[:, 0] * p[:, 0] + p[:, 1] * p[:, 1])
    w = 1.0 + k * p[:, 2]
    apex = k if k != 0.0 else 1.0  # (a cylinder has no apex: its foot is never past it)
    residual = np.where(rho * k * k + w >= 0.0, np.abs(rho - w) * rho,
                        np.sqrt(rho * rho + (w / apex) * (w / apex)) * rho * np.sqrt(1.0 + k * k))
    return a, own, residual


def _wall_interval(a, b, c, slab_lo, slab_hi):
    """Where the line is inside the wall's double cone ``a t^2 + 2 b t + c <= 0``, clipped to the slab.

    The solid is this set intersected with the slab 0 <= z <= 1 (the other nappe of a cone meets the
    slab only at the apex), so entry and exit come from one interval test: a cap counts exactly where the
    wall's own inequality holds, and a line that is nearly a generator keeps its exit however its
    ill-conditioned wall root rounds.  Returns the clipped interval's ends (NaN where empty).
    """
    t_lo, t_hi, real = solve_quadratic(a, b, c)
    linear = a == 0.0
    # a >= 0 (a = 0: one root and +-inf from the quadratic's q/a): inside between the roots.
    lo = np.where(real, t_lo, np.nan)
    hi = np.where(real, t_hi, np.nan)
    flat = linear & (b == 0.0)  # no t at all: inside everywhere or nowhere
    lo = np.where(flat, np.where(c <= 0.0, -np.inf, np.nan), lo)
    hi = np.where(flat, np.where(c <= 0.0, np.inf, np.nan), hi)
    inner_lo, inner_hi = np.maximum(lo, slab_lo), np.minimum(hi, slab_hi)  # NaN (empty) wins
    # a < 0: inside outside the roots (both nappes), or everywhere when there are none.
    lower_hi = np.where(real, np.minimum(t_lo, slab_hi), slab_hi)
    upper_lo = np.where(real, np.maximum(t_hi, slab_lo), slab_lo)
    lower_len = lower_hi - slab_lo
    upper_len = slab_hi - upper_lo
    take_upper = real & (upper_len > lower_len) | ~real
    outer_lo = np.where(take_upper, upper_lo, slab_lo)
    outer_hi = np.where(take_upper, slab_hi, lower_hi)
    negative = a < 0.0
    start = np.where(negative, outer_lo, inner_lo)
    end = np.where(negative, outer_hi, inner_hi)
    with np.errstate(invalid="ignore"):
        empty = ~(start <= end)
    return np.where(empty, np.nan, start), np.where(empty, np.nan, end)


def apex_shift(origin: np.ndarray, direction: np.ndarray, k: float) -> np.ndarray:
    """How far (N,) along each line its point nearest the apex (0, 0, -1/k) of a tapered cylinder lies, where
    the apex is within two units of the base (0 elsewhere, and for lines that have none)."""
    if not abs(k) >= 0.5:
        return np.zeros(origin.shape[0])
    apart = origin + np.array([0.0, 0.0, 1.0 / k])
    with np.errstate(divide="ignore", invalid="ignore"):
        along = -dot3(apart, direction) / dot3(direction, direction)
    return np.where(np.isfinite(along), along, 0.0)


def intersect_tapered_cylinder(origin: np.ndarray, direction: np.ndarray, small_radius: float,
                               tol: Tolerances = TOLERANCES) -> HitArrays:
    """Parts: 0 wall, 1 base disc (z = 0), 2 cap disc (z = 1).

    Where the apex is within two units of the base, the line is taken from its point nearest the apex
    (apex_shift): near the apex the wall's function is as small as the distance to it, and computed from a
    far origin its roots lost as many digits (10^-8 from the apex: half of them)."""
    k = small_radius - 1.0
    shift = apex_shift(origin, direction, k)
    origin = origin + shift[:, None] * direction if abs(k) >= 0.5 else origin
    ox, oy, oz = origin.T
    dx, dy, dz = direction.T
    r0 = 1.0 + k * oz
    a = dx * dx + dy * dy - k * k * dz * dz
    b = ox * dx + oy * dy - k * dz * r0
    c = ox * ox + oy * oy - r0 * r0
    # The slab 0 <= z <= 1: which cap bounds it on each side.
    with np.errstate(divide="ignore", invalid="ignore"):
        t_base = (0.0 - oz) / dz
        t_cap = (1.0 - oz) / dz
    parallel = dz == 0.0
    in_slab = (oz >= 0.0) & (oz <= 1.0)
    rising = dz > 0.0
    slab_lo = np.where(parallel, np.where(in_slab, -np.inf, np.nan), np.where(rising, t_base, t_cap))
    slab_hi = np.where(parallel, np.where(in_slab, np.inf, np.nan), np.where(rising, t_cap, t_base))
    t_in, t_out = _wall_interval(a, b, c, slab_lo, slab_hi)
    hit = np.isfinite(t_in) & np.isfinite(t_out)
    # An end on the slab's boundary is a cap (ties too: the apex of a cone is the cap's point).
    cap_in = t_in <= slab_lo
    cap_out = t_out >= slab_hi
    part_in = np.where(cap_in, np.where(rising, 1, 2), 0)
    part_out = np.where(cap_out, np.where(rising, 2, 1), 0)
    # A pair with a wall crossing, between the wall's roots, counts only where the line is provably inside
    # between its ends (the tangent line's touching pair, a line through a cone's apex).
    rounding = gamma(tol.hit_ulps)
    rows = np.nonzero(hit & ((part_in == 0) | (part_out == 0)))[0]  # (the rays with a wall crossing)
    o_w, d_w, a_w, b_w = origin[rows], direction[rows], a[rows], b[rows]
    sizes = wall_term_sizes(o_w, d_w, k)
    mid = 0.5 * (t_in[rows] + t_out[rows])
    proven = 0.5 * ((a_w * mid + 2.0 * b_w) * mid + c[rows]) < -rounding * wall_terms_at(sizes, mid)
    hit[rows[(a_w >= 0.0) & ~proven]] = False
    cap_normal = {1: np.array([0.0, 0.0, -1.0]), 2: np.array([0.0, 0.0, 1.0])}

    def normal_at(t, part):
        p = origin + np.where(hit, t, 0.0)[:, None] * direction
        wall = tapered_cylinder_normal(p, small_radius)
        return np.where((part == 1)[:, None], cap_normal[1], np.where((part == 2)[:, None], cap_normal[2], wall))

    out = _two_hits(t_in, t_out, normal_at(t_in, part_in), normal_at(t_out, part_out), part_in, part_out, hit)
    out.bend = np.zeros_like(out.t)
    for slot, (t, part) in enumerate(((t_in, part_in), (t_out, part_out))):
        wall = hit[rows] & (part[rows] == 0)
        ends = rows[wall]
        if ends.size:
            out.bend[ends, slot], out.error[ends, slot], out.offset[ends, slot] = wall_error_terms(
                o_w[wall], d_w[wall], k, a_w[wall], b_w[wall], t[ends], tuple(m[wall] for m in sizes), rounding)
    out.t = out.t + shift[:, None]
    return out


def intersect_convex_polyhedron(origin: np.ndarray, direction: np.ndarray,
                                plane_normals: np.ndarray, plane_offsets: np.ndarray) -> HitArrays:
    """Cyrus–Beck: the line is inside where it is on the inner side of every face plane."""
    # (N, F): > 0 means origin inside that plane.  Summed as the C core does (dot3), not by a matrix
    # product: a ray through an edge two faces share meets both at one t, and which face it enters by must not
    # hang on the last bit.
    num = plane_offsets[None, :] - dot3(origin[:, None, :], plane_normals[None, :, :])
    den = dot3(direction[:, None, :], plane_normals[None, :, :])
    with np.errstate(divide="ignore", invalid="ignore"):
        t = num / den
    entering_face = den < 0.0
    exiting_face = den > 0.0
    t_in_each = np.where(entering_face, t, -np.inf)
    t_out_each = np.where(exiting_face, t, np.inf)
    i_in = np.argmax(t_in_each, axis=1)
    i_out = np.argmin(t_out_each, axis=1)
    rows = np.arange(origin.shape[0])
    t_in = t_in_each[rows, i_in]
    t_out = t_out_each[rows, i_out]
    outside_parallel = ((den == 0.0) & (num < 0.0)).any(axis=1)
    hit = ~outside_parallel & np.isfinite(t_in) & np.isfinite(t_out) & (t_in <= t_out)
    return _two_hits(t_in, t_out, plane_normals[i_in], plane_normals[i_out], i_in, i_out, hit)


#: The corners of the squares round a tapered cylinder's base (z = 0) and top (z = 1) discs, for a top radius
#: of 1 (tapered_cylinder_bounds scales the top's x and y).
_DISC_CORNERS = np.array([[x, y, z] for z in (0.0, 1.0) for x, y in ((-1, -1), (-1, 1), (1, -1), (1, 1))],
                         dtype=np.float64)


def tapered_cylinder_bounds(values: np.ndarray) -> np.ndarray:
    """(N, 8, 3) generic points whose hull holds each tapered cylinder of (N, P) parameter rows (the top
    radius first; a negative one drawn as 0): the corners of the squares round its two discs."""
    top = np.maximum(values[:, 0], 0.0)
    points = np.broadcast_to(_DISC_CORNERS, (len(top), 8, 3)).copy()
    points[:, 4:, :2] *= top[:, None, None]
    return points
