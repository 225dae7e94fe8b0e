/* The C core of the SDL ray tracer (one translation unit: the .h files beside it hold its parts).
 *
 * rt_create() takes a SceneDesc (flat arrays owned by Python, see flatten.py), checks it, and builds a
 * bounding volume hierarchy over the top-level objects; rt_trace() shades a batch of camera rays on all
 * the threads asked for.  The semantics are those of the NumPy reference, tracer/trace.py and the modules
 * it uses; see core.h for the conventions.
 */
#define _POSIX_C_SOURCE 200809L

#include <pthread.h>
#include <stddef.h>
#include <stdio.h>
#include <stdatomic.h>
#include <stdlib.h>
#include <string.h>

#if defined(__SSE2__)
#include <emmintrin.h>
#endif

#include "core.h"
#include "interrupt.h"
#include "numeric.h"
#include "prims.h"
#include "shapes.h"
#include "mesh.h"
#include "csg.h"
#include "scan.h"
#include "bvh_build.h"
#include "sdl_read.h"

#ifndef RT_SOURCE_HASH
#define RT_SOURCE_HASH "unknown"
#endif
/* build.py finds this marker in the library file to tell whether it was built from the current sources. */
const char rt_build_marker[] = "RT_SOURCE_HASH=" RT_SOURCE_HASH ";";

const char *rt_build_id(void) { return rt_build_marker; }

int64_t rt_struct_size(int64_t which)
{
    switch (which) {
#define RT_STRUCT_SIZE(code, type, fields) case code: return (int64_t)sizeof(type);
    RT_STRUCTS(RT_STRUCT_SIZE)
#undef RT_STRUCT_SIZE
    }
    return -1;
}

/* Offset and size of every field of struct `which` (contract.py's STRUCTS) in its table's order, for the
 * loader to compare with ctypes'; returns the number of fields (nothing is written when capacity is smaller),
 * -1 for no such struct. */
int64_t rt_struct_layout(int64_t which, int64_t *offsets, int64_t *sizes, int64_t capacity)
{
    int64_t k = 0;
#define RT_FIELD_LAYOUT(type, name)                             \
    if (k < capacity) {                                         \
        offsets[k] = (int64_t)offsetof(type, name);             \
        sizes[k] = (int64_t)sizeof(((const type *)0)->name);    \
    }                                                           \
    k++;
#define RT_STRUCT_LAYOUT(code, type, fields) case code: fields(RT_FIELD_LAYOUT) return k;
    switch (which) {
    RT_STRUCTS(RT_STRUCT_LAYOUT)
    }
#undef RT_STRUCT_LAYOUT
#undef RT_FIELD_LAYOUT
    return -1;
}

const char *rt_contract_digest(void) { return RT_CONTRACT_DIGEST; }

/* ------------------------------------------------------------------------------------------------------
 * The scene at run time */

/* ...and as it is traversed: one record per inner node holding both children's boxes, side by side so
 * that one pass of two-lane arithmetic tests both.  A child is a leaf (items[first : first + count]) when
 * its count is > 0, else the index of its own pair record.  The boxes are the built tree's own single
 * precision ones (BvhNode: rounded outward), and a refit's rounded outward the same way: 64 bytes a
 * record, one for each bounded object but one (a scene of 10^5 instances holds 10^5 of them). */
typedef struct {
    float b[3][2][2];     /* [axis][0: lo, 1: hi][child] */
    int32_t child[2];     /* inner: pair index; leaf: first item */
    int32_t count[2];     /* leaf: items (> 0; -1: none left after removals); inner: 0 */
} PairNode;

typedef struct {
    int32_t child, count; /* as in PairNode */
    double near;          /* where the ray enters the child's box */
} TreeEntry;

typedef struct {
    SceneDesc d;
    MeshView *meshes;
    BvhNode *nodes;       /* only while building */
    int64_t n_nodes, tree_depth;
    PairNode *pairs;      /* none when the whole hierarchy is one leaf */
    int64_t n_pairs;
    int32_t root_first, root_count;  /* the root when it is a leaf */
    int64_t *items;       /* bounded objects in leaf order (after removals, a leaf may list one twice) */
    int64_t n_items;
    int64_t *unbounded;   /* the objects outside the hierarchy, each tried by every ray: the unbounded ones, */
    int64_t n_unbounded;  /* and those added since it was built (n_loose of them) */
    int64_t n_loose;
    int64_t csg_depth;    /* most CSG nodes on one root-to-leaf path */
    int64_t mesh_depth;   /* deepest mesh BVH, in nodes */
    int wide_mode;        /* how the mesh walks test boxes (mesh_wide.h), from the environment and the CPU */
    int64_t n_mesh_views;
    /* tracer.savings: objects x lights, a feeler from inside the object to the light is blocked (rt_set_sealed;
     * NULL: none known).  Which savings a trace uses is the trace's own (rt_trace's cutoff and flags). */
    uint8_t *sealed;
    /* for refitting the hierarchy (made when first needed, dropped when it is built again): per object, its
     * leaf as 2 * pair + child (< 0: outside the hierarchy, or in a root leaf), and per pair its parent as
     * 2 * pair + child */
    int64_t *leaf_of, *parent_of;
} Scene;

#define SHADOW_CACHE 16

typedef struct {
    int64_t obj[MEDIA_DEPTH];
    double speed[MEDIA_DEPTH];
    int depth;
} Media;

typedef struct {
    HitList *lists;       /* 2 per CSG level, and one more for a top-level object */
    int64_t n_lists;
    RawBuffer raw;
    int64_t *mesh_stack;
    WideEntry *wide_stack;  /* the wide mesh walk's (mesh_wide.h) */
    TreeEntry *tree_stack;
    int64_t counts[N_COUNTS];
    int64_t last_blocker[SHADOW_CACHE];  /* per light: the object that last blocked a feeler, or -1 */
    double cutoff;        /* tracer.savings: a secondary ray of smaller cumulative weight is not traced */
    int64_t savings;      /* SAVE_* bits: the other savings this trace makes */
    int64_t ray_budget;   /* most reflected and transmitted rays one camera ray's tree may trace (see shade.h) */
    int64_t rays_used;    /* reflected and transmitted rays traced for the current camera ray */
    int64_t ray_limit;    /* ...which the current ray's descendants may bring up to this (shade.h) */
    const volatile int32_t *cancel;  /* non-zero: stop tracing (rt_trace's flag); may be NULL */
    int oom;
    int stopped;          /* stop_requested() was seen: the colours are not to be used */
    int refracted;        /* the ray about to be shaded is a transmitted one (shade.h's secondary sets it) */
} Work;

/* Whether tracing should stop now: a signal was heard (interrupt.h) or the caller asked to cancel. */
static inline int stop_requested(const Work *w)
{
    return rt_interrupt_heard() != 0 || (w->cancel != NULL && *w->cancel != 0);
}

static int work_init(Work *w, const Scene *S)
{
    memset(w, 0, sizeof(*w));
    for (int i = 0; i < SHADOW_CACHE; i++)
        w->last_blocker[i] = -1;
    w->n_lists = 2 * S->csg_depth + 1;
    w->lists = (HitList *)calloc((size_t)w->n_lists, sizeof(HitList));
    w->mesh_stack = (int64_t *)malloc((size_t)(S->mesh_depth + 2) * sizeof(int64_t));
    /* (a wide node is no deeper than its binary node; each leaves at most three children on the stack) */
    w->wide_stack = (WideEntry *)malloc((size_t)(3 * S->mesh_depth + 4) * sizeof(WideEntry));
    w->tree_stack = (TreeEntry *)malloc((size_t)(S->tree_depth + 2) * sizeof(TreeEntry));
    if (!w->lists || !w->mesh_stack || !w->wide_stack || !w->tree_stack) {
        free(w->lists);
        free(w->mesh_stack);
        free(w->wide_stack);
        free(w->tree_stack);
        return 0;
    }
    return 1;
}

static void work_free(Work *w)
{
    for (int64_t i = 0; i < w->n_lists; i++)
        free(w->lists[i].h);
    free(w->lists);
    free(w->raw.h);
    free(w->mesh_stack);
    free(w->wide_stack);
    free(w->tree_stack);
}

static int list_reserve(Work *w, HitList *l, int64_t need)
{
    if (need <= l->cap)
        return 1;
    int64_t cap = l->cap ? l->cap : 16;
    while (cap < need)
        cap *= 2;
    Hit *p = (Hit *)realloc(l->h, (size_t)cap * sizeof(Hit));
    if (!p) {
        w->oom = 1;
        return 0;
    }
    l->h = p;
    l->cap = cap;
    return 1;
}

static inline double media_speed(const Media *m) { return m->depth > 0 ? m->speed[m->depth - 1] : 1.0; }

static inline void media_enter(Media *m, int64_t obj, double speed)
{
    if (m->depth < MEDIA_DEPTH) {
        m->obj[m->depth] = obj;
        m->speed[m->depth] = speed;
        m->depth++;
    }
}

/* Without the innermost entry for obj (unchanged where the ray was not known to be inside it). */
static inline void media_leave(Media *m, int64_t obj)
{
    int last = -1;
    for (int j = 0; j < m->depth; j++)
        if (m->obj[j] == obj)
            last = j;
    if (last < 0)
        return;
    for (int j = last; j < MEDIA_DEPTH - 1; j++) {
        m->obj[j] = m->obj[j + 1];
        m->speed[j] = m->speed[j + 1];
    }
    m->obj[MEDIA_DEPTH - 1] = -1;
    m->depth--;
}

/* ------------------------------------------------------------------------------------------------------
 * Primitives (tracer.compile.Primitive) */

/* The line passes within the bounding sphere (always, for unbounded shapes). */
static inline int prim_may_hit(const double *sphere, const double *o, const double *d)
{
    if (!isfinite(sphere[3]))
        return 1;
    double to_center[3] = {sphere[0] - o[0], sphere[1] - o[1], sphere[2] - o[2]};
    double dd = dot3(d, d);
    double along = dot3(to_center, d) / dd;
    double perp[3] = {to_center[0] - along * d[0], to_center[1] - along * d[1], to_center[2] - along * d[2]};
    return dot3(perp, perp) <= sphere[3] * sphere[3];
}

/* Whole-line hits of a closed-form shape or polyhedron in generic coordinates (room for 8 in out): each kind's
 * registered C function, called as contract.h's RT_SHAPE_HITS spells it in these names. */
static int analytic_hits(const Scene *S, int64_t p, const double *o, const double *d, Hit *out, int *inside)
{
    const SceneDesc *D = &S->d;
    const double *param = D->prim_param + PRIM_PARAMS * p;
    const int32_t *aux = D->prim_aux + 2 * p;
    (void)param;
    (void)aux;
    *inside = 0;
    switch (D->prim_kind[p]) {
#define REGISTERED_HITS(kind, call) case kind: return call;
    RT_SHAPE_HITS(REGISTERED_HITS)
#undef REGISTERED_HITS
    }
    return 0;
}

/* Closed analytic shapes: their normals must agree with their entering flags (ShapeKind.normals_agree). */
static inline int solid_analytic(int32_t kind)
{
    return RT_NORMALS_AGREE(kind);
}

/* World ray -> generic origin moved to the line's point nearest the generic centre (returns the shift). */
static inline double prim_generic_ray(const double *inv, const double *o, const double *d, double *og, double *dg)
{
    double raw[3];
    affine_point(inv, o, raw);
    affine_vector(inv, d, dg);
    double shift = -dot3(raw, dg) / dot3(dg, dg);
    if (!isfinite(shift))
        shift = 0.0;
    for (int i = 0; i < 3; i++)
        og[i] = raw[i] + shift * dg[i];
    return shift;
}

/* A hit's bounds (Primitive.bound_hits): its t's error (plus the shape's own root error, where it has one)
 * and how far its generic point may be from the surface: the shape's residual over |n| (its first-order
 * distance) plus the line's error; the shading turns it into a world distance (world_unit_normal).  A
 * `mesh` triangle is flat: the line's error moves its crossing by that error over the rate the line crosses
 * the triangle's own plane, its winding normal E1 x E2 (with the interpolated normal and a unit-curvature
 * floor the bound was up to 5e8 times short at grazing incidence); its offset keeps the floor's bound times
 * |d|, which is at least the line's error. */
static inline void hit_bounds(const ErrorFrame *frame, const double *dg, const MeshView *mesh, Hit *h)
{
    double error = point_error(frame, h->t);
    double nn = dot3(h->n, h->n), length = sqrt(nn);
    if (mesh)
        h->bend = 2.0 * length * frame->dd / frame->size;
    double bound = time_error_of(frame, error, dg, h, nn, length);
    if (mesh) {
        h->offset = (h->err + bound) * sqrt(frame->dd);
        double e1[3], e2[3], w[3];
        mesh_edges(mesh, h->part, e1, e2);
        cross3(e1, e2, w);
        bound = crossing_shift(sqrt(dot3(w, w)) * (frame->size * error), fabs(dot3(w, dg)), 0.0);
    } else {
        double gap = nn > 0.0 ? h->offset / length : h->offset;
        h->offset = gap + frame->size * error;
    }
    h->err += bound;
}

/* All hits of primitive p along the whole world line (Primitive.intersect), into out. */
static int prim_hits(const Scene *S, Work *w, int64_t p, const double *o, const double *d, HitList *out)
{
    const SceneDesc *D = &S->d;
    out->n = 0;
    out->inside = 0;
    double own_sphere[4], own_inverse[16], own_rounding[4];
    if (!prim_may_hit(prim_sphere_of(D, p, own_sphere), o, d))
        return 1;
    const double *inv = prim_inverse_of(D, p, own_inverse);
    double og[3], dg[3];
    double shift = prim_generic_ray(inv, o, d, og, dg);
    int64_t n;
    if (RT_IS_MESH(D->prim_kind[p])) {
        const MeshView *m = &S->meshes[D->prim_aux[2 * p]];
        n = mesh_all(m, og, dg, w->mesh_stack, w->wide_stack, &w->raw, &out->h, &out->cap);
        if (n < 0) {
            w->oom = 1;
            return 0;
        }
    } else {
        if (!list_reserve(w, out, 8))
            return 0;
        n = analytic_hits(S, p, og, dg, out->h, &out->inside);
        if (solid_analytic(D->prim_kind[p]))
            for (int64_t i = 0; i < n; i++)
                agree_with_crossing(&out->h[i], dg);
    }
    ErrorFrame frame;
    error_frame(o, og, dg, prim_rounding_of(D, p, inv, own_rounding), D->hit_gamma, &frame);
    const MeshView *mesh = D->prim_kind[p] == K_MESH ? &S->meshes[D->prim_aux[2 * p]] : NULL;
    for (int64_t i = 0; i < n; i++) {
        Hit *h = &out->h[i];
        h->t += shift;
        h->shape = (int32_t)p;
        hit_bounds(&frame, dg, mesh, h);
    }
    out->n = n;
    return 1;
}

/* The first hit of primitive p with t_min < t < t_max (Primitive.first_hit) and its bound on t's rounding;
 * for a `feeler` (Primitive.occludes) only whether there is one whose whole error interval lies between
 * t_min and t_max (compile.blocks_between: the feeler's end is protected as its start is). */
static int prim_first(const Scene *S, Work *w, int64_t p, const double *o, const double *d, double t_min,
                      double t_max, Hit *out, int feeler)
{
    const SceneDesc *D = &S->d;
    double own_sphere[4], own_inverse[16], own_rounding[4];
    if (!prim_may_hit(prim_sphere_of(D, p, own_sphere), o, d))
        return 0;
    const double *inv = prim_inverse_of(D, p, own_inverse);
    if (RT_IS_MESH(D->prim_kind[p])) {
        double og[3], dg[3];
        affine_point(inv, o, og);
        affine_vector(inv, d, dg);
        if (!mesh_closest(&S->meshes[D->prim_aux[2 * p]], og, dg, t_min, t_max, w->mesh_stack, w->wide_stack, out))
            return 0;
        out->shape = (int32_t)p;
        if (!feeler) {  /* (meshes are traced from the transformed origin itself, not a centred one) */
            ErrorFrame frame;
            error_frame(o, og, dg, prim_rounding_of(D, p, inv, own_rounding), D->hit_gamma, &frame);
            hit_bounds(&frame, dg, &S->meshes[D->prim_aux[2 * p]], out);
        }
        return 1;
    }
    double og[3], dg[3];
    double shift = prim_generic_ray(inv, o, d, og, dg);
    Hit buf[8];
    int inside;
    /* (spheres, the common case, without the call) */
    int n = D->prim_kind[p] == K_SPHERE ? hits_sphere(og, dg, buf) : analytic_hits(S, p, og, dg, buf, &inside);
    ErrorFrame frame;
    if (n)
        error_frame(o, og, dg, prim_rounding_of(D, p, inv, own_rounding), D->hit_gamma, &frame);
    for (int i = 0; i < n; i++) {
        double t = buf[i].t + shift;
        if (!(t > t_min && t < t_max))
            continue;
        /* after t_min with its whole error interval (compiled.first_after), compared without square roots */
        double along = solid_analytic(D->prim_kind[p]) ? agree_with_crossing(&buf[i], dg) : dot3(buf[i].n, dg);
        double error = point_error(&frame, t);
        if (exceeds_time_error(&frame, t - t_min - buf[i].err, error, dg, &buf[i], along) &&
            (!feeler || exceeds_time_error(&frame, t_max - t - buf[i].err, error, dg, &buf[i], along))) {
            *out = buf[i];
            out->t = t;
            out->shape = (int32_t)p;
            if (!feeler)
                hit_bounds(&frame, dg, NULL, out);
            return 1;
        }
    }
    return 0;
}

/* Does the feeler o + t d end, at t_max, within the bounding sphere (Primitive.ends_within)? */
static inline int feeler_ends_within(const double *sphere, const double *o, const double *d, double t_max)
{
    double apart[3];
    for (int i = 0; i < 3; i++)
        apart[i] = (o[i] + t_max * d[i]) - sphere[i];
    return dot3(apart, apart) <= sphere[3] * sphere[3];
}

/* Has mesh primitive p a hit whose whole error interval lies between t_min and t_max (compile.blocks_between;
 * Primitive.mesh_blocks_between)?  Its hits are taken first to last: one whose interval reaches t_max ends
 * the search (a light on the mesh's surface is not shadowed by it), one that reaches t_min is passed. */
static int mesh_blocks_between(const Scene *S, Work *w, int64_t p, const double *inv, const double *o,
                               const double *og, const double *dg, double t_min, double t_max)
{
    const MeshView *m = &S->meshes[S->d.prim_aux[2 * p]];
    double own_rounding[4];
    ErrorFrame frame;
    error_frame(o, og, dg, prim_rounding_of(&S->d, p, inv, own_rounding), S->d.hit_gamma, &frame);
    double lower = t_min;
    Hit h;
    while (mesh_closest(m, og, dg, lower, t_max, w->mesh_stack, w->wide_stack, &h)) {
        hit_bounds(&frame, dg, m, &h);
        if (!(h.t + h.err < t_max))
            return 0;
        if (h.t - h.err > t_min)
            return 1;
        lower = h.t;
    }
    return 0;
}

/* Is anything of mesh primitive p on the ray with t_min < t < t_max, with its whole error interval?  It is
 * asked for any hit first, and for the intervals of its hits only where the feeler ends within its bounding
 * sphere (where a light may sit on its surface).  (Not inlined into prim_occludes: inlined, it made every
 * feeler's walk 1.4 % longer, meshes or not.) */
static __attribute__((noinline)) int mesh_occludes(const Scene *S, Work *w, int64_t p, const double *o,
                                                   const double *d, double t_min, double t_max)
{
    const SceneDesc *D = &S->d;
    double own_sphere[4], own_inverse[16];
    const double *sphere = prim_sphere_of(D, p, own_sphere);
    if (!prim_may_hit(sphere, o, d))
        return 0;
    const double *inv = prim_inverse_of(D, p, own_inverse);
    double og[3], dg[3];
    affine_point(inv, o, og);
    affine_vector(inv, d, dg);
    if (!mesh_any(&S->meshes[D->prim_aux[2 * p]], og, dg, t_min, t_max, w->mesh_stack, w->wide_stack))
        return 0;
    if (!feeler_ends_within(sphere, o, d, t_max))
        return 1;
    return mesh_blocks_between(S, w, p, inv, o, og, dg, t_min, t_max);
}

/* Is anything of primitive p on the ray with t_min < t < t_max, with its whole error interval? */
static int prim_occludes(const Scene *S, Work *w, int64_t p, const double *o, const double *d, double t_min,
                         double t_max)
{
    if (RT_IS_MESH(S->d.prim_kind[p]))
        return mesh_occludes(S, w, p, o, d, t_min, t_max);
    Hit h;
    return prim_first(S, w, p, o, d, t_min, t_max, &h, 1);
}

/* ------------------------------------------------------------------------------------------------------
 * Objects: a primitive or a CSG tree (ref < 0) */

static int object_hits(const Scene *S, Work *w, int64_t ref, const double *o, const double *d, int64_t level,
                       HitList *out)
{
    if (ref >= 0)
        return prim_hits(S, w, ref, o, d, out);
    int64_t node = -ref - 1;
    HitList *left = &w->lists[2 * level], *right = &w->lists[2 * level + 1];
    if (!object_hits(S, w, S->d.csg_left[node], o, d, level + 1, left))
        return 0;
    if (!object_hits(S, w, S->d.csg_right[node], o, d, level + 1, right))
        return 0;
    if (!list_reserve(w, out, 2 * (left->n + right->n) + 1))
        return 0;
    out->n = csg_combine(S->d.csg_op[node], left, right, out->h, &out->inside);
    return 1;
}

static int object_first(const Scene *S, Work *w, int64_t ref, const double *o, const double *d, double t_min,
                        double t_max, Hit *out)
{
    if (ref >= 0)
        return prim_first(S, w, ref, o, d, t_min, t_max, out, 0);
    HitList *top = &w->lists[w->n_lists - 1];
    if (!object_hits(S, w, ref, o, d, 0, top))
        return 0;
    for (int64_t i = 0; i < top->n; i++) {
        if (top->h[i].t - top->h[i].err > t_min && top->h[i].t < t_max) {
            *out = top->h[i];
            return 1;
        }
    }
    return 0;
}

static int object_occludes(const Scene *S, Work *w, int64_t ref, const double *o, const double *d, double t_min,
                           double t_max)
{
    if (ref >= 0)
        return prim_occludes(S, w, ref, o, d, t_min, t_max);
    HitList *top = &w->lists[w->n_lists - 1];
    if (!object_hits(S, w, ref, o, d, 0, top))
        return 0;
    for (int64_t i = 0; i < top->n; i++)  /* compile.blocks_between */
        if (top->h[i].t - top->h[i].err > t_min && top->h[i].t + top->h[i].err < t_max)
            return 1;
    return 0;
}

/* ------------------------------------------------------------------------------------------------------
 * The scene: the first hit over all objects (trace.first_hits: where hits tie, the object that comes first in
 * the scene) and shadow feelers. */

/* nextafter(x, INFINITY) for x > 0 finite (a hit's t), without the call. */
static inline double next_up_positive(double x)
{
    uint64_t bits;
    memcpy(&bits, &x, sizeof(bits));
    bits++;
    memcpy(&x, &bits, sizeof(bits));
    return x;
}

/* The first hits of the objects seen so far (trace.first_hits): the nearest (`best`, ties of t to the lower
 * index), the second nearest time, and `reach`, the least t + error: every hit up to it lies within the
 * error interval of every hit found, so none of them is certainly nearer than another. */
typedef struct {
    Hit *best;
    int64_t obj;
    double second, reach;
} Nearest;

static inline void consider_object(const Scene *S, Work *w, int64_t obj, const double *o, const double *d, Nearest *n)
{
    Hit h;
    double limit = isfinite(n->reach) ? next_up_positive(n->reach) : INFINITY;  /* hits up to the reach */
    if (!object_first(S, w, S->d.object_ref[obj], o, d, 0.0, limit, &h))
        return;
    if (h.t < n->best->t || (h.t == n->best->t && obj < n->obj)) {
        n->second = n->best->t;
        *n->best = h;
        n->obj = obj;
    } else if (h.t < n->second) {
        n->second = h.t;
    }
    if (h.t + h.err < n->reach)
        n->reach = h.t + h.err;
}

/* The ray against the boxes of the object hierarchy (whose boxes are padded, so the test is conservative).
 *
 * The reference test is the slab test of box_hit below, in which an axis whose slab gives NaN (origin on a
 * face plane of a parallel ray) constrains nothing.  NaN cannot arise when the origin is finite and every
 * 1 / d is finite and non-zero (the boxes hold no NaN, see build_tree, and have lo <= hi), and then the
 * near plane of every slab is known from the sign of 1 / d: the "fast" test below computes exactly the
 * slab test's numbers for two boxes at once.  Other rays take box_hit, one box at a time. */
typedef struct {
    double o[3], inv[3];
    int near_side[3];     /* 1 where the ray runs toward -axis (hi is the near plane) */
    int fast;
} RayBoxes;

static inline void ray_boxes(const double *o, const double *d, RayBoxes *r)
{
    r->fast = 1;
    for (int i = 0; i < 3; i++) {
        r->o[i] = o[i];
        r->inv[i] = 1.0 / d[i];
        r->near_side[i] = r->inv[i] < 0.0;
        if (!isfinite(o[i]) || !isfinite(r->inv[i]) || r->inv[i] == 0.0)
            r->fast = 0;
    }
}

static inline int box_hit(const double *lo, const double *hi, const double *o, const double *inv, double near,
                          double far)
{
    for (int i = 0; i < 3; i++) {
        double a = (lo[i] - o[i]) * inv[i], b = (hi[i] - o[i]) * inv[i];
        if (a != a || b != b)
            continue;
        double mn = a < b ? a : b, mx = a < b ? b : a;
        if (mn > near) near = mn;
        if (mx < far) far = mx;
    }
    return near <= far;
}

#if defined(__SSE2__)
/* Both children's planes of one side and axis, as two doubles (exact). */
static inline __m128d pair_planes(const float *two)
{
    return _mm_cvtps_pd(_mm_castsi128_ps(_mm_loadl_epi64((const __m128i *)two)));
}
#endif

/* Which children of p the ray meets with lo <= t <= far (bit 0: child 0, bit 1: child 1), and where it
 * enters their boxes. */
static inline int pair_hit(const PairNode *p, const RayBoxes *r, double lo, double far, double *near_out)
{
    if (r->fast) {
#if defined(__SSE2__)
        __m128d near = _mm_set1_pd(lo), fr = _mm_set1_pd(far);
        for (int i = 0; i < 3; i++) {
            __m128d o = _mm_set1_pd(r->o[i]), inv = _mm_set1_pd(r->inv[i]);
            int s = r->near_side[i];
            __m128d tn = _mm_mul_pd(_mm_sub_pd(pair_planes(p->b[i][s]), o), inv);
            __m128d tf = _mm_mul_pd(_mm_sub_pd(pair_planes(p->b[i][1 - s]), o), inv);
            near = _mm_max_pd(tn, near);
            fr = _mm_min_pd(tf, fr);
        }
        _mm_storeu_pd(near_out, near);
        return _mm_movemask_pd(_mm_cmple_pd(near, fr));
#else
        int mask = 0;
        for (int c = 0; c < 2; c++) {
            double near = lo, fr = far;
            for (int i = 0; i < 3; i++) {
                int s = r->near_side[i];
                double tn = (p->b[i][s][c] - r->o[i]) * r->inv[i], tf = (p->b[i][1 - s][c] - r->o[i]) * r->inv[i];
                if (tn > near) near = tn;
                if (tf < fr) fr = tf;
            }
            near_out[c] = near;
            mask |= (near <= fr) << c;
        }
        return mask;
#endif
    }
    int mask = 0;
    for (int c = 0; c < 2; c++) {
        double box_lo[3] = {p->b[0][0][c], p->b[1][0][c], p->b[2][0][c]};
        double box_hi[3] = {p->b[0][1][c], p->b[1][1][c], p->b[2][1][c]};
        near_out[c] = lo;  /* (only orders the visit) */
        mask |= box_hit(box_lo, box_hi, r->o, r->inv, lo, far) << c;
    }
    return mask;
}

/* The children of p that the ray meets, nearer first: the first into *next, the other onto the stack. */
static inline int pair_children(const PairNode *p, const RayBoxes *r, double lo, double far, TreeEntry *next,
                                TreeEntry *stack, int64_t *top)
{
    double near[2];
    int mask = pair_hit(p, r, lo, far, near);
    if (!mask)
        return 0;
    int first = mask == 2 || (mask == 3 && near[1] < near[0]);
    next->child = p->child[first];
    next->count = p->count[first];
    next->near = near[first];
    if (mask == 3) {
        TreeEntry *e = &stack[(*top)++];
        e->child = p->child[1 - first];
        e->count = p->count[1 - first];
        e->near = near[1 - first];
    }
    return 1;
}

/* Every object whose box the ray meets for some t in [lo, reach] (the unbounded objects, then the hierarchy's
 * boxes), each offered to `visit` with the Nearest so far (whose reach may shrink as it goes).  Inlined
 * where it is called, with `visit` a constant. */
typedef void (*ObjectVisit)(const Scene *, Work *, int64_t, const double *, const double *, Nearest *);

static inline __attribute__((always_inline)) void
scene_objects(const Scene *S, Work *w, const double *o, const double *d, double lo, Nearest *n, ObjectVisit visit)
{
    for (int64_t i = 0; i < S->n_unbounded; i++)
        visit(S, w, S->unbounded[i], o, d, n);
    if (S->n_pairs) {
        RayBoxes r;
        ray_boxes(o, d, &r);
        TreeEntry *stack = w->tree_stack, e = {0, 0, 0.0};
        int64_t top = 0;
        for (;;) {
            if (e.count) {
                for (int64_t i = e.child; i < (int64_t)e.child + e.count; i++)
                    visit(S, w, S->items[i], o, d, n);
            } else if (pair_children(&S->pairs[e.child], &r, lo, n->reach, &e, stack, &top)) {
                continue;
            }
            /* the next child still in reach (entered no later than the reach: ties count) */
            do {
                if (!top)
                    return;
                e = stack[--top];
            } while (e.near > n->reach);
        }
    }
    for (int64_t i = S->root_first; i < (int64_t)S->root_first + S->root_count; i++)
        visit(S, w, S->items[i], o, d, n);
}

/* An object that comes before the tie's winner so far and has a hit within the reach wins it. */
static void earlier_in_reach(const Scene *S, Work *w, int64_t obj, const double *o, const double *d, Nearest *n)
{
    Hit h;
    if (obj < n->obj && object_first(S, w, S->d.object_ref[obj], o, d, 0.0, next_up_positive(n->reach), &h)) {
        *n->best = h;
        n->obj = obj;
    }
}

/* The first hit: the nearest, unless another hit lies within the error interval of every hit found (t at most
 * the least t + error, the reach); then, of those, the hit of the object that comes first in the scene
 * (trace.first_hits), however the two round.  Coplanar faces look the same from any position, on both
 * backends.  The second pass, over the boxes that hold [nearest t, reach], is taken only on such a tie. */
static int scene_first(const Scene *S, Work *w, const double *o, const double *d, Hit *best, int64_t *best_obj)
{
    Nearest n;
    n.best = best;
    best->t = INFINITY;
    n.obj = -1;
    n.second = n.reach = INFINITY;
    scene_objects(S, w, o, d, 0.0, &n, consider_object);
    if (n.obj >= 0 && n.second <= n.reach)
        scene_objects(S, w, o, d, best->t, &n, earlier_in_reach);
    *best_obj = n.obj;
    return n.obj >= 0;
}

/* Is any object on o + t d, 0 < t < t_max?  `cache` (may be NULL) remembers the last object that blocked a
 * feeler toward the same light and is tried first: neighbouring feelers are usually blocked by it, and
 * which object blocks does not change the answer. */
static int scene_occluded(const Scene *S, Work *w, const double *o, const double *d, double t_max, int64_t *cache)
{
    if (cache && *cache >= 0 && object_occludes(S, w, S->d.object_ref[*cache], o, d, 0.0, t_max))
        return 1;
    /* (the cached object, tried already, is skipped below) */
    int64_t tried = cache ? *cache : -1;
    for (int64_t i = 0; i < S->n_unbounded; i++)
        if (S->unbounded[i] != tried && object_occludes(S, w, S->d.object_ref[S->unbounded[i]], o, d, 0.0, t_max)) {
            if (cache) *cache = S->unbounded[i];
            return 1;
        }
    int64_t first = S->root_first, count = S->root_count;
    if (S->n_pairs) {
        RayBoxes r;
        ray_boxes(o, d, &r);
        TreeEntry *stack = w->tree_stack, e = {0, 0, 0.0};
        int64_t top = 0;
        for (;;) {
            if (e.count) {
                for (int64_t i = e.child; i < (int64_t)e.child + e.count; i++)
                    if (S->items[i] != tried && object_occludes(S, w, S->d.object_ref[S->items[i]], o, d, 0.0, t_max)) {
                        if (cache) *cache = S->items[i];
                        return 1;
                    }
            } else if (pair_children(&S->pairs[e.child], &r, 0.0, t_max, &e, stack, &top)) {
                continue;
            }
            if (!top)
                return 0;
            e = stack[--top];
        }
    }
    for (int64_t i = first; i < first + count; i++)
        if (S->items[i] != tried && object_occludes(S, w, S->d.object_ref[S->items[i]], o, d, 0.0, t_max)) {
            if (cache) *cache = S->items[i];
            return 1;
        }
    return 0;
}

/* The hit's unit world normal (zero if degenerate), as first_hits normalises it; returns how far along it
 * the world hit point may be from the surface (SurfaceHits.offset): the hit's generic distance maps to the
 * world along the gradient n by |n| / |n M^-1|, exactly for a plane (tracer.numerics.world_offsets). */
static inline double world_unit_normal(const Scene *S, const Hit *h, double *n)
{
    double own[16];
    normal_to_world(prim_inverse_of(&S->d, h->shape, own), h->n, n);
    double length = norm3(n);  /* (a shape scaled by 1e-200: |n M^-1|^2 overflows) */
    if (length > 0.0) {
        n[0] /= length;
        n[1] /= length;
        n[2] /= length;
    } else {
        n[0] = n[1] = n[2] = 0.0;
    }
    return h->offset * (norm3(h->n) / length);
}

/* ------------------------------------------------------------------------------------------------------
 * Shading: one function per combination of live effects (see shade.h). */

#define M_PI_VALUE 3.141592653589793 /* np.pi */
#define fmin_np nan_min                /* np.minimum: NaN wins */
#include "texture.h"
#include "shade.h"

/* One function per combination of live effects: lighting, shadows, Cook-Torrance, reflection, refraction,
 * textures (shadows and Cook-Torrance only ever come with lighting, see tracer.compile.live_effects). */
#define SHADE_VARIANT(NAME, L, SH, CT, RL, RR, TX)                                                          \
    static void NAME(const Scene *S, Work *w, const double *o, const double *d, int64_t level,             \
                     const Media *media, double weight, double *out)                                       \
    {                                                                                                      \
        shade_body(S, w, o, d, level, media, weight, out, L, SH, CT, RL, RR, TX, 0, 0, 0, 0, 0, NAME);     \
    }
/* Each combination without textures (suffix 0) and with them (suffix 1). */
#define SHADE_PAIR(BITS, L, SH, CT, RL, RR)                                                                 \
    SHADE_VARIANT(shade_##BITS##0, L, SH, CT, RL, RR, 0)                                                    \
    SHADE_VARIANT(shade_##BITS##1, L, SH, CT, RL, RR, 1)
SHADE_PAIR(00000, 0, 0, 0, 0, 0)
SHADE_PAIR(00001, 0, 0, 0, 0, 1)
SHADE_PAIR(00010, 0, 0, 0, 1, 0)
SHADE_PAIR(00011, 0, 0, 0, 1, 1)
SHADE_PAIR(10000, 1, 0, 0, 0, 0)
SHADE_PAIR(10001, 1, 0, 0, 0, 1)
SHADE_PAIR(10010, 1, 0, 0, 1, 0)
SHADE_PAIR(10011, 1, 0, 0, 1, 1)
SHADE_PAIR(10100, 1, 0, 1, 0, 0)
SHADE_PAIR(10101, 1, 0, 1, 0, 1)
SHADE_PAIR(10110, 1, 0, 1, 1, 0)
SHADE_PAIR(10111, 1, 0, 1, 1, 1)
SHADE_PAIR(11000, 1, 1, 0, 0, 0)
SHADE_PAIR(11001, 1, 1, 0, 0, 1)
SHADE_PAIR(11010, 1, 1, 0, 1, 0)
SHADE_PAIR(11011, 1, 1, 0, 1, 1)
SHADE_PAIR(11100, 1, 1, 1, 0, 0)
SHADE_PAIR(11101, 1, 1, 1, 0, 1)
SHADE_PAIR(11110, 1, 1, 1, 1, 0)
SHADE_PAIR(11111, 1, 1, 1, 1, 1)

/* The effects of Blender scenes, traced by shade_general alone. */
#define FX_GENERAL                                                                                          \
    (FX_PHYSICAL_LIGHTS | FX_SOFT_SHADOWS | FX_FRESNEL | FX_SMOOTH_TERMINATOR | FX_SEEN_LIGHTS | FX_LIGHT_SWITCHES)

/* Any combination of effects, its flags read from the scene at run time: the scenes that use an effect of
 * FX_GENERAL pay for that choice per ray, the others never come here. */
static void shade_general(const Scene *S, Work *w, const double *o, const double *d, int64_t level,
                          const Media *media, double weight, double *out)
{
    int64_t fx = S->d.effects;
    int l = (fx & FX_LIGHTING) != 0;
    shade_body(S, w, o, d, level, media, weight, out, l, l && (fx & FX_SHADOWS) != 0,
               l && (fx & FX_COOK_TORRANCE) != 0, (fx & FX_REFLECTION) != 0, (fx & FX_REFRACTION) != 0,
               (fx & FX_TEXTURES) != 0, (fx & FX_PHYSICAL_LIGHTS) != 0, (fx & FX_FRESNEL) != 0,
               (fx & FX_SMOOTH_TERMINATOR) != 0, (fx & FX_SEEN_LIGHTS) != 0, (fx & FX_LIGHT_SWITCHES) != 0,
               shade_general);
}

static ShadeFn pick_shade(int64_t effects)
{
    if (effects & FX_GENERAL)
        return shade_general;
    int l = (effects & FX_LIGHTING) != 0;
    int s = l && (effects & FX_SHADOWS) != 0, ct = l && (effects & FX_COOK_TORRANCE) != 0;
    int rl = (effects & FX_REFLECTION) != 0, rr = (effects & FX_REFRACTION) != 0;
    int tx = (effects & FX_TEXTURES) != 0;
    static const ShadeFn unlit[2][2][2] = {{{shade_000000, shade_000001}, {shade_000010, shade_000011}},
                                           {{shade_000100, shade_000101}, {shade_000110, shade_000111}}};
    static const ShadeFn lit[2][2][2][2][2] = {
        {{{{shade_100000, shade_100001}, {shade_100010, shade_100011}},
          {{shade_100100, shade_100101}, {shade_100110, shade_100111}}},
         {{{shade_101000, shade_101001}, {shade_101010, shade_101011}},
          {{shade_101100, shade_101101}, {shade_101110, shade_101111}}}},
        {{{{shade_110000, shade_110001}, {shade_110010, shade_110011}},
          {{shade_110100, shade_110101}, {shade_110110, shade_110111}}},
         {{{shade_111000, shade_111001}, {shade_111010, shade_111011}},
          {{shade_111100, shade_111101}, {shade_111110, shade_111111}}}},
    };
    return l ? lit[s][ct][rl][rr][tx] : unlit[rl][rr][tx];
}

/* ------------------------------------------------------------------------------------------------------
 * Building the scene: checks, mesh views, the top-level BVH */

/* The built tree as PairNodes (see scene_first); frees the BvhNodes. */
static int pair_tree(Scene *S)
{
    const BvhNode *nodes = S->nodes;
    S->n_pairs = 0;
    S->root_first = S->root_count = 0;
    if (S->n_nodes == 0)
        return 1;
    if (nodes[0].count) {
        S->root_first = nodes[0].offset;
        S->root_count = nodes[0].count;
        return 1;
    }
    int64_t *pair_of = (int64_t *)malloc((size_t)S->n_nodes * sizeof(int64_t));
    int64_t n_inner = 0;
    if (!pair_of)
        return 0;
    for (int64_t k = 0; k < S->n_nodes; k++)
        pair_of[k] = nodes[k].count ? -1 : n_inner++;
    S->pairs = (PairNode *)malloc((size_t)n_inner * sizeof(PairNode));
    if (!S->pairs) {
        free(pair_of);
        return 0;
    }
    for (int64_t k = 0; k < S->n_nodes; k++) {
        if (nodes[k].count)
            continue;
        PairNode *p = &S->pairs[pair_of[k]];
        for (int c = 0; c < 2; c++) {
            const BvhNode *child = &nodes[nodes[k].offset + c];
            for (int i = 0; i < 3; i++) {
                p->b[i][0][c] = child->lo[i];
                p->b[i][1][c] = child->hi[i];
            }
            p->child[c] = (int32_t)(child->count ? child->offset : pair_of[nodes[k].offset + c]);
            p->count[c] = (int32_t)child->count;
        }
    }
    S->n_pairs = n_inner;
    free(pair_of);
    free(S->nodes);
    S->nodes = NULL;
    return 1;
}

/* An object's box as the slab test sees it: an axis whose bounds are in the wrong order is the slab between
 * them, one with a NaN bound is no constraint at all; and its centre (0 where not finite). */
static void clean_box(const float *box, float *clean, double *centre)
{
    for (int k = 0; k < 3; k++) {
        double lo = box[k], hi = box[3 + k];
        if (lo != lo || hi != hi) {
            lo = -INFINITY;
            hi = INFINITY;
        } else if (lo > hi) {
            double x = lo; lo = hi; hi = x;
        }
        clean[k] = (float)lo;  /* (exact: a float, or an infinity) */
        clean[3 + k] = (float)hi;
        double c = 0.5 * (lo + hi);
        centre[k] = isfinite(c) ? c : 0.0;
    }
}

/* Drops the hierarchy (and what refits keep about it). */
static void drop_tree(Scene *S)
{
    free(S->nodes);
    free(S->pairs);
    free(S->items);
    free(S->unbounded);
    free(S->leaf_of);
    free(S->parent_of);
    S->nodes = NULL;
    S->pairs = NULL;
    S->items = S->unbounded = S->leaf_of = S->parent_of = NULL;
    S->n_nodes = S->n_pairs = S->n_unbounded = S->n_items = S->n_loose = 0;
    S->root_first = S->root_count = 0;
}

/* The object hierarchy over the bounded objects (bvh_build.h) on up to `threads` threads, as PairNodes;
 * the unbounded objects listed apart.  0 when memory runs out. */
static int build_tree(Scene *S, int64_t threads)
{
    const SceneDesc *D = &S->d;
    drop_tree(S);
    int64_t nb = 0;
    for (int64_t i = 0; i < D->n_objects; i++)
        nb += D->object_bounded[i] != 0;
    if (nb >= INT32_MAX)
        return 0;
    S->n_unbounded = D->n_objects - nb;
    S->n_items = nb;
    S->unbounded = (int64_t *)malloc((size_t)(S->n_unbounded + 1) * sizeof(int64_t));
    S->items = (int64_t *)malloc((size_t)(nb + 1) * sizeof(int64_t));
    double *centre = (double *)malloc((size_t)(3 * nb + 1) * sizeof(double));
    /* The boxes as the slab test sees them (clean_box), like centre[] by position in items[] (the partition
     * moves them with their items): the passes over a node then read memory in order. */
    float *boxes = (float *)malloc((size_t)(6 * nb + 1) * sizeof(float));
    if (!S->unbounded || !S->items || !centre || !boxes) {
        free(centre);
        free(boxes);
        return 0;
    }
    int64_t u = 0, b = 0;
    for (int64_t i = 0; i < D->n_objects; i++) {
        if (D->object_bounded[i]) {
            clean_box(D->object_box + 6 * i, boxes + 6 * b, centre + 3 * b);
            S->items[b++] = i;
        } else {
            S->unbounded[u++] = i;
        }
    }
    S->n_nodes = 0;
    S->tree_depth = 0;
    if (nb > 0) {
        ObjectInput in = {S->items, centre, boxes};
        S->nodes = object_bvh_build(&in, nb, threads, &S->n_nodes, &S->tree_depth);
    }
    free(centre);
    free(boxes);
    if (nb > 0 && !S->nodes)
        return 0;
    return pair_tree(S);
}

/* Where each bounded object's leaf is and each pair's parent (Scene.leaf_of, parent_of), for refits.
 * 0 when memory runs out. */
static int tree_links(Scene *S)
{
    if (S->leaf_of)
        return 1;
    int64_t n = S->d.n_objects;
    S->leaf_of = (int64_t *)malloc((size_t)(n + 1) * sizeof(int64_t));
    S->parent_of = (int64_t *)malloc((size_t)(S->n_pairs + 1) * sizeof(int64_t));
    if (!S->leaf_of || !S->parent_of) {
        free(S->leaf_of);
        free(S->parent_of);
        S->leaf_of = S->parent_of = NULL;
        return 0;
    }
    for (int64_t i = 0; i < n; i++)
        S->leaf_of[i] = -1;
    if (S->n_pairs)
        S->parent_of[0] = -1;
    for (int64_t p = 0; p < S->n_pairs; p++)
        for (int c = 0; c < 2; c++) {
            const PairNode *pair = &S->pairs[p];
            if (pair->count[c] == 0) {
                S->parent_of[pair->child[c]] = 2 * p + c;
                continue;
            }
            for (int64_t k = pair->child[c]; k < (int64_t)pair->child[c] + pair->count[c]; k++)
                S->leaf_of[S->items[k]] = 2 * p + c;
        }
    return 1;
}

/* The box of child c of pair p, from its objects (a leaf) or its own pair's two children. */
static void child_box(const Scene *S, int64_t p, int c, double *lo, double *hi)
{
    const PairNode *pair = &S->pairs[p];
    box_empty(lo, hi);
    if (pair->count[c] == 0) {
        const PairNode *below = &S->pairs[pair->child[c]];
        for (int k = 0; k < 2; k++) {
            double blo[3] = {below->b[0][0][k], below->b[1][0][k], below->b[2][0][k]};
            double bhi[3] = {below->b[0][1][k], below->b[1][1][k], below->b[2][1][k]};
            box_grow(lo, hi, blo, bhi);
        }
        return;
    }
    for (int64_t k = pair->child[c]; k < (int64_t)pair->child[c] + pair->count[c]; k++) {
        float box[6];
        double centre[3];
        clean_box(S->d.object_box + 6 * S->items[k], box, centre);
        box_grow_single(lo, hi, box, box + 3);
    }
}

static void set_child_box(Scene *S, int64_t p, int c)
{
    double lo[3], hi[3];
    child_box(S, p, c, lo, hi);
    for (int i = 0; i < 3; i++) {
        S->pairs[p].b[i][0][c] = bvh_single_below(lo[i]);
        S->pairs[p].b[i][1][c] = bvh_single_above(hi[i]);
    }
}

/* Refit: the hierarchy keeps its shape and takes the objects' boxes as they are now (D->object_box), so
 * that every box still holds its objects.  `objects` (n of them) are the objects whose boxes changed: each
 * leaf holding one, and the pairs above it up to the root, are fitted again; with n < 0 (or many objects)
 * every pair is, bottom up.  Which objects are bounded must not have changed (rt_edit rebuilds then).
 * 0 when memory runs out.  (Kept apart from the build so that either can be reimplemented alone.) */
static int refit_tree(Scene *S, const int64_t *objects, int64_t n)
{
    if (S->n_pairs == 0)  /* no boxes: the root leaf's objects are all tested */
        return 1;
    if (n < 0 || n > S->n_pairs / 8) {
        /* children are numbered after their parents: the pairs in reverse order go bottom up */
        for (int64_t p = S->n_pairs - 1; p >= 0; p--)
            for (int c = 0; c < 2; c++)
                set_child_box(S, p, c);
        return 1;
    }
    if (!tree_links(S))
        return 0;
    for (int64_t k = 0; k < n; k++) {
        int64_t link = S->leaf_of[objects[k]];
        while (link >= 0) {
            set_child_box(S, link / 2, (int)(link % 2));
            link = S->parent_of[link / 2];
        }
    }
    return 1;
}

static int64_t csg_depth_of(const SceneDesc *D, int64_t ref, int64_t guard)
{
    if (ref >= 0 || guard > D->n_csg)
        return 0;
    int64_t node = -ref - 1;
    int64_t a = csg_depth_of(D, D->csg_left[node], guard + 1), b = csg_depth_of(D, D->csg_right[node], guard + 1);
    return 1 + (a > b ? a : b);
}

static int ref_ok(const SceneDesc *D, int64_t ref)
{
    return ref >= 0 ? ref < D->n_prims : (-ref - 1) < D->n_csg;
}

/* Longest root-to-leaf path of a mesh BVH, checking its indices; -1 if they are inconsistent. */
static int64_t mesh_check_depth(const MeshView *m)
{
    if (m->n_nodes == 0)
        return 0;
    int64_t *stack = (int64_t *)malloc((size_t)(4 * m->n_nodes + 4) * sizeof(int64_t));
    if (!stack)
        return -1;
    int64_t top = 0, deepest = 0, visited = 0;
    stack[top++] = 0;
    stack[top++] = 1;
    while (top) {
        int64_t depth = stack[--top], node = stack[--top];
        const BvhNode *nd = &m->nodes[node];
        if (++visited > m->n_nodes) { free(stack); return -1; }
        if (depth > deepest) deepest = depth;
        if (nd->count) {
            if (nd->offset < 0 || (int64_t)nd->offset + nd->count > m->n_tris) { free(stack); return -1; }
            continue;
        }
        int64_t l = nd->offset, r = l + 1;
        if (l <= node || r >= m->n_nodes || nd->axis < 0 || nd->axis > 2) {
            free(stack);
            return -1;
        }
        stack[top++] = r; stack[top++] = depth + 1;
        stack[top++] = l; stack[top++] = depth + 1;
    }
    free(stack);
    return deepest;
}

/* Every index of a mesh in range: the leaf order, the vertex indices, the normal indices (below 0: none). */
static int mesh_check_indices(const MeshView *m)
{
    for (int64_t i = 0; i < m->n_tris; i++)
        if (m->order[i] < 0 || m->order[i] >= m->n_tris)
            return 0;
    for (int64_t i = 0; i < 3 * m->n_tris; i++)
        if (m->tri_vertex[i] < 0 || m->tri_vertex[i] >= m->n_vertices ||
            (m->tri_normal && m->tri_normal[i] >= m->n_normals))
            return 0;
    return 1;
}

/* Most objects added since the hierarchy was built that are kept outside it (each is tried by every ray)
 * before it is built again. */
#define LOOSE_MAX 64

/* After objects were removed (`removed`: their indices before, ascending, n of them) and added (the objects
 * after the old_n - n survivors): the hierarchy keeps its shape, its objects renumbered; a leaf's slots of a
 * removed object take a surviving object of the same leaf (tried twice, found once), or the leaf lists none
 * (count -1: an empty box, never entered by a ray the fast box test sees, and nothing in it if entered); the
 * added objects go outside the hierarchy; the leaves that lost objects are refitted.  S->d is the new description; leaf_of and parent_of are those of the old numbering
 * (tree_links).  1 when done; 0 when the hierarchy must be built again instead (or memory ran out). */
static int restructure_tree(Scene *S, int64_t old_n, const int64_t *removed, int64_t n)
{
    int64_t new_n = S->d.n_objects, added = new_n - (old_n - n);
    if (S->n_pairs == 0 || added < 0 || S->n_loose + added > LOOSE_MAX)
        return 0;
    int64_t *renumber = (int64_t *)malloc((size_t)(old_n + 1) * sizeof(int64_t));
    int64_t *touched = (int64_t *)malloc((size_t)(n + 1) * sizeof(int64_t));
    int64_t *leaf_of = (int64_t *)malloc((size_t)(new_n + 1) * sizeof(int64_t));
    int64_t *outside = (int64_t *)malloc((size_t)(S->n_unbounded + added + 1) * sizeof(int64_t));
    int ok = renumber && touched && leaf_of && outside;
    for (int64_t o = 0, r = 0; ok && o < old_n; o++) {
        if (r < n && removed[r] == o) {
            renumber[o] = -1;
            r++;
            ok = r == n || removed[r] > o;  /* (ascending, in range) */
        } else {
            renumber[o] = o - r;
        }
    }
    ok = ok && (n == 0 || removed[n - 1] < old_n);
    int64_t n_touched = 0;
    for (int64_t r = 0; ok && r < n; r++) {
        int64_t link = S->leaf_of[removed[r]];
        if (link < 0)
            continue;
        PairNode *pair = &S->pairs[link / 2];
        int64_t first = pair->child[link % 2], end = first + pair->count[link % 2], survivor = -1;
        for (int64_t k = first; k < end && survivor < 0; k++)
            if (renumber[S->items[k]] >= 0)
                survivor = S->items[k];
        if (survivor < 0)  /* no object left in the leaf: a count of -1 lists none (and its box is empty) */
            pair->count[link % 2] = -1;
        for (int64_t k = first; k < end; k++)
            if (renumber[S->items[k]] < 0)
                S->items[k] = survivor;
        touched[n_touched++] = link;
    }
    if (!ok) {
        free(renumber);
        free(touched);
        free(leaf_of);
        free(outside);
        return 0;
    }
    for (int64_t k = 0; k < S->n_items; k++)  /* (slots of emptied leaves hold -1, and are never read) */
        S->items[k] = S->items[k] < 0 ? -1 : renumber[S->items[k]];
    int64_t u = 0;
    for (int64_t k = 0; k < S->n_unbounded; k++)
        if (renumber[S->unbounded[k]] >= 0)
            outside[u++] = renumber[S->unbounded[k]];
    for (int64_t o = new_n - added; o < new_n; o++)
        outside[u++] = o;
    for (int64_t o = 0; o < old_n; o++)
        if (renumber[o] >= 0)
            leaf_of[renumber[o]] = S->leaf_of[o];
    for (int64_t o = new_n - added; o < new_n; o++)
        leaf_of[o] = -2;  /* (outside, though maybe bounded) */
    free(S->unbounded);
    free(S->leaf_of);
    S->unbounded = outside;
    S->n_unbounded = u;
    S->n_loose += added;
    S->leaf_of = leaf_of;
    for (int64_t t = 0; t < n_touched; t++)
        for (int64_t link = touched[t]; link >= 0; link = S->parent_of[link / 2])
            set_child_box(S, link / 2, (int)(link % 2));
    free(renumber);
    free(touched);
    return 1;
}

/* How many nodes the four-wide tree of mesh `mesh` has (0: it is walked as a binary tree); -1 for no such mesh. */
int64_t rt_mesh_wide_nodes(const void *scene, int64_t mesh)
{
    const Scene *S = (const Scene *)scene;
    if (!S || mesh < 0 || mesh >= S->n_mesh_views)
        return -1;
    return S->meshes[mesh].wide ? S->meshes[mesh].n_wide : 0;
}

/* How the scene's mesh walks test boxes: its wide mode (mesh_wide.h: WIDE_OFF, _SCALAR, _SSE2 or _AVX2), read
 * from the environment and the CPU when the scene was made; -1 for no scene. */
int rt_mesh_box_test(const void *scene)
{
    const Scene *S = (const Scene *)scene;
    return S ? S->wide_mode : -1;
}

/* Releases a buffer the library allocated for the caller (rt_build_mesh_bvh's nodes). */
void rt_free(void *buffer) { free(buffer); }

void rt_destroy(void *handle)
{
    Scene *S = (Scene *)handle;
    if (!S)
        return;
    drop_tree(S);
    for (int64_t k = 0; S->meshes && k < S->n_mesh_views; k++)
        free(S->meshes[k].wide);
    free(S->meshes);
    free(S->sealed);
    free(S);
}

/* Writes what was refused into the caller's buffer (when it gave one) and fails. */
#define REFUSE(...)                                              \
    do {                                                         \
        if (error && capacity > 0)                               \
            snprintf(error, (size_t)capacity, __VA_ARGS__);      \
        return 0;                                                \
    } while (0)

/* How deep object_ok follows booleans (MAX_CSG_DEPTH of tracer.backend, and some). */
#define MAX_CSG_CHECK 4096

/* Primitive p's kind, material and mesh in range; 0 (and the reason in `error`) if not. */
static int prim_ok(const SceneDesc *D, int64_t p, char *error, int64_t capacity)
{
    int kind = D->prim_kind[p];
    if (kind < 0 || kind >= K_COUNT)
        REFUSE("primitive %lld has unknown shape kind %d", (long long)p, kind);
    if (D->prim_material[p] < 0 || D->prim_material[p] >= D->n_materials)
        REFUSE("primitive %lld has material %d of %lld", (long long)p, (int)D->prim_material[p],
               (long long)D->n_materials);
    if (RT_IS_MESH(kind) && (D->prim_aux[2 * p] < 0 || D->prim_aux[2 * p] >= D->n_meshes))
        REFUSE("primitive %lld refers to mesh %lld of %lld", (long long)p, (long long)D->prim_aux[2 * p],
               (long long)D->n_meshes);
    if (D->instance_rows && (D->prim_slot[p] < -1 || D->prim_slot[p] >= D->n_prims - D->instance_rows ||
                             (D->prim_slot[p] < 0 && !RT_IS_MESH(kind))))
        REFUSE("primitive %lld has row %d of %lld (an instance row must be a mesh)", (long long)p,
               (int)D->prim_slot[p], (long long)(D->n_prims - D->instance_rows));
    return 1;
}

/* CSG node c's operation and children in range; 0 (and the reason in `error`) if not. */
static int csg_ok(const SceneDesc *D, int64_t c, char *error, int64_t capacity)
{
    if (D->csg_op[c] < OP_UNION || D->csg_op[c] > OP_DIFFERENCE || !ref_ok(D, D->csg_left[c]) ||
        !ref_ok(D, D->csg_right[c]) || D->csg_left[c] == -c - 1 || D->csg_right[c] == -c - 1)
        REFUSE("CSG node %lld is inconsistent (operation %d, children %lld and %lld)", (long long)c,
               (int)D->csg_op[c], (long long)D->csg_left[c], (long long)D->csg_right[c]);
    return 1;
}

/* Object i's reference, and every primitive and CSG node under it, in range (an edit's objects). */
static int object_ok(const SceneDesc *D, int64_t i, char *error, int64_t capacity)
{
    if (!ref_ok(D, D->object_ref[i]))
        REFUSE("object %lld refers to nothing (%lld)", (long long)i, (long long)D->object_ref[i]);
    int64_t ref = D->object_ref[i], visited = 0;
    int64_t stack[2 * MAX_CSG_CHECK + 2], top = 0;
    stack[top++] = ref;
    while (top) {
        ref = stack[--top];
        if (ref >= 0) {
            if (!prim_ok(D, ref, error, capacity))
                return 0;
            continue;
        }
        if (++visited > D->n_csg || top + 2 > 2 * MAX_CSG_CHECK + 2)
            REFUSE("object %lld: its booleans are not a tree of at most %d levels", (long long)i, MAX_CSG_CHECK);
        if (!csg_ok(D, -ref - 1, error, capacity))
            return 0;
        stack[top++] = D->csg_right[-ref - 1];
        stack[top++] = D->csg_left[-ref - 1];
    }
    return 1;
}

/* Takes the description and checks every index the tracer will follow, so that a bad description fails here,
 * not in a worker; the CSG depth.  With `objects` (n >= 0 of them: an edit that changed only those objects'
 * rows), only what they refer to is checked again, and the CSG depth is kept.  0 (and the reason in `error`)
 * when refused. */
static int take_desc(Scene *S, const SceneDesc *desc, const int64_t *objects, int64_t n, char *error,
                     int64_t capacity)
{
    S->d = *desc;
    /* The shading recursion uses about 1 KB of stack per level (gcc -fstack-usage: at most 976 bytes per
     * shade_* variant), so bounding the depth bounds the stack a worker thread needs, whatever the scene
     * says; tracer.model.traced_depth applies the same bound to the NumPy path. */
    if (S->d.max_depth > MAX_RECURSION_DEPTH)
        S->d.max_depth = MAX_RECURSION_DEPTH;
    if (S->d.max_depth < 0)
        S->d.max_depth = 0;
    const SceneDesc *D = &S->d;
    if (D->effects & FX_TEXTURES) {
        for (int64_t m = 0; m < D->n_materials; m++) {
            int32_t texture = D->mat_texture[m];
            int64_t image = D->mat_tex_image[m];
            if (texture < -3 || (texture > 0 && (image < 0 || image >= D->n_images)))
                REFUSE("material %lld has texture %d (image %lld of %lld)", (long long)m, (int)texture,
                       (long long)image, (long long)D->n_images);
        }
        for (int64_t i = 0; i < D->n_images; i++)
            if (D->image_info[2 * i] < 1 || D->image_info[2 * i + 1] < 1 || !D->image_data[i])
                REFUSE("image %lld is empty (%lld x %lld)", (long long)i, (long long)D->image_info[2 * i],
                       (long long)D->image_info[2 * i + 1]);
    }
    for (int64_t m = 0; m < D->n_materials; m++)
        if (D->mat_fresnel[m] < FRESNEL_CONSTANT || D->mat_fresnel[m] > FRESNEL_DIELECTRIC)
            REFUSE("material %lld has fresnel mode %d", (long long)m, (int)D->mat_fresnel[m]);
    /* (lights are read only where something is lit: then a physical one needs its shading variant) */
    for (int64_t l = 0; l < D->n_lights; l++)
        if (D->light_kind[l] < 0 || D->light_kind[l] > LIGHT_AREA || D->light_samples[l] < 1 ||
            (D->light_kind[l] != LIGHT_POINT && (D->effects & FX_LIGHTING) && !(D->effects & FX_PHYSICAL_LIGHTS)))
            REFUSE("light %lld has kind %d and %d samples", (long long)l, (int)D->light_kind[l],
                   (int)D->light_samples[l]);
    if (objects && n >= 0) {
        for (int64_t k = 0; k < n; k++) {
            if (objects[k] < 0 || objects[k] >= D->n_objects)
                REFUSE("edited object %lld of %lld", (long long)objects[k], (long long)D->n_objects);
            if (!object_ok(D, objects[k], error, capacity))
                return 0;
        }
        return 1;
    }
    if (D->instance_rows < 0 || D->instance_rows > D->n_prims)
        REFUSE("%lld instance rows of %lld primitives", (long long)D->instance_rows, (long long)D->n_prims);
    for (int64_t p = 0; p < D->n_prims; p++)
        if (!prim_ok(D, p, error, capacity))
            return 0;
    for (int64_t c = 0; c < D->n_csg; c++)
        if (!csg_ok(D, c, error, capacity))
            return 0;
    for (int64_t i = 0; i < D->n_objects; i++)
        if (!ref_ok(D, D->object_ref[i]))
            REFUSE("object %lld refers to nothing (%lld)", (long long)i, (long long)D->object_ref[i]);
    S->csg_depth = 0;
    for (int64_t i = 0; i < D->n_objects; i++) {
        int64_t depth = csg_depth_of(D, D->object_ref[i], 0);
        if (depth > S->csg_depth)
            S->csg_depth = depth;
    }
    return 1;
}

/* Whether the view's binary tree (whose arrays are at the addresses of `nodes`) still has the first and last
 * node it had when its wide tree was made: a mesh whose arrays were freed and others allocated at the same
 * addresses is then not taken for the old one. */
static int mesh_fingerprint_matches(const MeshView *old, const BvhNode *nodes, int64_t n)
{
    return memcmp(&old->fingerprint[0], &nodes[0], sizeof(BvhNode)) == 0 &&
           memcmp(&old->fingerprint[1], &nodes[n - 1], sizeof(BvhNode)) == 0;
}

/* The view's wide tree (mesh_wide.h) in `mode`: kept when taken over from the old view, made when missing,
 * dropped for the binary walk.  Without memory for it the binary walk is used. */
static void mesh_take_wide(MeshView *m, int mode)
{
    m->wide_mode = mode;
    if (mode == WIDE_OFF || m->n_nodes == 0) {
        free(m->wide);
        m->wide = NULL;
        m->n_wide = 0;
        return;
    }
    if (!m->wide)
        m->wide = wide_build(m->nodes, m->n_nodes, &m->n_wide);
    m->fingerprint[0] = m->nodes[0];
    m->fingerprint[1] = m->nodes[m->n_nodes - 1];
}

/* The meshes' views of the description's arrays, each checked (a mesh whose arrays and counts are those of
 * the view it had before keeps that view's check).  0 (and the reason in `error`) when refused. */
static int take_meshes(Scene *S, char *error, int64_t capacity)
{
    const SceneDesc *D = &S->d;
    MeshView *old = S->meshes;
    int64_t n_old = S->n_mesh_views;
    int wide_mode = wide_mode_from_environment();
    S->wide_mode = wide_mode;
    S->meshes = (MeshView *)calloc((size_t)(D->n_meshes + 1), sizeof(MeshView));
    S->n_mesh_views = D->n_meshes;
    S->mesh_depth = 0;
    if (!S->meshes) {
        free(old);
        REFUSE("out of memory");
    }
    int ok = 1;
    for (int64_t k = 0; k < D->n_meshes && ok; k++) {
        const int64_t *info = D->mesh_info + 4 * k;
        MeshView *m = &S->meshes[k];
        m->nodes = (const BvhNode *)D->mesh_nodes[k];
        m->n_nodes = info[0];
        m->n_tris = info[1];
        m->n_vertices = info[2];
        m->n_normals = info[3];
        m->order = D->mesh_order[k];
        m->tri_vertex = D->mesh_tri_vertex[k];
        m->tri_normal = D->mesh_tri_normal[k];
        m->vertices = D->mesh_vertices[k];
        m->normals = D->mesh_normals[k];
        m->tri_uv = D->mesh_tri_uv[k];
        m->rounding_factor = D->mesh_constants[0];
        m->barycentric_max = D->mesh_constants[1];
        m->parallel_eps = D->mesh_constants[2];
        m->dedupe = D->mesh_constants[3];
        m->dedupe_adjacent = D->mesh_constants[4];
        m->extent = D->mesh_extent[k];
        MeshView *seen = NULL;
        for (int64_t j = 0; j < n_old && !seen; j++)
            if (old[j].nodes == m->nodes && old[j].n_nodes == m->n_nodes && old[j].n_tris == m->n_tris &&
                old[j].n_vertices == m->n_vertices && old[j].n_normals == m->n_normals && old[j].order == m->order &&
                old[j].tri_vertex == m->tri_vertex && old[j].tri_normal == m->tri_normal &&
                old[j].vertices == m->vertices && old[j].normals == m->normals &&
                (m->n_nodes == 0 || mesh_fingerprint_matches(&old[j], m->nodes, m->n_nodes)))
                seen = &old[j];
        if (seen) {
            m->depth = seen->depth;
            m->wide = seen->wide;  /* (taken over: the old view is dropped below) */
            m->n_wide = seen->n_wide;
            seen->wide = NULL;
        } else {
            if (m->n_nodes < 0 || m->n_tris < 0 || m->n_vertices < 0 || m->n_normals < 0 ||
                ((m->n_nodes || m->n_tris) && (!m->nodes || !m->order || !m->tri_vertex || !m->vertices)) ||
                (m->tri_normal && !m->normals)) {
                if (error && capacity > 0)
                    snprintf(error, (size_t)capacity, "mesh %lld: missing arrays or negative counts", (long long)k);
                ok = 0;
                break;
            }
            if (!mesh_check_indices(m)) {
                if (error && capacity > 0)
                    snprintf(error, (size_t)capacity, "mesh %lld: an index is out of range", (long long)k);
                ok = 0;
                break;
            }
            m->depth = mesh_check_depth(m);
            if (m->depth < 0) {
                if (error && capacity > 0)
                    snprintf(error, (size_t)capacity, "mesh %lld: inconsistent hierarchy (or out of memory)",
                             (long long)k);
                ok = 0;
                break;
            }
        }
        if (m->depth > S->mesh_depth)
            S->mesh_depth = m->depth;
        mesh_take_wide(m, wide_mode);
    }
    for (int64_t j = 0; j < n_old; j++)
        free(old[j].wide);
    free(old);
    return ok;
}

void *rt_create_threaded(const SceneDesc *desc, int64_t threads, char *error, int64_t capacity)
{
    if (error && capacity > 0)
        error[0] = '\0';
    Scene *S = (Scene *)calloc(1, sizeof(Scene));
    if (!S) {
        if (error && capacity > 0)
            snprintf(error, (size_t)capacity, "out of memory");
        return NULL;
    }
    if (!take_desc(S, desc, NULL, -1, error, capacity) || !take_meshes(S, error, capacity))
        goto fail;
    if (!build_tree(S, threads)) {
        if (error && capacity > 0)
            snprintf(error, (size_t)capacity,
                     "out of memory (or more than 2^31 bounded objects) building the object hierarchy");
        goto fail;
    }
    return S;
fail:
    rt_destroy(S);
    return NULL;
}

/* An edit of the scene in place (tracer.edit): `desc` describes the scene as it is now (its arrays edited,
 * or new ones), and is checked and taken as rt_create takes it.  flags: EDIT_MESHES when the meshes may have
 * changed (each mesh not seen before is checked); EDIT_REBUILD to build the object hierarchy anew (on
 * `threads` threads); EDIT_OBJECTS when the objects `objects` (n of them, their indices before, ascending)
 * were removed and the objects after the survivors added (restructure_tree: the hierarchy renumbered, the
 * added objects outside it, until LOOSE_MAX of them call for a build); else the hierarchy is refitted to the
 * boxes of `objects` (n of them; n < 0: every object's), or rebuilt where an object in it became unbounded.
 * Keeps the sealed table only while the numbers of objects and lights stay.  0 on success; -1 (with the reason
 * in `error`) when the description is refused or memory runs out: the scene must then be destroyed, not
 * traced. */
int rt_edit(void *scene, const SceneDesc *desc, const int64_t *objects, int64_t n, int64_t flags, int64_t threads,
            char *error, int64_t capacity)
{
    Scene *S = (Scene *)scene;
    if (error && capacity > 0)
        error[0] = '\0';
    int64_t n_objects = S->d.n_objects, n_lights = S->d.n_lights;
    int restructured = (flags & EDIT_OBJECTS) != 0;
    int rebuild = (flags & EDIT_REBUILD) || (desc->n_objects != n_objects && !restructured) || S->n_pairs == 0;
    if (!rebuild && (n != 0 || restructured) && !tree_links(S)) {
        if (error && capacity > 0)
            snprintf(error, (size_t)capacity, "out of memory");
        return -1;
    }
    /* an object in the hierarchy that became unbounded has no box to be found by: only a build puts it right
     * (one outside it may be bounded or not: every ray tries it) */
    for (int64_t k = 0; !rebuild && !restructured && k < (n < 0 ? n_objects : n); k++) {
        int64_t i = n < 0 ? k : objects[k];
        rebuild = i < 0 || i >= n_objects || (S->leaf_of[i] >= 0 && !desc->object_bounded[i]);
    }
    /* an edit in place (no object added or removed, the meshes as they were) checks its own objects again */
    int in_place = !(flags & (EDIT_MESHES | EDIT_REBUILD | EDIT_OBJECTS)) && desc->n_objects == n_objects &&
                   desc->n_csg == S->d.n_csg && desc->n_prims == S->d.n_prims && n >= 0;
    if (!take_desc(S, desc, in_place ? objects : NULL, in_place ? n : -1, error, capacity))
        return -1;
    if ((flags & EDIT_MESHES) && !take_meshes(S, error, capacity))
        return -1;
    if (S->d.n_objects != n_objects || S->d.n_lights != n_lights) {
        free(S->sealed);
        S->sealed = NULL;
    }
    if (restructured && !rebuild)
        rebuild = !restructure_tree(S, n_objects, objects, n);
    int fitted = rebuild ? build_tree(S, threads) : restructured ? 1 : refit_tree(S, objects, n);
    if (!fitted) {
        if (error && capacity > 0)
            snprintf(error, (size_t)capacity, "out of memory fitting the object hierarchy");
        return -1;
    }
    return 0;
}
#undef REFUSE

/* The object hierarchy as built (for tests): returns the number of PairNode records; with buffers, copies
 * them (pairs, n records of sizeof(PairNode) bytes), the bounded objects in leaf order (items) and root[5]:
 * the root's first item and count when the whole hierarchy is one leaf, its depth, the number of items,
 * sizeof(PairNode). */
int64_t rt_object_tree(const void *scene, void *pairs, int64_t *items, int64_t *root)
{
    const Scene *S = (const Scene *)scene;
    int64_t n_items = S->n_items;
    if (pairs && S->n_pairs)
        memcpy(pairs, S->pairs, (size_t)S->n_pairs * sizeof(PairNode));
    if (items && n_items)
        memcpy(items, S->items, (size_t)n_items * sizeof(int64_t));
    if (root) {
        root[0] = S->root_first;
        root[1] = S->root_count;
        root[2] = S->tree_depth;
        root[3] = n_items;
        root[4] = (int64_t)sizeof(PairNode);
    }
    return S->n_pairs;
}

/* rt_create_threaded on one thread. */
void *rt_create(const SceneDesc *desc, char *error, int64_t capacity)
{
    return rt_create_threaded(desc, 1, error, capacity);
}

/* tracer.savings.sealed_lights of the scene: `sealed` has `count` = n_objects x n_lights entries, copied
 * (NULL: none known, no feeler is skipped for being inside).  0 on success, -1 for a wrong count or out of
 * memory. */
int rt_set_sealed(void *scene, const uint8_t *sealed, int64_t count)
{
    Scene *S = (Scene *)scene;
    uint8_t *copy = NULL;
    if (sealed) {
        if (count != S->d.n_objects * S->d.n_lights)
            return -1;
        copy = (uint8_t *)malloc(count ? (size_t)count : 1);
        if (!copy)
            return -1;
        if (count)
            memcpy(copy, sealed, (size_t)count);
    }
    free(S->sealed);
    S->sealed = copy;
    return 0;
}

/* ------------------------------------------------------------------------------------------------------
 * Batches over threads */

enum { JOB_TRACE, JOB_FIRST, JOB_OCCLUDED };

typedef struct {
    const Scene *S;
    int mode;
    int64_t n;
    const double *o, *d;
    double *colors;
    double *t, *normal;
    int32_t *shape, *object;
    int8_t *flags;
    double t_max;
    ShadeFn shade;
    double cutoff;        /* JOB_TRACE: the savings it makes (Work.cutoff, Work.savings) */
    int64_t savings;
    int64_t ray_budget;   /* JOB_TRACE: Work.ray_budget */
    const volatile int32_t *cancel;  /* Work.cancel */
    _Atomic int64_t next;
} Job;

typedef struct {
    Job *job;
    int64_t counts[N_COUNTS];
    int failed;
    int stopped;
} Worker;

#define CHUNK 16

static void *run_worker(void *arg)
{
    Worker *wk = (Worker *)arg;
    Job *job = wk->job;
    const Scene *S = job->S;
    Work w;
    if (!work_init(&w, S)) {
        wk->failed = 1;
        return NULL;
    }
    w.cutoff = job->cutoff;
    w.savings = job->savings;
    w.ray_budget = job->ray_budget;
    w.cancel = job->cancel;
    Media air;
    memset(&air, 0, sizeof(air));
    for (;;) {
        int64_t start = atomic_fetch_add(&job->next, CHUNK);
        if (start >= job->n)
            break;
        int64_t end = start + CHUNK < job->n ? start + CHUNK : job->n;
        if (stop_requested(&w)) {
            w.stopped = 1;
            break;
        }
        for (int64_t i = start; i < end; i++) {
            const double *o = job->o + 3 * i, *d = job->d + 3 * i;
            if (job->mode == JOB_TRACE) {
                w.rays_used = 0;
                w.ray_limit = w.ray_budget;
                job->shade(S, &w, o, d, 0, &air, 1.0, job->colors + 3 * i);
            } else if (job->mode == JOB_FIRST) {
                Hit h;
                int64_t obj;
                if (scene_first(S, &w, o, d, &h, &obj)) {
                    job->t[i] = h.t;
                    world_unit_normal(S, &h, job->normal + 3 * i);
                    job->shape[i] = h.shape;
                    job->object[i] = (int32_t)obj;
                    job->flags[i] = (int8_t)h.entering;
                } else {
                    job->t[i] = INFINITY;
                    job->normal[3 * i] = job->normal[3 * i + 1] = job->normal[3 * i + 2] = 0.0;
                    job->shape[i] = -1;
                    job->object[i] = -1;
                    job->flags[i] = 0;
                }
            } else {
                job->flags[i] = (int8_t)scene_occluded(S, &w, o, d, job->t_max, NULL);
            }
        }
    }
    memcpy(wk->counts, w.counts, sizeof(wk->counts));
    wk->failed = w.oom;
    wk->stopped = w.stopped;
    work_free(&w);
    return NULL;
}

#define MAX_THREADS 256

/* Runs the job on up to `threads` threads (the caller's among them); 0 on success, -1 on failure, -2 when
 * it stopped because stop_requested() (its results are then incomplete). */
static int run_job(Job *job, int64_t threads, int64_t *counts)
{
    if (threads < 1)
        threads = 1;
    if (threads > MAX_THREADS)
        threads = MAX_THREADS;
    int64_t useful = (job->n + CHUNK - 1) / CHUNK;
    if (threads > useful)
        threads = useful > 0 ? useful : 1;
    atomic_store(&job->next, 0);
    Worker workers[MAX_THREADS];
    pthread_t ids[MAX_THREADS];
    int started[MAX_THREADS];
    for (int64_t k = 0; k < threads; k++) {
        workers[k].job = job;
        memset(workers[k].counts, 0, sizeof(workers[k].counts));
        workers[k].failed = 0;
        workers[k].stopped = 0;
        started[k] = 0;
    }
    for (int64_t k = 1; k < threads; k++)
        started[k] = pthread_create(&ids[k], NULL, run_worker, &workers[k]) == 0;
    run_worker(&workers[0]);
    int failed = 0, stopped = 0;
    for (int64_t k = 0; k < threads; k++) {
        if (k > 0 && started[k])
            pthread_join(ids[k], NULL);
        failed |= workers[k].failed;
        stopped |= workers[k].stopped;
        if (counts)
            for (int c = 0; c < N_COUNTS; c++)
                counts[c] += workers[k].counts[c];
    }
    return failed ? -1 : stopped ? -2 : 0;
}

/* Shades n camera rays.  `ray_budget`: the most reflected and transmitted rays each one's tree traces (see
 * shade.h); `cancel`: a flag polled at every ray (NULL: none) which, set, stops the batch: -2 is returned
 * (as when a signal is heard, interrupt.h) and the colours are not to be used. */
int rt_trace(void *scene, int64_t n, const double *origins, const double *directions, double *colors,
             int64_t *counts, int64_t threads, double cutoff, int64_t savings, int64_t ray_budget,
             const int32_t *cancel)
{
    const Scene *S = (const Scene *)scene;
    Job job;
    memset(&job, 0, sizeof(job));
    job.S = S;
    job.mode = JOB_TRACE;
    job.n = n;
    job.o = origins;
    job.d = directions;
    job.colors = colors;
    job.shade = pick_shade(S->d.effects);
    job.cutoff = cutoff;
    job.savings = savings;
    job.ray_budget = ray_budget < 0 ? 0 : ray_budget;
    job.cancel = cancel;
    counts[RAY_CAMERA] += n;
    return run_job(&job, threads, counts);
}

int rt_first_hits(void *scene, int64_t n, const double *origins, const double *directions, double *t,
                  double *normal, int32_t *shape, int32_t *object, int8_t *entering, int64_t threads)
{
    Job job;
    memset(&job, 0, sizeof(job));
    job.S = (const Scene *)scene;
    job.mode = JOB_FIRST;
    job.n = n;
    job.o = origins;
    job.d = directions;
    job.t = t;
    job.normal = normal;
    job.shape = shape;
    job.object = object;
    job.flags = entering;
    return run_job(&job, threads, NULL);
}

int rt_occluded(void *scene, int64_t n, const double *origins, const double *directions, double t_max,
                int8_t *blocked, int64_t threads)
{
    Job job;
    memset(&job, 0, sizeof(job));
    job.S = (const Scene *)scene;
    job.mode = JOB_OCCLUDED;
    job.n = n;
    job.o = origins;
    job.d = directions;
    job.flags = blocked;
    job.t_max = t_max;
    return run_job(&job, threads, NULL);
}

/* Whole-line hits of one top-level object (CSG: the boolean's hits), world normals not normalised, with
 * their error bounds and offsets, as the reference's obj.intersect(); returns the number of hits (only
 * `capacity` are written) or -1. */
int64_t rt_object_hits(void *scene, int64_t object, const double *origin, const double *direction,
                       int64_t capacity, double *t, int8_t *entering, double *normal, int32_t *shape,
                       int32_t *part, double *uv, int8_t *inside_at_start, double *error, double *offset)
{
    const Scene *S = (const Scene *)scene;
    if (object < 0 || object >= S->d.n_objects)
        return -1;
    Work w;
    if (!work_init(&w, S))
        return -1;
    HitList *top = &w.lists[w.n_lists - 1];
    int ok = object_hits(S, &w, S->d.object_ref[object], origin, direction, 0, top);
    int64_t n = ok && !w.oom ? top->n : -1;
    for (int64_t i = 0; i < n && i < capacity; i++) {
        const Hit *h = &top->h[i];
        t[i] = h->t;
        entering[i] = (int8_t)h->entering;
        double unit[3];
        offset[i] = world_unit_normal(S, h, unit);
        double own[16];
        normal_to_world(prim_inverse_of(&S->d, h->shape, own), h->n, normal + 3 * i);
        shape[i] = h->shape;
        part[i] = h->part;
        uv[2 * i] = h->uv[0];
        uv[2 * i + 1] = h->uv[1];
        error[i] = h->err;
    }
    if (n >= 0)
        *inside_at_start = (int8_t)top->inside;
    work_free(&w);
    return n;
}

/* TextureSet.colors: texture colours at world points on primitives `shape`, hit on `part` (1 where
 * untextured); for the tests, which compare it with the NumPy reference point by point.  -1 on a bad
 * primitive index. */
int rt_texture_colors(void *scene, int64_t n, const int32_t *shape, const double *points, const int32_t *part,
                      const double *bary, double *out)
{
    const Scene *S = (const Scene *)scene;
    for (int64_t i = 0; i < n; i++)
        if (shape[i] < 0 || shape[i] >= S->d.n_prims)
            return -1;
    for (int64_t i = 0; i < n; i++) {
        if (S->d.effects & FX_TEXTURES)
            texture_color(S, shape[i], points + 3 * i, part[i], bary ? bary + 2 * i : NULL, out + 3 * i);
        else
            out[3 * i] = out[3 * i + 1] = out[3 * i + 2] = 1.0;
    }
    return 0;
}
