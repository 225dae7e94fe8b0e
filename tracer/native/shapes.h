/* Lines against the closed-form generic shapes, in generic coordinates: the C form of
 * tracer/intersect/analytic.py and tracer/intersect/torus.py.
 *
 * Each function writes the finite crossings of the whole line o + t d into `out` (sorted by t; normals
 * generic, not unit) and returns how many there are.  `out` must have room for 4 hits.
 */
#ifndef RT_SHAPES_H
#define RT_SHAPES_H

#include "core.h"
#include "numeric.h"

/* TORUS_RING and TORUS_TUBE come from contract.h (via core.h). */

/* analytic.agree_with_crossing for one hit: a normal on the wrong side of the ray loses its component
 * along the ray.  Returns n . d, after. */
static inline double agree_with_crossing(Hit *h, const double *d)
{
    double along = dot3(h->n, d);
    if (h->entering ? along > 0.0 : along < 0.0) {
        double k = along / dot3(d, d);
        for (int i = 0; i < 3; i++)
            h->n[i] -= k * d[i];
        along = dot3(h->n, d);
    }
    return along;
}

static inline void set_hit(Hit *h, double t, int entering, double nx, double ny, double nz, int part)
{
    h->t = t;
    h->n[0] = nx;
    h->n[1] = ny;
    h->n[2] = nz;
    h->uv[0] = h->uv[1] = 0.0;
    h->part = part;
    h->shape = -1;
    h->entering = entering;
    h->err = 0.0;
    h->bend = 0.0;  /* a flat face, unless the shape says otherwise */
    /* A flat face's point and the sphere's are off their surface by no more than the line's error (their
     * roots carry no rounding beyond the point error's): only the shapes whose roots do report more. */
    h->offset = 0.0;
}

/* Roots -b/a -+ sqrt(disc)/a about the line's point nearest the centre (analytic.intersect_sphere). */
static int hits_sphere(const double *o, const double *d, Hit *out)
{
    double a = dot3(d, d), b = dot3(o, d);
    double mid = -(b / a);
    double perp[3] = {o[0] + mid * d[0], o[1] + mid * d[1], o[2] + mid * d[2]};
    double disc = a * (1.0 - dot3(perp, perp));
    if (!(disc >= 0.0) || !(a > 0.0) || !isfinite(mid))
        return 0;
    double half = sqrt(disc) / a;
    double lo = mid - half, hi = mid + half;
    set_hit(&out[0], lo, 1, o[0] + lo * d[0], o[1] + lo * d[1], o[2] + lo * d[2], 0);
    set_hit(&out[1], hi, 0, o[0] + hi * d[0], o[1] + hi * d[1], o[2] + hi * d[2], 0);
    out[0].bend = out[1].bend = a;  /* G = (|p|^2 - 1) / 2: n = p, G'' = |d|^2 */
    return 2;
}

static int hits_cube(const double *o, const double *d, Hit *out)
{
    double near[3], far[3];
    for (int i = 0; i < 3; i++) {
        if (d[i] == 0.0) {
            int inside = o[i] >= -1.0 && o[i] <= 1.0;
            near[i] = inside ? -INFINITY : INFINITY;
            far[i] = inside ? INFINITY : -INFINITY;
        } else {
            double ta = (-1.0 - o[i]) / d[i], tb = (1.0 - o[i]) / d[i];
            near[i] = fmin_nan(ta, tb);
            far[i] = fmax_nan(ta, tb);
        }
    }
    int ai = 0, ao = 0;
    for (int i = 1; i < 3; i++) {
        if (near[i] > near[ai]) ai = i;
        if (far[i] < far[ao]) ao = i;
    }
    double t_in = near[ai], t_out = far[ao];
    if (!(t_in <= t_out && isfinite(t_in) && isfinite(t_out)))
        return 0;
    double s_in = d[ai] > 0.0 ? 1.0 : (d[ai] < 0.0 ? -1.0 : 0.0);
    double s_out = d[ao] > 0.0 ? 1.0 : (d[ao] < 0.0 ? -1.0 : 0.0);
    double n_in[3] = {0.0, 0.0, 0.0}, n_out[3] = {0.0, 0.0, 0.0};
    n_in[ai] = -s_in;
    n_out[ao] = s_out;
    set_hit(&out[0], t_in, 1, n_in[0], n_in[1], n_in[2], 2 * ai + (s_in < 0.0));
    set_hit(&out[1], t_out, 0, n_out[0], n_out[1], n_out[2], 2 * ao + (s_out > 0.0));
    return 2;
}

/* The square (thin: the caller turns its crossing into an enter/exit pair) and the plane z = 0. */
static int hits_z_plane(const double *o, const double *d, Hit *out, int bounded, double edge)
{
    if (d[2] == 0.0)
        return 0;
    double t = (0.0 - o[2]) / d[2];
    double px = o[0] + t * d[0], py = o[1] + t * d[1];
    if (bounded) {
        double limit = 1.0 + edge;
        if (!(fabs(px) <= limit && fabs(py) <= limit))
            return 0;
    }
    if (!isfinite(t))
        return 0;
    set_hit(&out[0], t, d[2] < 0.0, 0.0, 0.0, 1.0, 0);
    out[0].uv[0] = px;
    out[0].uv[1] = py;
    return 1;
}

/* The half-space z <= 0 holds the line at t = -inf when it rises, or when it runs inside, parallel. */
static inline int plane_inside_at_start(const double *o, const double *d)
{
    return d[2] > 0.0 || (d[2] == 0.0 && o[2] < 0.0);
}

/* The square (analytic.intersect_square): a thin sheet, so each crossing becomes an enter/exit pair at the
 * same time (the NumPy path pairs them in sheet_to_pairs).  Room for 2 hits. */
static int hits_square(const double *o, const double *d, double edge, Hit *out)
{
    int n = hits_z_plane(o, d, out, 1, edge);
    if (n) {
        out[1] = out[0];
        out[0].entering = 1;
        out[1].entering = 0;
    }
    return 2 * n;
}

/* The plane z = 0 (analytic.intersect_plane), with whether the line starts inside the half-space below. */
static int hits_plane(const double *o, const double *d, Hit *out, int *inside)
{
    *inside = plane_inside_at_start(o, d);
    return hits_z_plane(o, d, out, 0, 0.0);
}

/* The sizes of the terms of G = (x^2 + y^2 - (1 + k z)^2) / 2 along the line o + t d, which is
 * (a t^2 + 2 b t + c) / 2 with a, b, c computed from o: G's rounding at t is gamma times wall_terms_at
 * (analytic.wall_term_sizes).  (w = 1 + k z at o is off by its terms' size times the rounding, which near
 * the apex is not small.) */
typedef struct {
    double a, b, c;
} WallTerms;

static inline WallTerms wall_term_sizes(const double *o, const double *d, double k)
{
    double w0 = fabs(1.0 + k * o[2]), terms = 1.0 + fabs(k * o[2]);
    WallTerms m;
    m.a = d[0] * d[0] + d[1] * d[1] + k * k * d[2] * d[2];
    m.b = fabs(o[0] * d[0]) + fabs(o[1] * d[1]) + fabs(k * d[2]) * (w0 + terms);
    m.c = o[0] * o[0] + o[1] * o[1] + w0 * (w0 + 2.0 * terms);
    return m;
}

static inline double wall_terms_at(const WallTerms *m, double t)
{
    double at = fabs(t);
    return 0.5 * ((m->a * at + 2.0 * m->b) * at + m->c);
}

/* A wall hit of the line o + t d at t (analytic.wall_hits): the outward normal at the azimuth of the point p,
 * scaled by p's distance rho from the axis, (x, y, -k rho): the gradient of G at the wall point of that
 * azimuth and height.  Every point of a generator has the same normal, so it is known however far p is off
 * the wall along it (near a cone's apex 1 - z cancels); on the axis itself the axis is the only sensible
 * direction.  G bends by a; the root's own error is how far G's rounding moves it (crossing_shift of gamma
 * times its terms, which near the apex, where |grad G| is as small as the distance to the apex, the point
 * error no longer covers); the residual is the point's distance from the wall times |n| = rho sqrt(1 + k^2):
 * that of (rho, z) from the line rho = 1 + k z in the plane through the axis, or, where its foot
 * (rho, z) - (rho - w) (1, -k) / (1 + k^2) is past a cone's apex, its distance from the apex. */
static inline void wall_hit(const double *o, const double *d, double k, double a, double b, double t, int entering,
                            const WallTerms *m, double gamma, Hit *h)
{
    double p[3] = {o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
    double rho = sqrt(p[0] * p[0] + p[1] * p[1]), w = 1.0 + k * p[2];
    double n[3] = {p[0], p[1], -k * rho};
    if (dot3(n, n) < 1e-300) {
        n[0] = 0.0;
        n[1] = 0.0;
        n[2] = 1.0;
    }
    set_hit(h, t, entering, n[0], n[1], n[2], 0);
    h->bend = a;
    h->err = crossing_shift(gamma * wall_terms_at(m, t), fabs(a * t + b), fabs(a));
    if (rho * k * k + w >= 0.0)
        h->offset = fabs(rho - w) * rho;
    else
        h->offset = sqrt(rho * rho + (w / k) * (w / k)) * rho * sqrt(1.0 + k * k);
}

/* Where the line is inside the wall's double cone a t^2 + 2 b t + c <= 0, clipped to the slab
 * [slab_lo, slab_hi] (analytic._wall_interval).  Returns 0 where that is empty. */
static int wall_interval(double a, double b, double c, double slab_lo, double slab_hi, double *start, double *end)
{
    double lo = NAN, hi = NAN;
    int real = solve_quadratic(a, b, c, b * b - a * c, &lo, &hi);
    double s, e;
    if (a < 0.0) {  /* inside outside the roots (both nappes), or everywhere when there are none */
        double lower_hi = real ? nan_min2(lo, slab_hi) : slab_hi;
        double upper_lo = real ? nan_max2(hi, slab_lo) : slab_lo;
        int take_upper = !real || (slab_hi - upper_lo > lower_hi - slab_lo);
        s = take_upper ? upper_lo : slab_lo;
        e = take_upper ? slab_hi : lower_hi;
    } else {
        if (!real) {
            lo = hi = NAN;
        }
        if (a == 0.0 && b == 0.0) {  /* no t at all: inside everywhere or nowhere */
            lo = c <= 0.0 ? -INFINITY : NAN;
            hi = c <= 0.0 ? INFINITY : NAN;
        }
        s = nan_max2(lo, slab_lo);
        e = nan_min2(hi, slab_hi);
    }
    if (!(s <= e))
        return 0;
    *start = s;
    *end = e;
    return 1;
}

/* Tapered cylinder with top radius s: wall (part 0), base disc z = 0 (part 1), cap disc z = 1 (part 2).
 * Where the apex (0, 0, -1/k) is within two units of the base, the line is taken from its point nearest the
 * apex (analytic.apex_shift): near the apex the wall's function is as small as the distance to it, and
 * computed from a far origin its roots lost as many digits (10^8 from the apex: half of them). */
static int hits_tapered(const double *centred, const double *d, double s, double hit_ulps, Hit *out)
{
    double k = s - 1.0, u = DBL_EPSILON / 2.0, gamma = hit_ulps * u / (1.0 - hit_ulps * u);
    double o[3] = {centred[0], centred[1], centred[2]}, shift = 0.0;
    if (fabs(k) >= 0.5) {
        double apart[3] = {o[0], o[1], o[2] + 1.0 / k};
        double along = -dot3(apart, d) / dot3(d, d);
        if (isfinite(along)) {
            shift = along;
            for (int i = 0; i < 3; i++)
                o[i] = centred[i] + along * d[i];
        }
    }
    double r0 = 1.0 + k * o[2];
    double a = d[0] * d[0] + d[1] * d[1] - k * k * d[2] * d[2];
    double b = o[0] * d[0] + o[1] * d[1] - k * d[2] * r0;
    double c = o[0] * o[0] + o[1] * o[1] - r0 * r0;
    double t_base = (0.0 - o[2]) / d[2], t_cap = (1.0 - o[2]) / d[2];
    int rising = d[2] > 0.0;
    double slab_lo, slab_hi;
    if (d[2] == 0.0) {
        int in_slab = o[2] >= 0.0 && o[2] <= 1.0;
        slab_lo = in_slab ? -INFINITY : NAN;
        slab_hi = in_slab ? INFINITY : NAN;
    } else {
        slab_lo = rising ? t_base : t_cap;
        slab_hi = rising ? t_cap : t_base;
    }
    double t_in, t_out;
    if (!wall_interval(a, b, c, slab_lo, slab_hi, &t_in, &t_out) || !isfinite(t_in) || !isfinite(t_out))
        return 0;
    /* An end on the slab's boundary is a cap (ties too: a cone's apex is its cap's point). */
    int part_in = t_in <= slab_lo ? (rising ? 1 : 2) : 0;
    int part_out = t_out >= slab_hi ? (rising ? 2 : 1) : 0;
    /* A pair with a wall crossing, between the wall's roots, counts only where the line is provably inside
     * between its ends (the tangent line's touching pair, a line through a cone's apex). */
    WallTerms m = wall_term_sizes(o, d, k);
    if ((part_in == 0 || part_out == 0) && a >= 0.0) {
        double mid = 0.5 * (t_in + t_out);
        if (!(0.5 * ((a * mid + 2.0 * b) * mid + c) < -gamma * wall_terms_at(&m, mid)))
            return 0;
    }
    for (int end = 0; end < 2; end++) {
        double t = end ? t_out : t_in;
        int part = end ? part_out : part_in;
        if (part == 0) {
            wall_hit(o, d, k, a, b, t, !end, &m, gamma, &out[end]);
        } else {  /* a cap */
            set_hit(&out[end], t, !end, 0.0, 0.0, part == 1 ? -1.0 : 1.0, part);
        }
        out[end].t = t + shift;
    }
    return 2;
}

/* Convex polyhedron n_f . p <= offset_f (Cyrus-Beck); planes are (nx, ny, nz, offset). */
static int hits_polyhedron(const double *o, const double *d, const double *planes, int64_t count, Hit *out)
{
    int64_t i_in = 0, i_out = 0;
    double t_in = -INFINITY, t_out = INFINITY;
    int outside_parallel = 0;
    for (int64_t f = 0; f < count; f++) {
        const double *pl = planes + 4 * f;
        double num = pl[3] - dot3(o, pl);
        double den = dot3(d, pl);
        double t = num / den;
        double tin = den < 0.0 ? t : -INFINITY;
        double tout = den > 0.0 ? t : INFINITY;
        if (f == 0 || tin > t_in) { t_in = tin; i_in = f; }      /* first maximum, as argmax */
        if (f == 0 || tout < t_out) { t_out = tout; i_out = f; }  /* first minimum, as argmin */
        if (den == 0.0 && num < 0.0)
            outside_parallel = 1;
    }
    if (outside_parallel || !isfinite(t_in) || !isfinite(t_out) || !(t_in <= t_out))
        return 0;
    const double *a = planes + 4 * i_in, *b = planes + 4 * i_out;
    set_hit(&out[0], t_in, 1, a[0], a[1], a[2], (int)i_in);
    set_hit(&out[1], t_out, 0, b[0], b[1], b[2], (int)i_out);
    return 2;
}

/* ---------------------------------------------------------------------------------------------------
 * The torus (|p|^2 + R^2 - r^2)^2 = 4 R^2 (x^2 + y^2), R = 1, r = 0.2: the quartic in the arc length s from
 * the point of the line nearest the centre, roots from the companion matrix's eigenvalues, the nearly
 * real ones polished by Newton steps. */

static inline double quartic_at(double s, const double *c)
{
    return (((s + c[0]) * s + c[1]) * s + c[2]) * s + c[3];
}

static double torus_polish(double s, const double *c, int64_t steps)
{
    for (int64_t step = 0; step < steps; step++) {
        double p = quartic_at(s, c);
        double dp = ((4.0 * s + 3.0 * c[0]) * s + 2.0 * c[1]) * s + c[2];
        double candidate = s - p / dp;
        double p_new = quartic_at(candidate, c);
        if (isfinite(candidate) && fabs(p_new) < fabs(p))
            s = candidate;
    }
    return s;
}

/* Newton steps on the quartic's derivative: the extremum a complex pair of roots sits over. */
static double torus_minimum_near(double s, const double *c, int64_t steps)
{
    for (int64_t step = 0; step < steps; step++) {
        double d1 = ((4.0 * s + 3.0 * c[0]) * s + 2.0 * c[1]) * s + c[2];
        double d2 = (12.0 * s + 6.0 * c[0]) * s + 2.0 * c[1];
        double candidate = s - d1 / d2;
        if (isfinite(candidate) && d2 > 0.0)
            s = candidate;
    }
    return s;
}

/* torus.residual_bound: how far from zero a computed quartic value at s can be where the exact one is 0. */
static inline double torus_residual_bound(double s, const double *magnitudes, double ulps)
{
    return ulps * DBL_EPSILON * quartic_at(fabs(s), magnitudes);
}

static int hits_torus(const double *o, const double *d, int64_t newton_steps, double residual_ulps,
                      double pair_shortcut, Hit *out)
{
    double speed = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    if (!(speed > 0.0))
        return 0;
    double u[3] = {d[0] / speed, d[1] / speed, d[2] / speed};
    double b = dot3(o, u);
    double q[3] = {o[0] - b * u[0], o[1] - b * u[1], o[2] - b * u[2]};
    double bound = TORUS_RING + TORUS_TUBE;
    if (!(dot3(q, q) <= bound * bound))
        return 0;
    double shift = -b;
    double R2 = TORUS_RING * TORUS_RING, tube2 = TORUS_TUBE * TORUS_TUBE;
    double f = dot3(q, u);
    double e = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + R2 - tube2;
    double c[4];
    c[0] = 4.0 * f;
    c[1] = 4.0 * f * f + 2.0 * e - 4.0 * R2 * (u[0] * u[0] + u[1] * u[1]);
    c[2] = 4.0 * e * f - 8.0 * R2 * (q[0] * u[0] + q[1] * u[1]);
    c[3] = e * e - 4.0 * R2 * (q[0] * q[0] + q[1] * q[1]);
    /* torus.coefficient_magnitudes: the same terms in absolute value */
    double fa = fabs(f), ea = q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + R2 + tube2, m[4];
    m[0] = 4.0 * fa;
    m[1] = 4.0 * fa * fa + 2.0 * ea + 4.0 * R2 * (u[0] * u[0] + u[1] * u[1]);
    m[2] = 4.0 * ea * fa + 8.0 * R2 * (fabs(q[0] * u[0]) + fabs(q[1] * u[1]));
    m[3] = ea * ea + 4.0 * R2 * (q[0] * q[0] + q[1] * q[1]);
    double h[4][4] = {{-c[0], -c[1], -c[2], -c[3]}, {1.0, 0.0, 0.0, 0.0}, {0.0, 1.0, 0.0, 0.0}, {0.0, 0.0, 1.0, 0.0}};
    double wr[4], wi[4];
    if (hessenberg_eigenvalues(h, 4, wr, wi) != 0)
        return 0;
    /* Real eigenvalues count; a complex pair only where the quartic's minimum next to it is provably below
     * zero (then as its two nearby roots). See tracer/intersect/torus.py. */
    double s[4];
    int m_count = 0;
    for (int i = 0; i < 4; i++) {
        double start;
        if (wi[i] == 0.0) {
            start = wr[i];
        } else if (fabs(wi[i]) > pair_shortcut * (1.0 + fabs(wr[i]))) {
            continue;  /* far from the real axis: no near-double root (Tolerances.torus_pair_shortcut) */
        } else {
            double centre = torus_minimum_near(wr[i], c, newton_steps);
            double depth = quartic_at(centre, c);
            double curvature = (12.0 * centre + 6.0 * c[0]) * centre + 2.0 * c[1];
            /* a proven pair of real roots split by no more than twice the imaginary part (torus.py) */
            if (!(depth < -torus_residual_bound(centre, m, residual_ulps)) ||
                !(-depth <= 2.0 * curvature * wi[i] * wi[i]) || !(curvature > 0.0))
                continue;
            double half = sqrt((depth < 0.0 ? -depth : 0.0) / (0.5 * curvature));
            start = wi[i] > 0.0 ? centre - half : centre + half;
        }
        s[m_count++] = torus_polish(start, c, newton_steps);
    }
    for (int i = 1; i < m_count; i++)  /* insertion sort */
        for (int j = i; j > 0 && s[j] < s[j - 1]; j--) {
            double x = s[j]; s[j] = s[j - 1]; s[j - 1] = x;
        }
    for (int i = m_count; i < 4; i++)
        s[i] = INFINITY;
    /* Inside the tube between an entry and its exit, outside between an exit and the next entry: a pair
     * whose sign the quartic does not prove beyond rounding is no crossing. */
    static const int pairs[3][3] = {{0, 1, 1}, {2, 3, 1}, {1, 2, 0}};
    for (int k = 0; k < 3; k++) {
        int first = pairs[k][0], second = pairs[k][1];
        if (!isfinite(s[first]) || !isfinite(s[second]))
            continue;
        double mid = 0.5 * (s[first] + s[second]);
        double value = quartic_at(mid, c), limit = torus_residual_bound(mid, m, residual_ulps);
        if (pairs[k][2] ? !(value < -limit) : !(value > limit))
            s[first] = s[second] = INFINITY;
    }
    for (int i = 1; i < 4; i++)
        for (int j = i; j > 0 && s[j] < s[j - 1]; j--) {
            double x = s[j]; s[j] = s[j - 1]; s[j - 1] = x;
        }
    int n = 0;
    for (int i = 0; i < 4; i++) {
        if (!isfinite(s[i]))
            continue;
        double p[3] = {q[0] + s[i] * u[0], q[1] + s[i] * u[1], q[2] + s[i] * u[2]};
        double r2 = p[0] * p[0] + p[1] * p[1] + p[2] * p[2];
        double kk = r2 + TORUS_RING * TORUS_RING - tube2;
        double g[3] = {4.0 * p[0] * kk, 4.0 * p[1] * kk, 4.0 * p[2] * kk};
        g[0] -= 8.0 * TORUS_RING * TORUS_RING * p[0];
        g[1] -= 8.0 * TORUS_RING * TORUS_RING * p[1];
        double t = (s[i] + shift) / speed;
        /* Hits alternate in, out, in, out along the line (it starts outside the bounded torus). */
        set_hit(&out[n], t, (n % 2) == 0, g[0], g[1], g[2], 0);
        /* torus.root_error: residual bound over the slope, or near a double root over the curvature */
        double limit = torus_residual_bound(s[i], m, residual_ulps);
        double slope = fabs(((4.0 * s[i] + 3.0 * c[0]) * s[i] + 2.0 * c[1]) * s[i] + c[2]);
        double curvature = fabs((12.0 * s[i] + 6.0 * c[0]) * s[i] + 2.0 * c[1]);
        out[n].err = fmin_nan(limit / slope, sqrt(2.0 * limit / curvature)) / speed;
        /* G is the quartic itself (n its gradient): it bends by speed^2 times its curvature in s */
        out[n].bend = curvature * speed * speed;
        out[n].offset = fabs(kk * kk - 4.0 * TORUS_RING * TORUS_RING * (p[0] * p[0] + p[1] * p[1]));
        n++;
    }
    return n;
}

/* paraboloid.wall_proven_inside: is the wall function a t^2 + 2 b t + c provably negative at t, below minus
 * gamma times the size of its terms there (those of a, b, c: am, bm, cm)?  A pair of wall crossings whose
 * middle is not may be the touching pair rounding makes of a line tangent to the wall. */
static inline int quadric_proven_inside(double a, double b, double c, double am, double bm, double cm, double t,
                                        double gamma)
{
    double at = fabs(t);
    return (a * t + 2.0 * b) * t + c < -gamma * ((am * at + 2.0 * bm) * at + cm);
}

static inline double gamma_of(double ulps)
{
    double u = DBL_EPSILON / 2.0;
    return ulps * u / (1.0 - ulps * u);
}

/* The generic paraboloid x^2 + y^2 <= z <= 1 (intersect/paraboloid.py): wall (part 0), cap disc z = 1
 * (part 1).  Inside the wall between the roots of a t^2 + 2 b t + c (a >= 0), clipped to z <= 1; a pair with
 * a wall crossing counts only where the line is provably inside between its ends. */
static int hits_paraboloid(const double *o, const double *d, double hit_ulps, Hit *out)
{
    double a = d[0] * d[0] + d[1] * d[1];
    double b = o[0] * d[0] + o[1] * d[1] - 0.5 * d[2];
    double c = o[0] * o[0] + o[1] * o[1] - o[2];
    double t_cap = (1.0 - o[2]) / d[2];
    double slab_lo, slab_hi;
    if (d[2] == 0.0) {
        int below = o[2] <= 1.0;
        slab_lo = below ? -INFINITY : NAN;
        slab_hi = below ? INFINITY : NAN;
    } else {
        slab_lo = d[2] > 0.0 ? -INFINITY : t_cap;
        slab_hi = d[2] > 0.0 ? t_cap : INFINITY;
    }
    double t_in, t_out;
    if (!wall_interval(a, b, c, slab_lo, slab_hi, &t_in, &t_out) || !isfinite(t_in) || !isfinite(t_out))
        return 0;
    if ((t_in > slab_lo || t_out < slab_hi) &&
        !quadric_proven_inside(a, b, c, a, fabs(o[0] * d[0]) + fabs(o[1] * d[1]) + 0.5 * fabs(d[2]),
                               o[0] * o[0] + o[1] * o[1] + fabs(o[2]), 0.5 * (t_in + t_out), gamma_of(hit_ulps)))
        return 0;
    for (int end = 0; end < 2; end++) {
        double t = end ? t_out : t_in;
        int part = end ? t_out >= slab_hi : t_in <= slab_lo;  /* an end on z = 1 is the cap (ties too) */
        double p[3] = {o[0] + t * d[0], o[1] + t * d[1], o[2] + t * d[2]};
        if (part) {
            set_hit(&out[end], t, !end, 0.0, 0.0, 1.0, 1);
        } else {  /* G = x^2 + y^2 - z (n its gradient) bends by 2 a */
            set_hit(&out[end], t, !end, 2.0 * p[0], 2.0 * p[1], -1.0, 0);
            out[end].bend = 2.0 * a;
            out[end].offset = fabs(p[0] * p[0] + p[1] * p[1] - p[2]);
        }
    }
    return 2;
}

/* The generic hyperboloid of one sheet x^2 + y^2 - (1 - S^2) z^2 <= S^2, -1 <= z <= 1 (intersect/hyperboloid.py):
 * wall (part 0), bottom cap z = -1 (part 1), top cap z = 1 (part 2); S is the waist.  Up to two intervals of
 * the line inside (a line steeper than the wall's asymptotes can cross the waist's hole): up to 4 hits. */
static int hits_hyperboloid(const double *o, const double *d, double waist, double hit_ulps, Hit *out)
{
    double w2 = waist * waist;
    double k = 1.0 - w2;
    double a = d[0] * d[0] + d[1] * d[1] - k * d[2] * d[2];
    double b = o[0] * d[0] + o[1] * d[1] - k * o[2] * d[2];
    double c = o[0] * o[0] + o[1] * o[1] - k * o[2] * o[2] - w2;
    double t_bottom = (-1.0 - o[2]) / d[2], t_top = (1.0 - o[2]) / d[2];
    int rising = d[2] > 0.0;
    double slab_lo, slab_hi;
    if (d[2] == 0.0) {
        int in_slab = o[2] >= -1.0 && o[2] <= 1.0;
        slab_lo = in_slab ? -INFINITY : NAN;
        slab_hi = in_slab ? INFINITY : NAN;
    } else {
        slab_lo = rising ? t_bottom : t_top;
        slab_hi = rising ? t_top : t_bottom;
    }
    /* hyperboloid._inside_intervals: a >= 0 between the roots, a < 0 outside them */
    double lo = NAN, hi = NAN;
    int real = solve_quadratic(a, b, c, b * b - a * c, &lo, &hi);
    double between_lo = real ? lo : NAN, between_hi = real ? hi : NAN;
    if (a == 0.0 && b == 0.0) {  /* no t at all: inside everywhere or nowhere */
        between_lo = c <= 0.0 ? -INFINITY : NAN;
        between_hi = c <= 0.0 ? INFINITY : NAN;
    }
    double t[4];
    if (a < 0.0) {
        t[0] = slab_lo;
        t[1] = real ? nan_min2(lo, slab_hi) : slab_hi;
        t[2] = real ? nan_max2(hi, slab_lo) : NAN;
        t[3] = real ? slab_hi : NAN;
    } else {
        t[0] = nan_max2(between_lo, slab_lo);
        t[1] = nan_min2(between_hi, slab_hi);
        t[2] = t[3] = NAN;
    }
    if (t[0] <= t[1] && t[2] <= t[3] && t[1] >= t[2]) {  /* touching intervals are one */
        t[1] = t[3];
        t[2] = t[3] = NAN;
    }
    /* Between the roots, a pair with a wall crossing counts only where the line is provably inside. */
    if (a >= 0.0 && isfinite(t[0]) && isfinite(t[1]) && (t[0] > slab_lo || t[1] < slab_hi) &&
        !quadric_proven_inside(a, b, c, d[0] * d[0] + d[1] * d[1] + fabs(k) * d[2] * d[2],
                               fabs(o[0] * d[0]) + fabs(o[1] * d[1]) + fabs(k * o[2] * d[2]),
                               o[0] * o[0] + o[1] * o[1] + fabs(k) * o[2] * o[2] + w2, 0.5 * (t[0] + t[1]),
                               gamma_of(hit_ulps)))
        t[0] = t[1] = NAN;
    int n = 0;
    for (int interval = 0; interval < 2; interval++) {
        double t_in = t[2 * interval], t_out = t[2 * interval + 1];
        if (!(t_in <= t_out) || !isfinite(t_in) || !isfinite(t_out))
            continue;
        /* An end on the slab's boundary is a cap (ties too). */
        int part_in = t_in <= slab_lo ? (rising ? 1 : 2) : 0;
        int part_out = t_out >= slab_hi ? (rising ? 2 : 1) : 0;
        for (int end = 0; end < 2; end++) {
            double at = end ? t_out : t_in;
            int part = end ? part_out : part_in;
            double p[3] = {o[0] + at * d[0], o[1] + at * d[1], o[2] + at * d[2]};
            double nv[3] = {p[0], p[1], -k * p[2]};  /* half the gradient */
            if (part) {
                nv[0] = nv[1] = 0.0;
                nv[2] = part == 1 ? -1.0 : 1.0;
            } else if (dot3(nv, nv) < 1e-300) {  /* the double cone's apex */
                nv[0] = nv[1] = 0.0;
                nv[2] = 1.0;
            }
            set_hit(&out[n], at, !end, nv[0], nv[1], nv[2], part);
            if (!part) {  /* G = (x^2 + y^2 - k z^2 - S^2) / 2 bends by a; the residual is |G| */
                out[n].bend = a;
                out[n].offset = 0.5 * fabs(p[0] * p[0] + p[1] * p[1] - k * p[2] * p[2] - w2);
            }
            n++;
        }
    }
    return n;
}

#endif
