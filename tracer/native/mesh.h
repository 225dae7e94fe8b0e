/* Rays against triangle meshes: the C form of tracer/intersect/mesh.py, walking the very same arrays (one
 * ray at a time instead of packets).  All-hits, closest-hit and any-hit queries; the tolerances, the
 * deduplication of shared-edge crossings and the ordering of coincident enter/exit pairs are those of the
 * NumPy code.
 *
 * A mesh is vertex-indexed: three int32 vertex (and normal) indices per triangle into the mesh's own
 * vertex and normal arrays, a leaf order, and 32-byte nodes.  Edges, scales, orientation and normals are
 * computed from the vertices where a hit needs them, with the NumPy code's operations in its order. */
#ifndef RT_MESH_H
#define RT_MESH_H

#include <stddef.h>
#include <stdlib.h>

#include "core.h"
#include "numeric.h"
#include "bvh_build.h"
#include "mesh_wide.h"

typedef struct {
    const BvhNode *nodes;
    int64_t n_nodes;
    WideNode *wide;  /* the same tree four children a node (mesh_wide.h; owned), or NULL: the binary walk */
    int64_t n_wide;
    int wide_mode;   /* WIDE_SCALAR or WIDE_SSE2 where there is a wide tree */
    BvhNode fingerprint[2];  /* the first and last binary node when the wide tree was made */
    const int32_t *order;       /* leaf slot -> triangle */
    const int32_t *tri_vertex;  /* 3 per triangle */
    const int32_t *tri_normal;  /* 3 per triangle (below 0: the triangle has no normals), or NULL */
    const double *vertices, *normals;
    const double *tri_uv;       /* 6 per triangle: its corners' texture coordinates, or NULL */
    int64_t n_tris, n_vertices, n_normals;
    double extent;
    int64_t depth;  /* longest root-to-leaf path, in nodes */
    double rounding_factor, barycentric_max, parallel_eps, dedupe, dedupe_adjacent;
} MeshView;

typedef struct {
    double o[3], d[3], inv[3], speed, magnitude;
    int finite_inv;  /* every 1 / d finite: no slab test can meet 0 * inf */
} MeshRay;

typedef struct {
    int64_t slot;  /* leaf-order triangle */
    double t, b1, b2;
    int entering;
} RawHit;

static inline void mesh_ray(MeshRay *r, const double *o, const double *d)
{
    for (int i = 0; i < 3; i++) {
        r->o[i] = o[i];
        r->d[i] = d[i];
        r->inv[i] = 1.0 / d[i];
    }
    r->speed = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
    r->magnitude = sqrt(o[0] * o[0] + o[1] * o[1] + o[2] * o[2]);
    r->finite_inv = isfinite(r->inv[0]) && isfinite(r->inv[1]) && isfinite(r->inv[2]) && isfinite(o[0]) &&
                    isfinite(o[1]) && isfinite(o[2]);
}

/* np.minimum / np.maximum: NaN wins. */
static inline double nan_min(double a, double b) { return (isnan(a) || isnan(b)) ? NAN : (a < b ? a : b); }
static inline double nan_max(double a, double b) { return (isnan(a) || isnan(b)) ? NAN : (a > b ? a : b); }

/* The node's box meets the ray for some t in [lower, upper]; a NaN slab (origin on a face plane of a
 * parallel ray) constrains nothing, as in TriangleMesh._slab.  A ray whose inverse direction (and origin)
 * is finite cannot make a NaN (box corners are finite), and then plain min/max give the same answer. */
static inline int slab_hit(const BvhNode *node, const MeshRay *r, double lower, double upper)
{
    const double *o = r->o, *inv = r->inv;
    if (r->finite_inv && !isnan(lower) && !isnan(upper)) {
        double near = lower, far = upper;
        for (int i = 0; i < 3; i++) {
            double a = ((double)node->lo[i] - o[i]) * inv[i], b = ((double)node->hi[i] - o[i]) * inv[i];
            double enter = a < b ? a : b, leave = a < b ? b : a;
            near = enter > near ? enter : near;
            far = leave < far ? leave : far;
        }
        return near <= far;
    }
    double near = NAN, far = NAN;
    for (int i = 0; i < 3; i++) {
        double a = ((double)node->lo[i] - o[i]) * inv[i], b = ((double)node->hi[i] - o[i]) * inv[i];
        near = fmax_nan(near, nan_min(a, b));
        far = fmin_nan(far, nan_max(a, b));
    }
    near = fmax_nan(near, lower);
    far = fmin_nan(far, upper);
    return near <= far;
}

static inline double length3(const double *v) { return sqrt(dot3(v, v)); }

/* The corners of triangle tri (original order). */
static inline void mesh_corners(const MeshView *m, int64_t tri, const double **p0, const double **p1,
                                const double **p2)
{
    const int32_t *index = m->tri_vertex + 3 * tri;
    *p0 = m->vertices + 3 * (int64_t)index[0];
    *p1 = m->vertices + 3 * (int64_t)index[1];
    *p2 = m->vertices + 3 * (int64_t)index[2];
}

static inline void mesh_edges(const MeshView *m, int64_t tri, double *e1, double *e2)
{
    const double *p0, *p1, *p2;
    mesh_corners(m, tri, &p0, &p1, &p2);
    for (int k = 0; k < 3; k++) {
        e1[k] = p1[k] - p0[k];
        e2[k] = p2[k] - p0[k];
    }
}

/* Moller-Trumbore's first half against the triangle in leaf slot i: its corners and edges, the determinant
 * and the barycentrics (u, v).  mesh_triangle_may_hit and mesh_triangle share it, so that the quick pass
 * computes exactly the numbers the full test rejects by. */
typedef struct {
    const double *p0, *p1, *p2;
    double e1[3], e2[3], qvec[3];
    double det, inv_det, u, v;
} MeshCrossing;

static inline void mesh_crossing(const MeshView *m, int64_t i, const MeshRay *r, MeshCrossing *c)
{
    mesh_corners(m, m->order[i], &c->p0, &c->p1, &c->p2);
    mesh_edges(m, m->order[i], c->e1, c->e2);
    const double *p0 = c->p0;
    double s[3] = {r->o[0] - p0[0], r->o[1] - p0[1], r->o[2] - p0[2]};
    double pvec[3];
    cross3(r->d, c->e2, pvec);
    c->det = dot3(c->e1, pvec);
    cross3(s, c->e1, c->qvec);
    c->inv_det = 1.0 / c->det;
    c->u = dot3(s, pvec) * c->inv_det;
    c->v = dot3(r->d, c->qvec) * c->inv_det;
}

/* The slack mesh_triangle allows is at most barycentric_max (the cap), so a barycentric beyond twice that is
 * a miss whatever the slack: rejected before the slack's square roots and divisions (most triangles of a
 * leaf are).  Without a branch, so that the quick pass over a leaf overlaps its loads. */
static inline int mesh_quickly_rejected(const MeshView *m, const MeshCrossing *c)
{
    double reject = 2.0 * m->barycentric_max;
    return (c->u < -reject) | (c->v < -reject) | (c->u + c->v > 1.0 + 2.0 * reject);
}

/* Whether the triangle in leaf slot i may be hit: mesh_triangle's quick rejection alone
 * (mesh_leaf_candidates). */
static inline int mesh_triangle_may_hit(const MeshView *m, int64_t i, const MeshRay *r)
{
    MeshCrossing c;
    mesh_crossing(m, i, r, &c);
    return !mesh_quickly_rejected(m, &c);
}

/* Bit k: the triangle in leaf slot first + k (k < count <= 64) may be hit (mesh_triangle_may_hit). */
static inline uint64_t mesh_leaf_candidates(const MeshView *m, int64_t first, int64_t count, const MeshRay *r)
{
    uint64_t may = 0;
    for (int64_t k = 0; k < count; k++)
        may |= (uint64_t)mesh_triangle_may_hit(m, first + k, r) << k;
    return may;
}

/* Moller-Trumbore against the triangle in leaf slot i. */
static inline int mesh_triangle(const MeshView *m, int64_t i, const MeshRay *r, double *t, double *b1, double *b2)
{
    MeshCrossing c;
    mesh_crossing(m, i, r, &c);
    if (mesh_quickly_rejected(m, &c))
        return 0;
    const double *p0 = c.p0, *p1 = c.p1, *p2 = c.p2;
    const double *e1 = c.e1, *e2 = c.e2, *qvec = c.qvec;
    double det = c.det, inv_det = c.inv_det, u = c.u, v = c.v;
    double tt = dot3(e2, qvec) * inv_det;
    /* The barycentric slack bounds the rounding of this ray and triangle (see ROUNDING_FACTOR in
     * mesh.py), capped for near-parallel rays; its scales are the largest vertex norm and the edges. */
    double radius = nan_max(nan_max(length3(p0), length3(p1)), length3(p2));
    double e1_length = length3(e1), e2_length = length3(e2);
    double abs_det = fabs(det);
    double s1 = e2_length + radius, s2 = e1_length + radius;
    double rounding = m->rounding_factor * DBL_EPSILON * r->speed * (r->magnitude + radius) / abs_det;
    double cap = m->barycentric_max / nan_max(s1, s2);
    rounding = nan_min(rounding, cap);
    double slack1 = rounding * s1, slack2 = rounding * s2;
    if (abs_det > m->parallel_eps * r->speed * (e1_length * e2_length) && u >= -slack1 && v >= -slack2 &&
        u + v <= 1.0 + slack1 + slack2 && isfinite(tt)) {
        *t = tt;
        *b1 = u;
        *b2 = v;
        return 1;
    }
    return 0;
}

/* The unit vertex normals of triangle tri (zero where a normal is zero, all zero where the triangle has
 * none); returns whether it has normals.  (TriangleMesh._unit_corner_normals) */
static inline int mesh_corner_normals(const MeshView *m, int64_t tri, double c[3][3])
{
    const int32_t *index = m->tri_normal ? m->tri_normal + 3 * tri : NULL;
    int has = index && index[0] >= 0 && index[1] >= 0 && index[2] >= 0;
    for (int j = 0; j < 3; j++) {
        double length = has ? length3(m->normals + 3 * (int64_t)index[j]) : 0.0;
        for (int k = 0; k < 3; k++)
            c[j][k] = length > 0.0 ? m->normals[3 * (int64_t)index[j] + k] / length : 0.0;
    }
    return has;
}

/* TriangleMesh.smooth_lift: how far the point at barycentrics (b1, b2) of triangle tri moves onto the smooth
 * surface of its vertex normals (generic); returns 0 (and no move) for a triangle without normals. */
static inline int mesh_smooth_lift(const MeshView *m, int64_t tri, double b1, double b2, double *lift)
{
    double c[3][3];
    int has = mesh_corner_normals(m, tri, c);
    lift[0] = lift[1] = lift[2] = 0.0;
    if (!has)
        return 0;
    const double *p[3];
    mesh_corners(m, tri, &p[0], &p[1], &p[2]);
    double w[3] = {1.0 - b1 - b2, b1, b2}, g[3], mixed[3];
    for (int k = 0; k < 3; k++)
        g[k] = (w[0] * p[0][k] + w[1] * p[1][k]) + w[2] * p[2][k];
    for (int j = 0; j < 3; j++) {
        double to[3] = {g[0] - p[j][0], g[1] - p[j][1], g[2] - p[j][2]};
        double below = nan_min(dot3(to, c[j]), 0.0);
        for (int k = 0; k < 3; k++) {
            double q = g[k] - below * c[j][k];
            mixed[k] = j == 0 ? w[0] * q : mixed[k] + w[j] * q;
        }
    }
    for (int k = 0; k < 3; k++)
        lift[k] = mixed[k] - g[k];
    return 1;
}

/* The winding normal E1 x E2 of triangle tri into w; returns whether the unit corner normals, summed,
 * point against it (the geometric normal is then -w).  (TriangleMesh._geometric) */
static inline int mesh_winding(const MeshView *m, int64_t tri, const double c[3][3], double *w)
{
    double e1[3], e2[3], sum[3];
    mesh_edges(m, tri, e1, e2);
    cross3(e1, e2, w);
    for (int k = 0; k < 3; k++)
        sum[k] = (c[0][k] + c[1][k]) + c[2][k];
    return dot3(sum, w) < 0.0;
}

static inline int mesh_entering(const MeshView *m, int64_t slot, const double *d)
{
    double c[3][3], w[3];
    int64_t tri = m->order[slot];
    mesh_corner_normals(m, tri, c);
    int flip = mesh_winding(m, tri, c, w);
    double facing = dot3(d, w);
    return flip ? facing > 0.0 : facing < 0.0;
}

/* The unit geometric normal g (generic; zero for a degenerate triangle) of original triangle `tri`, on the
 * side its corner normals c (filled in) point to, as mesh_normal_entering forms it; returns whether it has
 * corner normals (smooth shading).  (TriangleMesh.geometric_normals) */
static inline int mesh_geometric_normal(const MeshView *m, int64_t tri, double c[3][3], double *g)
{
    int has = mesh_corner_normals(m, tri, c);
    int flip = mesh_winding(m, tri, c, g);
    if (flip)
        for (int k = 0; k < 3; k++)
            g[k] = -g[k];
    double g_length = length3(g);
    for (int k = 0; k < 3; k++)
        g[k] = g_length > 0.0 ? g[k] / g_length : 0.0;
    return has;
}

/* Unit shading normal (generic) of original triangle `tri` at barycentrics (b1, b2). */
/* mesh_normal, and whether a ray along d enters there (mesh_entering), from one set of corner normals. */
static inline int mesh_normal_entering(const MeshView *m, int64_t tri, double b1, double b2, const double *d,
                                       double *n)
{
    double c[3][3], g[3];
    int has = mesh_corner_normals(m, tri, c);
    int flip = mesh_winding(m, tri, c, g);
    double facing = d ? dot3(d, g) : 0.0;
    int entering = flip ? facing > 0.0 : facing < 0.0;
    if (flip)
        for (int k = 0; k < 3; k++)
            g[k] = -g[k];
    double g_length = length3(g);
    for (int k = 0; k < 3; k++)
        g[k] = g_length > 0.0 ? g[k] / g_length : 0.0;
    double w0 = 1.0 - b1 - b2;
    double s[3];
    for (int k = 0; k < 3; k++)
        s[k] = w0 * c[0][k] + b1 * c[1][k] + b2 * c[2][k];
    double length = length3(s);
    if (has && length > 1e-12 && dot3(s, g) > 0.0) {
        n[0] = s[0] / length;
        n[1] = s[1] / length;
        n[2] = s[2] / length;
    } else {
        n[0] = g[0];
        n[1] = g[1];
        n[2] = g[2];
    }
    return entering;
}

static inline void mesh_normal(const MeshView *m, int64_t tri, double b1, double b2, double *n)
{
    mesh_normal_entering(m, tri, b1, b2, NULL, n);
}

static inline void mesh_fill_hit(const MeshView *m, int64_t slot, double t, double b1, double b2, int entering, Hit *h)
{
    int64_t tri = m->order[slot];
    h->t = t;
    mesh_normal(m, tri, b1, b2, h->n);
    h->uv[0] = b1;
    h->uv[1] = b2;
    h->part = (int32_t)tri;
    h->shape = -1;
    h->entering = entering;
    h->err = 0.0;  /* the primitive adds the bound on t's rounding (core.c, tracer.numerics) */
}

/* mesh_fill_hit with the flag mesh_entering gives a ray along d, the corner normals found once. */
static inline void mesh_fill_hit_along(const MeshView *m, int64_t slot, double t, double b1, double b2, const double *d,
                                       Hit *h)
{
    int64_t tri = m->order[slot];
    h->t = t;
    h->entering = mesh_normal_entering(m, tri, b1, b2, d, h->n);
    h->uv[0] = b1;
    h->uv[1] = b2;
    h->part = (int32_t)tri;
    h->shape = -1;
    h->err = 0.0;
}

/* The leaf's triangles in slot order: a hit with lower < t < *best_t becomes the best. */
static inline void mesh_leaf_closest(const MeshView *m, const MeshRay *r, int64_t first, int64_t count, double lower,
                                     double *best_t, double *best_b1, double *best_b2, int64_t *best_slot)
{
    /* (in runs of 64: first which may be hit, then those in slot order) */
    for (int64_t start = first; start < first + count; start += 64) {
        int64_t run = first + count - start < 64 ? first + count - start : 64;
        for (uint64_t may = mesh_leaf_candidates(m, start, run, r); may; may &= may - 1) {
            int64_t i = start + __builtin_ctzll(may);
            double t, b1, b2;
            if (mesh_triangle(m, i, r, &t, &b1, &b2) && t > lower && t < *best_t) {
                *best_t = t;
                *best_b1 = b1;
                *best_b2 = b2;
                *best_slot = i;
            }
        }
    }
}

static inline int mesh_leaf_any(const MeshView *m, const MeshRay *r, int64_t first, int64_t count, double lower,
                                double upper)
{
    for (int64_t start = first; start < first + count; start += 64) {
        int64_t run = first + count - start < 64 ? first + count - start : 64;
        for (uint64_t may = mesh_leaf_candidates(m, start, run, r); may; may &= may - 1) {
            double t, b1, b2;
            if (mesh_triangle(m, start + __builtin_ctzll(may), r, &t, &b1, &b2) && t > lower && t < upper)
                return 1;
        }
    }
    return 0;
}

/* Growable buffer of raw hits (per thread). */
typedef struct {
    RawHit *h;
    int64_t n, cap;
} RawBuffer;

static int raw_push(RawBuffer *b, int64_t slot, double t, double b1, double b2)
{
    if (b->n == b->cap) {
        int64_t cap = b->cap ? 2 * b->cap : 64;
        RawHit *p = (RawHit *)realloc(b->h, (size_t)cap * sizeof(RawHit));
        if (!p)
            return 0;
        b->h = p;
        b->cap = cap;
    }
    RawHit *h = &b->h[b->n++];
    h->slot = slot;
    h->t = t;
    h->b1 = b1;
    h->b2 = b2;
    h->entering = 0;
    return 1;
}

/* Stable insertion sorts of raw hits (hit lists of one line are short). */
static void raw_sort_by_sign_then_t(RawHit *h, int64_t n)
{
    for (int64_t i = 1; i < n; i++) {
        RawHit x = h[i];
        int64_t j = i;
        while (j > 0 && (h[j - 1].entering > x.entering || (h[j - 1].entering == x.entering && h[j - 1].t > x.t))) {
            h[j] = h[j - 1];
            j--;
        }
        h[j] = x;
    }
}

static void raw_sort_by_t(RawHit *h, int64_t n)
{
    for (int64_t i = 1; i < n; i++) {
        RawHit x = h[i];
        int64_t j = i;
        while (j > 0 && h[j - 1].t > x.t) {
            h[j] = h[j - 1];
            j--;
        }
        h[j] = x;
    }
}

/* Do the triangles in leaf slots a and b share a vertex, by index or by position?
 * (TriangleMesh._touching) */
static inline int mesh_touching(const MeshView *m, int64_t a, int64_t b)
{
    const int32_t *va = m->tri_vertex + 3 * (int64_t)m->order[a], *vb = m->tri_vertex + 3 * (int64_t)m->order[b];
    for (int x = 0; x < 3; x++)
        for (int y = 0; y < 3; y++) {
            if (va[x] == vb[y])
                return 1;
            const double *p = m->vertices + 3 * (int64_t)va[x], *q = m->vertices + 3 * (int64_t)vb[y];
            if (p[0] == q[0] && p[1] == q[1] && p[2] == q[2])
                return 1;
        }
    return 0;
}

/* How far apart hits a and b may be and still be one place (mesh.py's _dedupe_window): wider when the two
 * triangles share a vertex. */
static inline double dedupe_window(const MeshView *m, const RawHit *a, const RawHit *b, double tol_scale)
{
    double scale = fmax_nan(fabs(b->t), fabs(a->t)) + tol_scale;
    return (mesh_touching(m, a->slot, b->slot) ? m->dedupe_adjacent : m->dedupe) * scale;
}

/* Every crossing of the leaf's triangles, kept raw; 0 when memory ran out. */
static inline int mesh_leaf_all(const MeshView *m, const MeshRay *r, int64_t first, int64_t count, RawBuffer *raw)
{
    for (int64_t start = first; start < first + count; start += 64) {
        int64_t run = first + count - start < 64 ? first + count - start : 64;
        for (uint64_t may = mesh_leaf_candidates(m, start, run, r); may; may &= may - 1) {
            int64_t i = start + __builtin_ctzll(may);
            double t, b1, b2;
            if (mesh_triangle(m, i, r, &t, &b1, &b2) && !raw_push(raw, i, t, b1, b2))
                return 0;
        }
    }
    return 1;
}

/* The wide walks (mesh_wide.h: the same leaves in the same order as the binary walk) are written once, always
 * inlined with `mode` the box test, and made twice: for the build's baseline (the scalar or SSE2 test the scene
 * chose) and, where the compiler can, compiled for AVX2 with its test, called when the scene chose AVX2. */
#define RT_WALK_INLINE inline __attribute__((always_inline))

/* mesh_closest's walk of the wide tree. */
static RT_WALK_INLINE void mesh_closest_wide_walk(int mode, const MeshView *m, const MeshRay *r, const WideRay *wr,
                                                  double lower, WideEntry *stack, double *best_t, double *best_b1,
                                                  double *best_b2, int64_t *best_slot)
{
    int64_t top = 0;
    WideEntry e = {0, 0, lower};
    for (;;) {
        if (e.count) {
            mesh_leaf_closest(m, r, e.child, e.count, lower, best_t, best_b1, best_b2, best_slot);
        } else {
            const WideNode *node = &m->wide[e.child];
            double near[WIDE_CHILDREN];
            int mask = wide_hit(mode, node, wr, lower, *best_t, near);
            if (mask)
                wide_push(node, mask, near, wr->octant, stack, &top);
        }
        do {
            if (!top)
                return;
            e = stack[--top];
        } while (e.near > *best_t);
    }
}

/* mesh_any's: whether a leaf the ray meets has a hit with lower < t < upper (nearer leaves first; the answer
 * does not depend on the order). */
static RT_WALK_INLINE int mesh_any_wide_walk(int mode, const MeshView *m, const MeshRay *r, const WideRay *wr,
                                             double lower, double upper, WideEntry *stack)
{
    int64_t top = 0;
    WideEntry e = {0, 0, lower};
    for (;;) {
        if (e.count) {
            if (mesh_leaf_any(m, r, e.child, e.count, lower, upper))
                return 1;
        } else {
            const WideNode *node = &m->wide[e.child];
            double near[WIDE_CHILDREN];
            int mask = wide_hit(mode, node, wr, lower, upper, near);
            if (mask)
                wide_push(node, mask, near, wr->octant, stack, &top);
        }
        if (!top)
            return 0;
        e = stack[--top];
    }
}

/* mesh_all's: every crossing of the leaves the line meets, left first (the binary walk's order: octant 0's),
 * into raw; 0 when memory ran out. */
static RT_WALK_INLINE int mesh_all_wide_walk(int mode, const MeshView *m, const MeshRay *r, const WideRay *wr,
                                             WideEntry *stack, RawBuffer *raw)
{
    int64_t top = 0;
    WideEntry e = {0, 0, -INFINITY};
    for (;;) {
        if (e.count) {
            if (!mesh_leaf_all(m, r, e.child, e.count, raw))
                return 0;
        } else {
            const WideNode *node = &m->wide[e.child];
            double near[WIDE_CHILDREN];
            int mask = wide_hit(mode, node, wr, -INFINITY, INFINITY, near);
            if (mask)
                wide_push(node, mask, near, 0, stack, &top);
        }
        if (!top)
            return 1;
        e = stack[--top];
    }
}

#if RT_WIDE_AVX2
RT_TARGET_AVX2 static void mesh_closest_wide_avx2(const MeshView *m, const MeshRay *r, const WideRay *wr,
                                                  double lower, WideEntry *stack, double *best_t, double *best_b1,
                                                  double *best_b2, int64_t *best_slot)
{
    mesh_closest_wide_walk(WIDE_AVX2, m, r, wr, lower, stack, best_t, best_b1, best_b2, best_slot);
}

RT_TARGET_AVX2 static int mesh_any_wide_avx2(const MeshView *m, const MeshRay *r, const WideRay *wr, double lower,
                                             double upper, WideEntry *stack)
{
    return mesh_any_wide_walk(WIDE_AVX2, m, r, wr, lower, upper, stack);
}

RT_TARGET_AVX2 static int mesh_all_wide_avx2(const MeshView *m, const MeshRay *r, const WideRay *wr,
                                             WideEntry *stack, RawBuffer *raw)
{
    return mesh_all_wide_walk(WIDE_AVX2, m, r, wr, stack, raw);
}
#endif

/* The box test of the baseline walks: the scene's choice, AVX2 aside. */
static inline int mesh_baseline_mode(const MeshView *m)
{
    return m->wide_mode == WIDE_SSE2 ? WIDE_SSE2 : WIDE_SCALAR;
}

static void mesh_closest_wide(const MeshView *m, const MeshRay *r, const WideRay *wr, double lower,
                              WideEntry *stack, double *best_t, double *best_b1, double *best_b2, int64_t *best_slot)
{
#if RT_WIDE_AVX2
    if (m->wide_mode == WIDE_AVX2) {
        mesh_closest_wide_avx2(m, r, wr, lower, stack, best_t, best_b1, best_b2, best_slot);
        return;
    }
#endif
    mesh_closest_wide_walk(mesh_baseline_mode(m), m, r, wr, lower, stack, best_t, best_b1, best_b2, best_slot);
}

static int mesh_any_wide(const MeshView *m, const MeshRay *r, const WideRay *wr, double lower, double upper,
                         WideEntry *stack)
{
#if RT_WIDE_AVX2
    if (m->wide_mode == WIDE_AVX2)
        return mesh_any_wide_avx2(m, r, wr, lower, upper, stack);
#endif
    return mesh_any_wide_walk(mesh_baseline_mode(m), m, r, wr, lower, upper, stack);
}

static int mesh_all_wide(const MeshView *m, const MeshRay *r, const WideRay *wr, WideEntry *stack, RawBuffer *raw)
{
#if RT_WIDE_AVX2
    if (m->wide_mode == WIDE_AVX2)
        return mesh_all_wide_avx2(m, r, wr, stack, raw);
#endif
    return mesh_all_wide_walk(mesh_baseline_mode(m), m, r, wr, stack, raw);
}

/* The first hit with lower < t < upper (nearer child first, by the ray's own direction). */
static int mesh_closest(const MeshView *m, const double *o, const double *d, double lower, double upper,
                        int64_t *stack, WideEntry *wide_stack, Hit *out)
{
    if (m->n_nodes == 0)
        return 0;
    MeshRay r;
    mesh_ray(&r, o, d);
    double best_t = upper, best_b1 = 0.0, best_b2 = 0.0;
    int64_t best_slot = -1, top = 0;
    WideRay wr;
    if (m->wide && wide_ray(r.o, r.inv, r.d, lower, upper, &wr)) {
        mesh_closest_wide(m, &r, &wr, lower, wide_stack, &best_t, &best_b1, &best_b2, &best_slot);
        goto found;
    }
    stack[top++] = 0;
    while (top) {
        int64_t node = stack[--top];
        const BvhNode *nd = &m->nodes[node];
        if (!slab_hit(nd, &r, lower, best_t))
            continue;
        if (nd->count) {
            mesh_leaf_closest(m, &r, nd->offset, nd->count, lower, &best_t, &best_b1, &best_b2, &best_slot);
            continue;
        }
        int64_t near = nd->offset, far = nd->offset + 1;
        if (r.d[nd->axis] < 0.0) {
            int64_t x = near; near = far; far = x;
        }
        stack[top++] = far;
        stack[top++] = near;
    }
found:
    if (best_slot < 0)
        return 0;
    mesh_fill_hit_along(m, best_slot, best_t, best_b1, best_b2, d, out);
    return 1;
}

/* Any hit with lower < t < upper (shadow feelers); the leaves are tried nearer first on the wide walk (the
 * answer does not depend on the order). */
static int mesh_any(const MeshView *m, const double *o, const double *d, double lower, double upper, int64_t *stack,
                    WideEntry *wide_stack)
{
    if (m->n_nodes == 0)
        return 0;
    MeshRay r;
    mesh_ray(&r, o, d);
    WideRay wr;
    if (m->wide && wide_ray(r.o, r.inv, r.d, lower, upper, &wr))
        return mesh_any_wide(m, &r, &wr, lower, upper, wide_stack);
    int64_t top = 0;
    stack[top++] = 0;
    while (top) {
        int64_t node = stack[--top];
        const BvhNode *nd = &m->nodes[node];
        if (!slab_hit(nd, &r, lower, upper))
            continue;
        if (nd->count) {
            if (mesh_leaf_any(m, &r, nd->offset, nd->count, lower, upper))
                return 1;
            continue;
        }
        stack[top++] = nd->offset + 1;
        stack[top++] = nd->offset;
    }
    return 0;
}

/* Every crossing of the whole line, deduplicated and ordered as TriangleMesh.all_hits.  Grows
 * *out_buffer as needed and returns the count, or -1 when memory ran out. */
static int64_t mesh_all(const MeshView *m, const double *o, const double *d, int64_t *stack, WideEntry *wide_stack,
                        RawBuffer *raw, Hit **out_buffer, int64_t *out_capacity)
{
    raw->n = 0;
    if (m->n_nodes == 0)
        return 0;
    MeshRay r;
    mesh_ray(&r, o, d);
    WideRay wr;
    if (m->wide && wide_ray(r.o, r.inv, r.d, -INFINITY, INFINITY, &wr)) {
        if (!mesh_all_wide(m, &r, &wr, wide_stack, raw))
            return -1;
    } else {
        int64_t top = 0;
        stack[top++] = 0;
        while (top) {
            int64_t node = stack[--top];
            const BvhNode *nd = &m->nodes[node];
            if (!slab_hit(nd, &r, -INFINITY, INFINITY))
                continue;
            if (nd->count) {
                if (!mesh_leaf_all(m, &r, nd->offset, nd->count, raw))
                    return -1;
                continue;
            }
            stack[top++] = nd->offset + 1;
            stack[top++] = nd->offset;
        }
    }
    int64_t n = raw->n;
    if (n == 0)
        return 0;
    RawHit *h = raw->h;
    for (int64_t i = 0; i < n; i++)
        h[i].entering = mesh_entering(m, h[i].slot, d);
    double tol_scale = m->extent / (r.speed > 0.0 ? r.speed : 1.0);

    /* Drop repeated crossings (a shared edge or vertex hit twice, coincident faces): same sign, within
     * the window of the hit before in (sign, t) order.  Compacting in place never overwrites h[i - 1]
     * before it is read. */
    raw_sort_by_sign_then_t(h, n);
    int64_t kept = 0;
    for (int64_t i = 0; i < n; i++) {
        int repeat = i > 0 && h[i].entering == h[i - 1].entering &&
                     h[i].t - h[i - 1].t <= dedupe_window(m, &h[i - 1], &h[i], tol_scale);
        if (!repeat)
            h[kept++] = h[i];
    }
    n = kept;

    /* Sort by time (stable: on equal times exits, which came first, stay first).  An enter and an exit
     * at (nearly) the same time go in the order that alternates with what came before: outside (net
     * enters <= 0) -> enter first, inside -> exit first. */
    raw_sort_by_t(h, n);
    if (n > 1) {
        uint8_t small[64];
        uint8_t *tie = n <= 64 ? small : (uint8_t *)malloc((size_t)n);
        if (!tie)
            return -1;
        for (int64_t i = 0; i + 1 < n; i++)
            tie[i] = h[i + 1].entering != h[i].entering &&
                     h[i + 1].t - h[i].t <= dedupe_window(m, &h[i], &h[i + 1], tol_scale);
        tie[n - 1] = 0;
        for (int64_t i = n - 1; i > 0; i--)  /* pairs do not overlap: tie[i] &= !tie[i - 1] (old values) */
            tie[i] = tie[i] && !tie[i - 1];
        int64_t net = 0;  /* enters minus exits before hit i */
        for (int64_t i = 0; i < n; i++) {
            int64_t before = net;
            net += h[i].entering ? 1 : -1;
            if (i + 1 < n && tie[i]) {  /* a pair: its net count does not depend on its order */
                net += h[i + 1].entering ? 1 : -1;
                if (h[i].entering == (before > 0)) {
                    RawHit a = h[i];
                    h[i].slot = h[i + 1].slot;
                    h[i].b1 = h[i + 1].b1;
                    h[i].b2 = h[i + 1].b2;
                    h[i].entering = h[i + 1].entering;
                    h[i + 1].slot = a.slot;
                    h[i + 1].b1 = a.b1;
                    h[i + 1].b2 = a.b2;
                    h[i + 1].entering = a.entering;
                }
                i++;
            }
        }
        if (tie != small)
            free(tie);
    }

    if (n > *out_capacity) {
        int64_t cap = *out_capacity ? *out_capacity : 16;
        while (cap < n)
            cap *= 2;
        Hit *p = (Hit *)realloc(*out_buffer, (size_t)cap * sizeof(Hit));
        if (!p)
            return -1;
        *out_buffer = p;
        *out_capacity = cap;
    }
    for (int64_t i = 0; i < n; i++)
        mesh_fill_hit(m, h[i].slot, h[i].t, h[i].b1, h[i].b2, h[i].entering, &(*out_buffer)[i]);
    return n;
}

#endif
