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

/* EDGE_TOLERANCE, TORUS_RING, TORUS_TUBE and TORUS_IMAG_TOLERANCE come from contract.h (via core.h). */

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
}

static int hits_sphere(const double *o, const double *d, Hit *out)
{
    double a = dot3(d, d), b = dot3(o, d), c = dot3(o, o) - 1.0;
    double ba = b / a;
    double perp[3] = {o[0] - ba * d[0], o[1] - ba * d[1], o[2] - ba * d[2]};
    double disc = a * (1.0 - dot3(perp, perp));
    double lo, hi;
    if (!solve_quadratic(a, b, c, disc, &lo, &hi) || !(a > 0.0))
        return 0;
    if (!isfinite(lo) || !isfinite(hi))
        return 0;
    set_hit(&out[0], lo, 1, o[0] + lo * d[0], o[1] + lo * d[1], o[2] + lo * d[2], 0);
    set_hit(&out[1], hi, 0, o[0] + hi * d[0], o[1] + hi * d[1], o[2] + hi * d[2], 0);
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
static int hits_z_plane(const double *o, const double *d, Hit *out, int bounded)
{
    if (d[2] == 0.0)
        return 0;
    double t = (0.0 - o[2]) / d[2];
    double px = o[0] + t * d[0], py = o[1] + t * d[1];
    if (bounded) {
        double limit = 1.0 + EDGE_TOLERANCE;
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

static inline void tapered_normal(const double *p, double k, double *n)
{
    double radius = 1.0 + k * p[2];
    n[0] = p[0];
    n[1] = p[1];
    n[2] = -k * radius;
    if (dot3(n, n) < 1e-300) {
        n[0] = 0.0;
        n[1] = 0.0;
        n[2] = 1.0;
    }
}

/* Tapered cylinder with top radius s: wall, base disc z = 0 (part 1), cap disc z = 1 (part 2). */
static int hits_tapered(const double *o, const double *d, double s, Hit *out)
{
    double k = s - 1.0;
    double r0 = 1.0 + k * o[2];
    double a = d[0] * d[0] + d[1] * d[1] - k * k * d[2] * d[2];
    double b = o[0] * d[0] + o[1] * d[1] - k * d[2] * r0;
    double c = o[0] * o[0] + o[1] * o[1] - r0 * r0;
    double ts[4], ns[4][3];
    int valid[4] = {0, 0, 0, 0};
    double lo = NAN, hi = NAN;
    int real = solve_quadratic(a, b, c, b * b - a * c, &lo, &hi);
    for (int slot = 0; slot < 2; slot++) {
        double tw = slot ? hi : lo;
        int finite = real && isfinite(tw);
        double tt = finite ? tw : 0.0;
        double p[3] = {o[0] + tt * d[0], o[1] + tt * d[1], o[2] + tt * d[2]};
        ts[slot] = tw;
        tapered_normal(p, k, ns[slot]);
        valid[slot] = finite && p[2] >= -EDGE_TOLERANCE && p[2] <= 1.0 + EDGE_TOLERANCE;
    }
    for (int slot = 2; slot < 4; slot++) {
        double z = slot == 2 ? 0.0 : 1.0, radius = slot == 2 ? 1.0 : s;
        int crosses = d[2] != 0.0;
        double t = (z - o[2]) / d[2];
        double tt = crosses ? t : 0.0;
        double px = o[0] + tt * d[0], py = o[1] + tt * d[1];
        ts[slot] = t;
        ns[slot][0] = 0.0;
        ns[slot][1] = 0.0;
        ns[slot][2] = slot == 2 ? -1.0 : 1.0;
        valid[slot] = crosses && (px * px + py * py <= radius * radius * (1.0 + EDGE_TOLERANCE)) && radius > 0.0;
    }
    int i_in = 0, i_out = 0, any = 0;
    double t_in = INFINITY, t_out = -INFINITY;
    for (int slot = 0; slot < 4; slot++) {
        double tmin = valid[slot] ? ts[slot] : INFINITY, tmax = valid[slot] ? ts[slot] : -INFINITY;
        any |= valid[slot];
        if (slot == 0 || tmin < t_in) { t_in = tmin; i_in = slot; }    /* first minimum, as argmin */
        if (slot == 0 || tmax > t_out) { t_out = tmax; i_out = slot; }  /* first maximum, as argmax */
    }
    if (!any || !isfinite(t_in) || !isfinite(t_out))
        return 0;
    set_hit(&out[0], t_in, 1, ns[i_in][0], ns[i_in][1], ns[i_in][2], i_in >= 2 ? i_in - 1 : 0);
    set_hit(&out[1], t_out, 0, ns[i_out][0], ns[i_out][1], ns[i_out][2], i_out >= 2 ? i_out - 1 : 0);
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

static int hits_torus(const double *o, const double *d, int64_t newton_steps, Hit *out)
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
    double h[4][4] = {{-c[0], -c[1], -c[2], -c[3]}, {1.0, 0.0, 0.0, 0.0}, {0.0, 1.0, 0.0, 0.0}, {0.0, 0.0, 1.0, 0.0}};
    double wr[4], wi[4];
    if (hessenberg_eigenvalues(h, 4, wr, wi) != 0)
        return 0;
    double s[4];
    int m = 0;
    for (int i = 0; i < 4; i++)
        if (fabs(wi[i]) <= TORUS_IMAG_TOLERANCE * (1.0 + fabs(wr[i])))
            s[m++] = torus_polish(wr[i], c, newton_steps);
    for (int i = 1; i < m; i++)  /* insertion sort */
        for (int j = i; j > 0 && s[j] < s[j - 1]; j--) {
            double x = s[j]; s[j] = s[j - 1]; s[j - 1] = x;
        }
    int n = 0;
    for (int i = 0; i < m; i++) {
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
        set_hit(&out[n], t, (i % 2) == 0, g[0], g[1], g[2], 0);
        n++;
    }
    return n;
}

#endif
