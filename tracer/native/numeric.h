/* Small numerical building blocks: 3-vectors, affine maps, the stable quadratic and the eigenvalues of a
 * small real Hessenberg matrix (for the torus quartic's companion matrix).
 *
 * Sums are written in the order NumPy evaluates them (left to right), so that results agree with the
 * reference to the last bit wherever NumPy itself does not use BLAS.
 */
#ifndef RT_NUMERIC_H
#define RT_NUMERIC_H

#include <float.h>
#include <math.h>
#include <stdint.h>

#include "core.h"

/* fmin/fmax with their NaN rule (a NaN argument loses; np.fmin/np.fmax too), inlined: the libm calls are
 * slow in the inner loops. */
static inline double fmin_nan(double a, double b) { return (a < b || b != b) ? a : b; }
static inline double fmax_nan(double a, double b) { return (a > b || b != b) ? a : b; }

/* np.maximum / np.minimum: a NaN argument wins */
static inline double nan_max2(double a, double b) { return (a != a || b != b) ? NAN : (a > b ? a : b); }
static inline double nan_min2(double a, double b) { return (a != a || b != b) ? NAN : (a < b ? a : b); }

static inline double clip(double x, double lo, double hi)  /* np.clip: NaN stays NaN */
{
    return x < lo ? lo : (x > hi ? hi : x);
}

static inline double dot3(const double *a, const double *b) { return a[0] * b[0] + a[1] * b[1] + a[2] * b[2]; }

static inline void cross3(const double *a, const double *b, double *out)
{
    out[0] = a[1] * b[2] - a[2] * b[1];
    out[1] = a[2] * b[0] - a[0] * b[2];
    out[2] = a[0] * b[1] - a[1] * b[0];
}

static inline double max_abs3(const double *a)
{
    double m = fabs(a[0]);
    if (fabs(a[1]) > m) m = fabs(a[1]);
    if (fabs(a[2]) > m) m = fabs(a[2]);
    return m;
}

/* tracer.numerics.norm3: |v| without overflow or underflow.  Where |v|^2 leaves [2^-900, 2^900], v is
 * scaled by the power of two nearest its largest component first (exact, so no bit changes where the plain
 * form would have been right). */
static inline double norm3(const double *v)
{
    double squared = dot3(v, v);
    if (squared >= 0x1p-900 && squared <= 0x1p900)
        return sqrt(squared);
    double largest = max_abs3(v);
    if (largest == 0.0)
        return 0.0;
    int exponent;
    frexp(isfinite(largest) ? largest : 1.0, &exponent);
    double s[3] = {ldexp(v[0], -exponent), ldexp(v[1], -exponent), ldexp(v[2], -exponent)};
    return ldexp(sqrt(dot3(s, s)), exponent);
}

/* tracer.numerics.feeler_to: the direction from `start` to `target` and the t at which it arrives (1, or a
 * power of two where the feeler is longer than FEELER_REACH = 2^64 and is scaled by it: no overflow). */
static inline double feeler_to(const double *start, const double *target, double *d)
{
    for (int i = 0; i < 3; i++)
        d[i] = target[i] - start[i];
    double largest = max_abs3(d);
    if (!(largest > 0x1p64) || !isfinite(largest))
        return 1.0;
    int exponent;
    frexp(largest, &exponent);
    for (int i = 0; i < 3; i++)
        d[i] = ldexp(d[i], -exponent);
    return ldexp(1.0, exponent);
}

/* feeler_to where the shading knows the distance to the target from the hit point the feeler starts near:
 * the scaling is looked for only beyond FEELER_REACH (numerics.feeler_to with lengths). */
static inline double feeler_to_known(const double *start, const double *target, double length, double *d)
{
    if (length > 0x1p64)
        return feeler_to(start, target, d);
    for (int i = 0; i < 3; i++)
        d[i] = target[i] - start[i];
    return 1.0;
}

/* p' = M p for an affine row-major 4x4 */
static inline void affine_point(const double *m, const double *p, double *out)
{
    for (int i = 0; i < 3; i++)
        out[i] = p[0] * m[4 * i] + p[1] * m[4 * i + 1] + p[2] * m[4 * i + 2] + m[4 * i + 3];
}

/* v' = M[:3, :3] v */
static inline void affine_vector(const double *m, const double *v, double *out)
{
    for (int i = 0; i < 3; i++)
        out[i] = v[0] * m[4 * i] + v[1] * m[4 * i + 1] + v[2] * m[4 * i + 2];
}

/* n' = n @ M[:3, :3] (a generic normal through the inverse matrix: the inverse-transpose rule) */
static inline void normal_to_world(const double *inv, const double *n, double *out)
{
    for (int j = 0; j < 3; j++)
        out[j] = n[0] * inv[j] + n[1] * inv[4 + j] + n[2] * inv[8 + j];
}

/* tracer.terminator.world_vectors: the generic vector v in world coordinates, x with inverse x = v (the
 * 3 x 3 part of the primitive's inverse, row-major in 16), by cofactors. */
static inline void generic_to_world_vector(const double *a, const double *v, double *out)
{
    double c00 = a[5] * a[10] - a[6] * a[9], c01 = a[6] * a[8] - a[4] * a[10], c02 = a[4] * a[9] - a[5] * a[8];
    double c10 = a[2] * a[9] - a[1] * a[10], c11 = a[0] * a[10] - a[2] * a[8], c12 = a[1] * a[8] - a[0] * a[9];
    double c20 = a[1] * a[6] - a[2] * a[5], c21 = a[2] * a[4] - a[0] * a[6], c22 = a[0] * a[5] - a[1] * a[4];
    double det = a[0] * c00 + a[1] * c01 + a[2] * c02;
    out[0] = (c00 * v[0] + c10 * v[1] + c20 * v[2]) / det;
    out[1] = (c01 * v[0] + c11 * v[1] + c21 * v[2]) / det;
    out[2] = (c02 * v[0] + c12 * v[1] + c22 * v[2]) / det;
}

/* An instance row's numbers (tracer.instances), from its float32 affine `a` (3 rows of 4) and box, operation
 * for operation as the NumPy path computes them for all its rows at once. */

/* The inverse (row-major 4x4) by cofactors: the adjugate over the determinant, the translation carried back. */
static inline void instance_inverse(const float *a32, double *inv)
{
    double a[12];
    for (int k = 0; k < 12; k++)
        a[k] = a32[k];
#define A(r, c) a[4 * (r) + (c)]
    double adj[3][3] = {
        {A(1, 1) * A(2, 2) - A(1, 2) * A(2, 1), A(0, 2) * A(2, 1) - A(0, 1) * A(2, 2), A(0, 1) * A(1, 2) - A(0, 2) * A(1, 1)},
        {A(1, 2) * A(2, 0) - A(1, 0) * A(2, 2), A(0, 0) * A(2, 2) - A(0, 2) * A(2, 0), A(0, 2) * A(1, 0) - A(0, 0) * A(1, 2)},
        {A(1, 0) * A(2, 1) - A(1, 1) * A(2, 0), A(0, 1) * A(2, 0) - A(0, 0) * A(2, 1), A(0, 0) * A(1, 1) - A(0, 1) * A(1, 0)}};
    double det = A(0, 0) * adj[0][0] + A(0, 1) * adj[1][0] + A(0, 2) * adj[2][0];
    for (int i = 0; i < 3; i++) {
        for (int j = 0; j < 3; j++)
            inv[4 * i + j] = adj[i][j] / det;
        inv[4 * i + 3] = -(inv[4 * i] * A(0, 3) + inv[4 * i + 1] * A(1, 3) + inv[4 * i + 2] * A(2, 3));
    }
#undef A
    inv[12] = inv[13] = inv[14] = 0.0;
    inv[15] = 1.0;
}

/* Its rounding terms (PrimitiveTable.rounding_terms): the inverse's relative residual (the largest of
 * |inverse @ matrix - I| over |inverse| @ |matrix|, the bottom row exact), the generic size, the norms. */
static inline void instance_rounding(const double *inv, const float *a32, double generic_size, double *r)
{
    double error = 0.0;
    for (int i = 0; i < 3; i++)
        for (int j = 0; j < 4; j++) {
            double m0 = a32[j], m1 = a32[4 + j], m2 = a32[8 + j];
            const double *row = inv + 4 * i;
            double product = row[0] * m0 + row[1] * m1 + row[2] * m2;
            double magnitude = fabs(row[0]) * fabs(m0) + fabs(row[1]) * fabs(m1) + fabs(row[2]) * fabs(m2);
            if (j == 3) {
                product = product + row[3];
                magnitude = magnitude + fabs(row[3]);
            }
            double residual = fabs(product - (i == j ? 1.0 : 0.0));
            double relative = magnitude > 0.0 ? residual / magnitude : 0.0;
            error = relative > error ? relative : error;
        }
    double sums[3], moves[3];
    for (int i = 0; i < 3; i++) {
        sums[i] = fabs(inv[4 * i]) + fabs(inv[4 * i + 1]) + fabs(inv[4 * i + 2]);
        moves[i] = fabs(inv[4 * i + 3]);
    }
    r[0] = error;
    r[1] = generic_size;
    r[2] = fmax(fmax(sums[0], sums[1]), sums[2]);
    r[3] = fmax(fmax(moves[0], moves[1]), moves[2]);
}

/* A bounding sphere (centre, radius) round a single-precision box (lo, hi): the radius half its diagonal,
 * padded by tracer.instances.SPHERE_PADDING. */
static inline void instance_sphere(const float *box, double *sphere)
{
    double e[3];
    for (int i = 0; i < 3; i++) {
        double lo = box[i], hi = box[3 + i];
        sphere[i] = 0.5 * (lo + hi);
        e[i] = hi - lo;
    }
    sphere[3] = sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2]) * 0.5 * (1 + 1e-9);
}

/* tracer.numerics.crossing_shift: how far (in t) a crossing of a line with a surface G = 0 can move when G
 * along the line is off by `delta`, where the line crosses at rate `slope` (|dG/dt|) and G bends by `bend`
 * (|d^2G/dt^2|): at most delta slope / (slope^2 - bend delta), which is delta / slope on a flat face and at
 * most 2 delta / slope, or where the root pair may be a double root, sqrt(2 delta / bend).  No curvature is
 * assumed: a flat face at grazing incidence gets delta / slope. */
static inline double crossing_shift(double delta, double slope, double bend)
{
    if (!(delta > 0.0))
        return 0.0;
    double squared = slope * slope;
    if (squared > 2.0 * bend * delta)  /* (2 / (1 + sqrt(1 - x)) <= 1 / (1 - x / 2): no square root) */
        return delta * slope / (squared - bend * delta);
    return sqrt(2.0 * delta / bend);
}

/* tracer.numerics.point_errors and time_errors for the hits of one generic ray, its per-ray parts computed
 * once.  `r` is the primitive's prim_rounding: its inverse's error, size, |inverse|, |translation|; `gamma` the
 * scene's hit_gamma (the primitive's rounding is gamma + its inverse's error, as Primitive.rounding). */
typedef struct {
    double base;   /* the transformed origin's size before cancellation + |centred origin| + size */
    double reach;  /* max |d_generic| */
    double dd;     /* |d_generic|^2 */
    double rate;   /* rounding / size */
    double size;
} ErrorFrame;

static inline void error_frame(const double *o, const double *og, const double *dg, const double *r, double gamma,
                               ErrorFrame *f)
{
    f->base = r[2] * max_abs3(o) + r[3] + max_abs3(og) + r[1];
    f->reach = max_abs3(dg);
    f->dd = dot3(dg, dg);
    f->rate = (gamma + r[0]) / r[1];
    f->size = r[1];
}

/* The generic point error E of a hit at t, relative to the shape's size (the line's, across it). */
static inline double point_error(const ErrorFrame *f, double t)
{
    return f->rate * (f->base + (isfinite(t) ? fabs(t) : 0.0) * f->reach);
}

/* The bound on t's error beyond the shape's own root error (Hit.err), given |n| (`length`): G along the line
 * is off by |n| size E (the line's error across the surface), and the crossing moves by crossing_shift of
 * that (tracer.numerics.time_errors); a zero normal counts as grazing. */
static inline double time_error_of(const ErrorFrame *f, double error, const double *dg, const Hit *h, double nn,
                                   double length)
{
    if (!(nn > 0.0))
        return f->size * sqrt(error / f->dd);
    return crossing_shift(length * (f->size * error), fabs(dot3(h->n, dg)), fabs(h->bend));
}

static inline double time_error(const ErrorFrame *f, double error, const double *dg, const Hit *h)
{
    double nn = dot3(h->n, h->n);
    return time_error_of(f, error, dg, h, nn, sqrt(nn));
}

/* Is gap > time_error(f, error, dg, h)?  `along` is n . dg.  The bound is at most 2 |n| size E / |n.d|: most
 * hits, far from where the ray starts, are decided without a square root. */
static inline int exceeds_time_error(const ErrorFrame *f, double gap, double error, const double *dg, const Hit *h,
                                     double along)
{
    if (!(gap > 0.0))
        return 0;
    double line = f->size * error;
    if (gap * gap * (along * along) > 4.0 * dot3(h->n, h->n) * (line * line))
        return 1;
    return gap > time_error(f, error, dg, h);
}

/* Where a secondary ray starts (tracer.numerics.offset_distance): along the unit normal by the hit's
 * offset (its point's distance from the surface, bounded by the primitive) plus the rounding of the world
 * point o + t d and of the offset origin. */
static inline double offset_distance(double offset, double t, const double *o, const double *d, double offset_ulps)
{
    double u = DBL_EPSILON / 2.0, g = offset_ulps * u / (1.0 - offset_ulps * u);
    return offset + g * (max_abs3(o) + fabs(t) * max_abs3(d));
}

/* Roots of a t^2 + 2 b t + c = 0 given disc = b^2 - a c, as tracer.intersect.quadratic.solve_quadratic:
 * returns 0 where there are none (then lo, hi are untouched). */
static inline int solve_quadratic(double a, double b, double c, double disc, double *lo, double *hi)
{
    if (!(disc >= 0.0))
        return 0;
    double root = sqrt(disc);
    double q = -(b + (b >= 0.0 ? root : -root));
    double t1, t2;
    if (q == 0.0) {
        t1 = (c == 0.0) ? 0.0 : NAN;
        t2 = t1;
    } else {
        t1 = q / a;
        t2 = c / q;
    }
    double l = fmin_nan(t1, t2), h = fmax_nan(t1, t2);
    if (isnan(l) && isnan(h))
        return 0;
    *lo = l;
    *hi = h;
    return 1;
}

/* ---------------------------------------------------------------------------------------------------
 * Eigenvalues of a real n x n upper Hessenberg matrix (n <= 4) by the implicitly shifted double-shift QR
 * iteration (Francis steps with 3x3 Householder reflectors), after diagonal balancing by powers of two.
 * Only the eigenvalues are wanted, so transformations are applied to the active block only.
 * Returns 0 on success, -1 if the iteration did not converge.
 */

static void balance_small(double h[4][4], int n)
{
    int changed = 1;
    for (int sweep = 0; changed && sweep < 64; sweep++) {
        changed = 0;
        for (int i = 0; i < n; i++) {
            double col = 0.0, row = 0.0;
            for (int j = 0; j < n; j++) {
                if (j == i) continue;
                col += fabs(h[j][i]);
                row += fabs(h[i][j]);
            }
            if (col == 0.0 || row == 0.0)
                continue;
            /* Find the power of two f that brings the column norm (times f) and the row norm (over f)
             * closest together; apply it only if that shrinks their sum noticeably. */
            double total = col + row, f = 1.0, c = col;
            while (c < row / 2.0) { f *= 2.0; c *= 4.0; }
            while (c >= row * 2.0) { f /= 2.0; c /= 4.0; }
            if ((c + row) / f < 0.95 * total) {
                for (int j = 0; j < n; j++) {
                    h[i][j] /= f;
                    h[j][i] *= f;
                }
                changed = 1;
            }
        }
    }
}

/* Eigenvalues of [[a, b], [c, d]] without needless cancellation. */
static void eig2(double a, double b, double c, double d, double *r1, double *i1, double *r2, double *i2)
{
    double p = 0.5 * (a - d);
    double bc = b * c;
    double q = p * p + bc;
    if (q >= 0.0) {
        double z = p + copysign(sqrt(q), p);
        *r1 = d + z;
        *r2 = (z != 0.0) ? d - bc / z : d;
        *i1 = *i2 = 0.0;
    } else {
        double s = sqrt(-q);
        *r1 = *r2 = d + p;
        *i1 = s;
        *i2 = -s;
    }
}

static int hessenberg_eigenvalues(double h[4][4], int n, double *wr, double *wi)
{
    balance_small(h, n);
    double norm = 0.0;
    for (int i = 0; i < n; i++)
        for (int j = (i > 0 ? i - 1 : 0); j < n; j++)
            norm += fabs(h[i][j]);
    int hi = n - 1, iterations = 0;
    while (hi >= 0) {
        /* Deflate: find the start `lo` of the unreduced block ending at `hi`. */
        int lo = hi;
        while (lo > 0) {
            double s = fabs(h[lo - 1][lo - 1]) + fabs(h[lo][lo]);
            if (s == 0.0) s = norm;
            if (fabs(h[lo][lo - 1]) <= DBL_EPSILON * s) {
                h[lo][lo - 1] = 0.0;
                break;
            }
            lo--;
        }
        if (lo == hi) {
            wr[hi] = h[hi][hi];
            wi[hi] = 0.0;
            hi--;
            iterations = 0;
            continue;
        }
        if (lo == hi - 1) {
            eig2(h[hi - 1][hi - 1], h[hi - 1][hi], h[hi][hi - 1], h[hi][hi], &wr[hi - 1], &wi[hi - 1], &wr[hi], &wi[hi]);
            hi -= 2;
            iterations = 0;
            continue;
        }
        if (++iterations > 60)
            return -1;
        /* Shifts: the eigenvalues of the trailing 2x2 (as trace and determinant), or an exceptional pair
         * now and then to break a cycle. */
        double tr, det;
        if (iterations % 11 == 10) {
            double s = fabs(h[hi][hi - 1]) + fabs(h[hi - 1][hi - 2]);
            double a = 0.75 * s + h[hi][hi];
            tr = 2.0 * a;
            det = a * a + 0.4375 * s * s;
        } else {
            double a = h[hi - 1][hi - 1], b = h[hi - 1][hi], c = h[hi][hi - 1], d = h[hi][hi];
            tr = a + d;
            det = a * d - b * c;
        }
        /* First column of (H - s1 I)(H - s2 I) = H^2 - tr H + det I, restricted to the block. */
        double x = h[lo][lo] * h[lo][lo] + h[lo][lo + 1] * h[lo + 1][lo] - tr * h[lo][lo] + det;
        double y = h[lo + 1][lo] * (h[lo][lo] + h[lo + 1][lo + 1] - tr);
        double z = h[lo + 1][lo] * h[lo + 2][lo + 1];
        for (int k = lo; k <= hi - 1; k++) {
            int m = (k <= hi - 2) ? 3 : 2;  /* reflector size: 3, and 2 for the last step */
            double v[3] = {x, y, m == 3 ? z : 0.0};
            double scale = fabs(v[0]) + fabs(v[1]) + fabs(v[2]);
            if (scale != 0.0) {
                v[0] /= scale; v[1] /= scale; v[2] /= scale;
                double alpha = sqrt(v[0] * v[0] + v[1] * v[1] + v[2] * v[2]);
                if (v[0] > 0.0) alpha = -alpha;
                v[0] -= alpha;  /* v = x - alpha e1, the reflector maps x to alpha e1 */
                double vv = v[0] * v[0] + v[1] * v[1] + v[2] * v[2];
                if (vv != 0.0) {
                    double beta = 2.0 / vv;
                    int col0 = (k > lo) ? k - 1 : lo;
                    for (int j = col0; j <= hi; j++) {
                        double s = v[0] * h[k][j] + v[1] * h[k + 1][j];
                        if (m == 3) s += v[2] * h[k + 2][j];
                        s *= beta;
                        h[k][j] -= s * v[0];
                        h[k + 1][j] -= s * v[1];
                        if (m == 3) h[k + 2][j] -= s * v[2];
                    }
                    int row1 = (k + 3 < hi) ? k + 3 : hi;
                    for (int i = lo; i <= row1; i++) {
                        double s = h[i][k] * v[0] + h[i][k + 1] * v[1];
                        if (m == 3) s += h[i][k + 2] * v[2];
                        s *= beta;
                        h[i][k] -= s * v[0];
                        h[i][k + 1] -= s * v[1];
                        if (m == 3) h[i][k + 2] -= s * v[2];
                    }
                    if (k > lo) {  /* the bulge below the subdiagonal is gone */
                        h[k + 1][k - 1] = 0.0;
                        if (m == 3) h[k + 2][k - 1] = 0.0;
                    }
                }
            }
            if (k < hi - 1) {
                x = h[k + 1][k];
                y = h[k + 2][k];
                z = (k < hi - 2) ? h[k + 3][k] : 0.0;
            }
        }
    }
    return 0;
}

#endif
