/* A mesh's BVH walked four children at a time: the binary tree of bvh_build.h (the NumPy reference's tree,
 * which the C core is given) collapsed into nodes of up to four children whose boxes are tested together,
 * two lanes of double arithmetic at a time where the CPU has SSE2.
 *
 * The walk finds exactly what the binary walk of mesh.h finds (the same hit, bit for bit, and the same
 * triangle on a tie), because:
 *  - the box test is the binary walk's: the same single-precision boxes, widened to double exactly, and the
 *    same double slab arithmetic (near = max(lower, enter), far = min(upper, leave), in axis order), with the
 *    near plane of each slab picked by the sign of 1 / d, which gives the same numbers as min / max of the two
 *    planes' times when no time is NaN: so only rays whose origin and every 1 / d are finite and non-zero
 *    (and whose interval has no NaN) come here; the others take the binary walk;
 *  - the binary nodes a wide node skips over are never tested: that loses nothing because every box of the
 *    tree holds its children's boxes (checked when the wide tree is made; a tree where one does not is
 *    walked as a binary tree), and a box inside another passes the slab test only where the other does;
 *  - the leaves are tried in the binary walk's order: at each binary node the child on the side the ray
 *    comes from first (by the sign of d along the node's split axis), the left child for all-hits and
 *    any-hit; a wide node keeps that order for each of the eight octants of the direction;
 *  - a child queued with its entry time `near` (max of lower and the slabs' entry) is taken only while near
 *    <= the best hit so far: the binary walk's test of that box at that moment, since its exit was past near.
 *
 * The four boxes are tested together with AVX (four doubles a register) where the CPU has AVX2 (asked at run
 * time: the walks are compiled twice, once for the build's baseline and once for AVX2, mesh.h), else two at
 * a time with SSE2, else one at a time; the arithmetic is the same (IEEE operations lane by lane, and the
 * build contracts nothing into fused multiply-adds), so every path gives the same answers.  The environment,
 * read when a scene is made: SDL_TRACER_SIMD=sse2 keeps to SSE2 (a CPU without AVX2), SDL_TRACER_SIMD=0 tests
 * the boxes one at a time (the path of builds without SSE2), SDL_TRACER_MESH_BVH=binary walks the binary
 * tree (the reference the tests compare with). */
#ifndef RT_MESH_WIDE_H
#define RT_MESH_WIDE_H

#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#define RT_WIDE_SSE2 1
#else
#define RT_WIDE_SSE2 0
#endif

/* AVX2 code in a build for an older baseline: GCC's and Clang's per-function target attribute on x86
 * (RT_NO_AVX2 leaves it out). */
#if RT_WIDE_SSE2 && (defined(__x86_64__) || defined(__i386__)) && defined(__GNUC__) && !defined(RT_NO_AVX2)
#include <immintrin.h>
#define RT_WIDE_AVX2 1
#define RT_TARGET_AVX2 __attribute__((target("avx2")))
#else
#define RT_WIDE_AVX2 0
#endif

#include "bvh_build.h"

#define WIDE_CHILDREN 4

/* A node of up to four children.  A child is a leaf (count > 0: the triangles in leaf slots child ..
 * child + count - 1), an inner wide node (count 0: its index), or nothing (child -1, an empty box that no
 * ray the wide walk takes can enter: lo +inf, hi -inf).  order[octant] lists the four children in the order
 * the binary walk reaches them for a direction in that octant (bit k set: d[k] < 0), two bits each, the
 * first in the lowest bits; order[0] is also the left-first order of all-hits and any-hit. */
typedef struct {
    float box[2][3][WIDE_CHILDREN];  /* [0: lo, 1: hi][axis][child]: the binary nodes' boxes as they are */
    int32_t child[WIDE_CHILDREN];
    uint16_t count[WIDE_CHILDREN];
    uint8_t order[8];
} WideNode;

_Static_assert(sizeof(WideNode) == 128, "WideNode: two cache lines");

/* A child waiting on the walk's stack, and where the ray enters its box. */
typedef struct {
    int32_t child;
    int32_t count;
    double near;
} WideEntry;

/* How the mesh walks are done (wide_mode, from the environment when a scene is made). */
enum { WIDE_OFF = 0, WIDE_SCALAR = 1, WIDE_SSE2 = 2, WIDE_AVX2 = 3 };

/* Whether this CPU (and its operating system, which must save the wide registers) runs AVX2 code. */
static int wide_cpu_has_avx2(void)
{
#if RT_WIDE_AVX2
    __builtin_cpu_init();
    return __builtin_cpu_supports("avx2") != 0;
#else
    return 0;
#endif
}

static int wide_mode_from_environment(void)
{
    const char *bvh = getenv("SDL_TRACER_MESH_BVH");
    if (bvh && strcmp(bvh, "binary") == 0)
        return WIDE_OFF;
    const char *simd = getenv("SDL_TRACER_SIMD");
    if ((simd && strcmp(simd, "0") == 0) || !RT_WIDE_SSE2)
        return WIDE_SCALAR;
    if ((simd && strcmp(simd, "sse2") == 0) || !wide_cpu_has_avx2())
        return WIDE_SSE2;
    return WIDE_AVX2;
}

/* ------------------------------------------------------------------------------------------------------
 * Making the wide tree */

static inline double wide_half_area(const BvhNode *n)
{
    double x = (double)n->hi[0] - n->lo[0], y = (double)n->hi[1] - n->lo[1], z = (double)n->hi[2] - n->lo[2];
    return x * y + y * z + z * x;
}

/* Whether every box is ordered (lo <= hi, no NaN) and holds its children's boxes: what lets the wide walk
 * skip the boxes of the binary nodes it collapses. */
static int wide_boxes_nest(const BvhNode *nodes, int64_t n)
{
    for (int64_t k = 0; k < n; k++) {
        const BvhNode *p = &nodes[k];
        for (int i = 0; i < 3; i++)
            if (!(p->lo[i] <= p->hi[i]))
                return 0;
        if (p->count)
            continue;
        for (int c = 0; c < 2; c++) {
            const BvhNode *q = &nodes[p->offset + c];
            for (int i = 0; i < 3; i++)
                if (!(p->lo[i] <= q->lo[i] && q->hi[i] <= p->hi[i]))
                    return 0;
        }
    }
    return 1;
}

/* The binary nodes one wide node stands for: up to four frontier nodes (its children, in the binary tree's
 * left-to-right order) under at most three collapsed inner nodes. */
typedef struct {
    int64_t frontier[WIDE_CHILDREN];
    int n;
} WideGroup;

/* The frontier under binary inner node `root`: its two children, then, while there is room, the inner
 * frontier node of the largest box replaced by its two children (in place, keeping the left-to-right order). */
static void wide_group(const BvhNode *nodes, int64_t root, WideGroup *g)
{
    g->n = 2;
    g->frontier[0] = nodes[root].offset;
    g->frontier[1] = nodes[root].offset + 1;
    while (g->n < WIDE_CHILDREN) {
        int pick = -1;
        double largest = -1.0;
        for (int j = 0; j < g->n; j++) {
            const BvhNode *f = &nodes[g->frontier[j]];
            double area = wide_half_area(f);
            if (!f->count && area > largest) {
                largest = area;
                pick = j;
            }
        }
        if (pick < 0)
            return;
        int64_t inner = g->frontier[pick];
        for (int j = g->n; j > pick + 1; j--)
            g->frontier[j] = g->frontier[j - 1];
        g->frontier[pick] = nodes[inner].offset;
        g->frontier[pick + 1] = nodes[inner].offset + 1;
        g->n++;
    }
}

/* Appends to `out` the frontier positions under binary node `node` in the order the binary walk reaches
 * them for a direction in `octant`. */
static void wide_walk_order(const BvhNode *nodes, const WideGroup *g, int64_t node, int octant, int *out, int *n)
{
    for (int j = 0; j < g->n; j++)
        if (g->frontier[j] == node) {
            out[(*n)++] = j;
            return;
        }
    int64_t first = nodes[node].offset, second = first + 1;
    if (octant >> nodes[node].axis & 1) {
        int64_t x = first; first = second; second = x;
    }
    wide_walk_order(nodes, g, first, octant, out, n);
    wide_walk_order(nodes, g, second, octant, out, n);
}

/* The wide node for binary inner node `root` (its inner children still to be numbered: child = the binary
 * node's index, count 0). */
static void wide_fill(const BvhNode *nodes, int64_t root, WideNode *w, WideGroup *g)
{
    wide_group(nodes, root, g);
    for (int j = 0; j < WIDE_CHILDREN; j++) {
        const BvhNode *f = j < g->n ? &nodes[g->frontier[j]] : NULL;
        for (int i = 0; i < 3; i++) {
            w->box[0][i][j] = f ? f->lo[i] : INFINITY;
            w->box[1][i][j] = f ? f->hi[i] : -INFINITY;
        }
        w->child[j] = f ? (f->count ? f->offset : (int32_t)g->frontier[j]) : -1;
        w->count[j] = f ? f->count : 0;
    }
    for (int octant = 0; octant < 8; octant++) {
        int seq[WIDE_CHILDREN], n = 0;
        wide_walk_order(nodes, g, root, octant, seq, &n);
        for (int j = g->n; j < WIDE_CHILDREN; j++)
            seq[n++] = j;
        w->order[octant] = (uint8_t)(seq[0] | seq[1] << 2 | seq[2] << 4 | seq[3] << 6);
    }
}

/* The wide tree of a checked binary tree of n >= 1 nodes (mesh_check_depth), root first; NULL when the boxes
 * do not nest or memory runs out (the binary walk is then used).  *count: its nodes.  A binary tree that is one
 * leaf becomes one wide node with that leaf as its only child. */
static WideNode *wide_build(const BvhNode *nodes, int64_t n, int64_t *count)
{
    *count = 0;
    if (n < 1 || !wide_boxes_nest(nodes, n))
        return NULL;
    int64_t capacity = n / 2 + 1;  /* each wide node but the root's own collapses at least one inner node */
    WideNode *wide = (WideNode *)malloc((size_t)capacity * sizeof(WideNode));
    int64_t *queue = (int64_t *)malloc((size_t)capacity * sizeof(int64_t));  /* binary node of each wide node */
    if (!wide || !queue) {
        free(wide);
        free(queue);
        return NULL;
    }
    if (nodes[0].count) {  /* a single leaf: its box is tested as the binary walk tests it */
        WideNode *w = &wide[0];
        for (int j = 0; j < WIDE_CHILDREN; j++)
            for (int i = 0; i < 3; i++) {
                w->box[0][i][j] = j ? INFINITY : nodes[0].lo[i];
                w->box[1][i][j] = j ? -INFINITY : nodes[0].hi[i];
            }
        for (int j = 0; j < WIDE_CHILDREN; j++) {
            w->child[j] = j ? -1 : nodes[0].offset;
            w->count[j] = j ? 0 : nodes[0].count;
        }
        memset(w->order, 0 | 1 << 2 | 2 << 4 | 3 << 6, sizeof(w->order));
        free(queue);
        *count = 1;
        return wide;
    }
    int64_t made = 1;
    queue[0] = 0;
    for (int64_t k = 0; k < made; k++) {
        WideGroup g;
        wide_fill(nodes, queue[k], &wide[k], &g);
        for (int j = 0; j < WIDE_CHILDREN; j++)
            if (wide[k].child[j] >= 0 && wide[k].count[j] == 0) {
                queue[made] = wide[k].child[j];
                wide[k].child[j] = (int32_t)made++;
            }
    }
    free(queue);
    WideNode *fitted = (WideNode *)realloc(wide, (size_t)made * sizeof(WideNode));
    *count = made;
    return fitted ? fitted : wide;
}

/* ------------------------------------------------------------------------------------------------------
 * Walking it */

/* A ray as the wide walk's box test sees it. */
typedef struct {
    double o[3], inv[3];
    int near_side[3];  /* 1 where 1 / d < 0: the slab's near plane is hi */
    int octant;        /* bit k: d[k] < 0 */
} WideRay;

/* Whether the wide walk may take this ray (see the top of this file); fills *w when it may. */
static inline int wide_ray(const double *o, const double *inv, const double *d, double lower, double upper,
                           WideRay *w)
{
    if (lower != lower || upper != upper)
        return 0;
    w->octant = 0;
    for (int i = 0; i < 3; i++) {
        if (!isfinite(o[i]) || !isfinite(inv[i]) || inv[i] == 0.0)
            return 0;
        w->o[i] = o[i];
        w->inv[i] = inv[i];
        w->near_side[i] = inv[i] < 0.0;
        w->octant |= (d[i] < 0.0) << i;
    }
    return 1;
}

/* Which children of node the ray meets for some t in [lower, upper] (bit j: child j) and where it enters
 * their boxes (near[j]; only meaningful for those it meets). */
static inline int wide_hit_scalar(const WideNode *node, const WideRay *r, double lower, double upper, double *near)
{
    int mask = 0;
    for (int j = 0; j < WIDE_CHILDREN; j++) {
        double n = lower, f = upper;
        for (int i = 0; i < 3; i++) {
            const float *near_plane = node->box[r->near_side[i]][i], *far_plane = node->box[1 - r->near_side[i]][i];
            double enter = ((double)near_plane[j] - r->o[i]) * r->inv[i];
            double leave = ((double)far_plane[j] - r->o[i]) * r->inv[i];
            n = enter > n ? enter : n;
            f = leave < f ? leave : f;
        }
        near[j] = n;
        mask |= (n <= f) << j;
    }
    return mask;
}

#if RT_WIDE_SSE2
static inline int wide_hit_sse2(const WideNode *node, const WideRay *r, double lower, double upper, double *near)
{
    __m128d n01 = _mm_set1_pd(lower), n23 = n01, f01 = _mm_set1_pd(upper), f23 = f01;
    for (int i = 0; i < 3; i++) {
        __m128d o = _mm_set1_pd(r->o[i]), inv = _mm_set1_pd(r->inv[i]);
        __m128 np = _mm_loadu_ps(node->box[r->near_side[i]][i]), fp = _mm_loadu_ps(node->box[1 - r->near_side[i]][i]);
        /* (cvtps2pd widens exactly; max(a, b) = a > b ? a : b and min likewise, as the scalar test) */
        n01 = _mm_max_pd(_mm_mul_pd(_mm_sub_pd(_mm_cvtps_pd(np), o), inv), n01);
        n23 = _mm_max_pd(_mm_mul_pd(_mm_sub_pd(_mm_cvtps_pd(_mm_movehl_ps(np, np)), o), inv), n23);
        f01 = _mm_min_pd(_mm_mul_pd(_mm_sub_pd(_mm_cvtps_pd(fp), o), inv), f01);
        f23 = _mm_min_pd(_mm_mul_pd(_mm_sub_pd(_mm_cvtps_pd(_mm_movehl_ps(fp, fp)), o), inv), f23);
    }
    _mm_storeu_pd(near, n01);
    _mm_storeu_pd(near + 2, n23);
    return _mm_movemask_pd(_mm_cmple_pd(n01, f01)) | _mm_movemask_pd(_mm_cmple_pd(n23, f23)) << 2;
}
#endif

#if RT_WIDE_AVX2
/* wide_hit_sse2 four lanes at a time (the same operations, lane by lane: cvtps2pd, sub, mul, max / min, and
 * a <= compare, which is false for NaN as cmple_pd is). */
RT_TARGET_AVX2 static inline int wide_hit_avx2(const WideNode *node, const WideRay *r, double lower, double upper,
                                               double *near)
{
    __m256d n = _mm256_set1_pd(lower), f = _mm256_set1_pd(upper);
    for (int i = 0; i < 3; i++) {
        __m256d o = _mm256_set1_pd(r->o[i]), inv = _mm256_set1_pd(r->inv[i]);
        __m256d np = _mm256_cvtps_pd(_mm_loadu_ps(node->box[r->near_side[i]][i]));
        __m256d fp = _mm256_cvtps_pd(_mm_loadu_ps(node->box[1 - r->near_side[i]][i]));
        n = _mm256_max_pd(_mm256_mul_pd(_mm256_sub_pd(np, o), inv), n);
        f = _mm256_min_pd(_mm256_mul_pd(_mm256_sub_pd(fp, o), inv), f);
    }
    _mm256_storeu_pd(near, n);
    return _mm256_movemask_pd(_mm256_cmp_pd(n, f, _CMP_LE_OQ));
}
#endif

/* The box test of `mode`.  Called with the constant WIDE_AVX2 only from walks compiled for AVX2 (mesh.h), where
 * it is inlined; elsewhere mode is the scene's scalar or SSE2 choice. */
static inline int wide_hit(int mode, const WideNode *node, const WideRay *r, double lower, double upper, double *near)
{
#if RT_WIDE_AVX2
    if (mode == WIDE_AVX2)
        return wide_hit_avx2(node, r, lower, upper, near);
#endif
#if RT_WIDE_SSE2
    if (mode == WIDE_SSE2)
        return wide_hit_sse2(node, r, lower, upper, near);
#endif
    (void)mode;
    return wide_hit_scalar(node, r, lower, upper, near);
}

/* Pushes the children of `node` in `mask` so that they come off the stack in the order order[octant]. */
static inline void wide_push(const WideNode *node, int mask, const double *near, int octant, WideEntry *stack,
                             int64_t *top)
{
    unsigned order = node->order[octant];
    for (int k = WIDE_CHILDREN - 1; k >= 0; k--) {
        int j = (int)(order >> (2 * k) & 3);
        if (mask >> j & 1) {
            WideEntry *e = &stack[(*top)++];
            e->child = node->child[j];
            e->count = node->count[j];
            e->near = near[j];
        }
    }
}

#endif
