/* Building a mesh's BVH in C: the same tree, node for node, as _build_bvh_numpy in
 * tracer/intersect/mesh.py (binned surface-area heuristic along the centroids' longest axis, stable
 * partitions, nodes numbered in the same depth-first order), in O(n log n) with no Python per node.
 *
 * Every floating-point step is the NumPy code's, in its order (bucket = min(trunc((c - lo) * (bins /
 * width)), bins - 1); half area = sx sy + sy sz + sz sx of the clamped sizes; cost = left area * left count
 * + right area * right count; the first minimum wins), so the two builders agree exactly and the tests
 * can compare their arrays. */
#ifndef RT_BVH_BUILD_H
#define RT_BVH_BUILD_H

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "mesh.h"

#define BVH_MAX_BINS 64
#define BVH_MAX_THREADS 256

/* The nearest float at or below / at or above x (mesh.py's _single_outward): node boxes are kept in
 * single precision, rounded outward so that they still hold every triangle.  NaN stays NaN. */
static inline float bvh_single_below(double x)
{
    float f = (float)x;
    return (double)f > x ? nextafterf(f, -INFINITY) : f;
}

static inline float bvh_single_above(double x)
{
    float f = (float)x;
    return (double)f < x ? nextafterf(f, INFINITY) : f;
}

static int bvh_grow_stack(int64_t **stack, int64_t *capacity)
{
    int64_t *p = (int64_t *)realloc(*stack, (size_t)(2 * *capacity) * sizeof(int64_t));
    if (!p)
        return 0;
    *stack = p;
    *capacity *= 2;
    return 1;
}

/* Room for at least `need` nodes in *nodes (grown by doubling); 0 when memory runs out. */
static int bvh_reserve(MeshNode **nodes, int64_t *capacity, int64_t need)
{
    if (need <= *capacity)
        return 1;
    int64_t cap = *capacity ? *capacity : 64;
    while (cap < need)
        cap *= 2;
    MeshNode *p = (MeshNode *)realloc(*nodes, (size_t)cap * sizeof(MeshNode));
    if (!p)
        return 0;
    *nodes = p;
    *capacity = cap;
    return 1;
}

static double bvh_half_area(const double *lo, const double *hi)
{
    double s[3];
    for (int k = 0; k < 3; k++) {
        double size = hi[k] - lo[k];
        size = size > 0.0 ? size : (size != size ? size : 0.0);  /* np.maximum(size, 0): NaN stays */
        s[k] = isfinite(size) ? size : 0.0;
    }
    return s[0] * s[1] + s[1] * s[2] + s[2] * s[0];
}

static inline int64_t bvh_bucket(double c, double c_lo, double scale, int64_t bins)
{
    int64_t b = (int64_t)((c - c_lo) * scale);
    return b < bins - 1 ? b : bins - 1;
}

/* A triangle's box (min and max of its corners, NaN-propagating as np.minimum and np.maximum) and the
 * centroid's coordinate on one axis ((P0 + P1 + P2) / 3 summed in corner order), from the vertices: what
 * TriangleMesh._build_bvh computes for the NumPy builder, without keeping it for every triangle. */
static inline void bvh_box(const double *vertices, const int32_t *tri, int64_t t, double *lo, double *hi)
{
    const double *p0 = vertices + 3 * (int64_t)tri[3 * t], *p1 = vertices + 3 * (int64_t)tri[3 * t + 1];
    const double *p2 = vertices + 3 * (int64_t)tri[3 * t + 2];
    for (int k = 0; k < 3; k++) {
        lo[k] = nan_min(nan_min(p0[k], p1[k]), p2[k]);
        hi[k] = nan_max(nan_max(p0[k], p1[k]), p2[k]);
    }
}

static inline double bvh_centroid(const double *vertices, const int32_t *tri, int64_t t, int k)
{
    return ((vertices[3 * (int64_t)tri[3 * t] + k] + vertices[3 * (int64_t)tri[3 * t + 1] + k]) +
            vertices[3 * (int64_t)tri[3 * t + 2] + k]) / 3.0;
}

/* What every part of a build reads and writes: the triangles, the parameters, the leaf order (each subtree
 * rearranges only its own range of it) and a scratch array of the same length (likewise). */
typedef struct {
    const double *vertices;
    const int32_t *tri;
    int64_t leaf_size, bins;
    double pad;
    int32_t *order, *scratch;
} BvhInput;

/* A node's record (its box, and a leaf's range) from the triangles order[start, end); returns where its
 * range splits (the left child takes [start, middle)), or -1 for a leaf.  *axis_out: the split axis. */
static int64_t bvh_node(const BvhInput *in, int64_t start, int64_t end, MeshNode *record, int *axis_out)
{
    const double *vertices = in->vertices;
    const int32_t *tri = in->tri;
    int32_t *order = in->order, *scratch = in->scratch;
    int64_t bins = in->bins;
    double lo[3] = {INFINITY, INFINITY, INFINITY}, hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    double c_lo[3] = {INFINITY, INFINITY, INFINITY}, c_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int64_t i = start; i < end; i++) {
        int64_t t = order[i];
        double t_lo[3], t_hi[3];
        bvh_box(vertices, tri, t, t_lo, t_hi);
        for (int k = 0; k < 3; k++) {
            double a = t_lo[k], b = t_hi[k], c = bvh_centroid(vertices, tri, t, k);
            lo[k] = a < lo[k] ? a : lo[k];
            hi[k] = b > hi[k] ? b : hi[k];
            c_lo[k] = c < c_lo[k] ? c : c_lo[k];
            c_hi[k] = c > c_hi[k] ? c : c_hi[k];
        }
    }
    memset(record, 0, sizeof(*record));
    for (int k = 0; k < 3; k++) {
        record->lo[k] = bvh_single_below(lo[k] - in->pad);
        record->hi[k] = bvh_single_above(hi[k] + in->pad);
    }
    int64_t size = end - start;
    if (size <= in->leaf_size) {
        record->offset = (int32_t)start;
        record->count = (uint16_t)size;
        record->axis = -1;
        return -1;
    }
    int axis = 0;
    for (int k = 1; k < 3; k++)
        if (c_hi[k] - c_lo[k] > c_hi[axis] - c_lo[axis])
            axis = k;
    double width = c_hi[axis] - c_lo[axis];
    double scale = (double)bins / width;
    int64_t middle;
    if (!(width > 0.0) || !isfinite(width) || !isfinite(scale)) {
        middle = start + size / 2;  /* all centroids in one place (or spread past a double): halve the range */
    } else {
        double box_lo[BVH_MAX_BINS][3], box_hi[BVH_MAX_BINS][3];
        int64_t in_bin[BVH_MAX_BINS] = {0};
        for (int64_t b = 0; b < bins; b++)
            for (int k = 0; k < 3; k++)
                box_lo[b][k] = INFINITY, box_hi[b][k] = -INFINITY;
        for (int64_t i = start; i < end; i++) {
            int64_t t = order[i];
            int64_t b = bvh_bucket(bvh_centroid(vertices, tri, t, axis), c_lo[axis], scale, bins);
            double t_lo[3], t_hi[3];
            bvh_box(vertices, tri, t, t_lo, t_hi);
            in_bin[b]++;
            for (int k = 0; k < 3; k++) {
                double a = t_lo[k], c = t_hi[k];
                box_lo[b][k] = a < box_lo[b][k] ? a : box_lo[b][k];
                box_hi[b][k] = c > box_hi[b][k] ? c : box_hi[b][k];
            }
        }
        /* Candidate k splits after bucket k: areas of the prefix and suffix boxes. */
        double right_area[BVH_MAX_BINS];
        double acc_lo[3] = {INFINITY, INFINITY, INFINITY}, acc_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
        for (int64_t b = bins - 1; b >= 1; b--) {
            for (int k = 0; k < 3; k++) {
                acc_lo[k] = box_lo[b][k] < acc_lo[k] ? box_lo[b][k] : acc_lo[k];
                acc_hi[k] = box_hi[b][k] > acc_hi[k] ? box_hi[b][k] : acc_hi[k];
            }
            right_area[b - 1] = bvh_half_area(acc_lo, acc_hi);
        }
        for (int k = 0; k < 3; k++)
            acc_lo[k] = INFINITY, acc_hi[k] = -INFINITY;
        int64_t best = -1, left_count = 0;
        double best_cost = INFINITY;
        for (int64_t b = 0; b + 1 < bins; b++) {
            for (int k = 0; k < 3; k++) {
                acc_lo[k] = box_lo[b][k] < acc_lo[k] ? box_lo[b][k] : acc_lo[k];
                acc_hi[k] = box_hi[b][k] > acc_hi[k] ? box_hi[b][k] : acc_hi[k];
            }
            left_count += in_bin[b];
            int64_t right_count = size - left_count;
            double cost = (left_count == 0 || right_count == 0)
                              ? INFINITY
                              : bvh_half_area(acc_lo, acc_hi) * (double)left_count +
                                    right_area[b] * (double)right_count;
            if (best < 0 || cost < best_cost) {  /* np.argmin: the first minimum */
                best = b;
                best_cost = cost;
            }
        }
        /* Stable partition: the left buckets keep their order at the front, the rest follows. */
        int64_t kept = start, moved = 0;
        for (int64_t i = start; i < end; i++) {
            int64_t t = order[i];
            if (bvh_bucket(bvh_centroid(vertices, tri, t, axis), c_lo[axis], scale, bins) <= best)
                order[kept++] = t;
            else
                scratch[start + moved++] = t;
        }
        for (int64_t i = 0; i < moved; i++)
            order[kept + i] = scratch[start + i];
        /* (a split with an empty side would never end: halve instead; the order is then unchanged) */
        middle = kept == start || kept == end ? start + size / 2 : kept;
    }
    *axis_out = axis;
    return middle;
}

/* A subtree still to be built: over order[start, end), its nodes (its root first, then its descendants in
 * the order the sequential builder numbers them) into its own buffer. */
typedef struct {
    int64_t start, end;
    MeshNode *nodes;
    int64_t count, capacity;
    int failed;
} BvhTask;

/* Marks a node record as standing for task k (until the tasks' nodes are put in place). */
#define BVH_DEFERRED (-2)

/* The sequential builder over order[start, end): the root at index 0 of *out, each node's children
 * numbered together when it splits, a left subtree's nodes all before its right sibling's (the numbering
 * of _build_bvh_numpy).  A node other than the root with at most `defer` triangles is not built: its record
 * says BVH_DEFERRED with the index of the task appended to *tasks for it.  Returns the number of nodes, or -1
 * when memory runs out. */
static int64_t bvh_build_range(const BvhInput *in, int64_t start, int64_t end, int64_t defer, MeshNode **out,
                               int64_t *capacity, BvhTask **tasks, int64_t *n_tasks, int64_t *task_capacity)
{
    int64_t stack_capacity = 3 * 64, top = 0, nodes = 1;
    int64_t *stack = (int64_t *)malloc((size_t)stack_capacity * sizeof(int64_t));
    if (!stack || !bvh_reserve(out, capacity, 2 * ((end - start) / (in->leaf_size + 1)) + 1)) {
        free(stack);
        return -1;
    }
    stack[top++] = 0, stack[top++] = start, stack[top++] = end;
    while (top) {
        int64_t hi_end = stack[--top], lo_start = stack[--top], node = stack[--top];
        if (node > 0 && hi_end - lo_start <= defer) {
            if (*n_tasks == *task_capacity) {
                int64_t cap = *task_capacity ? 2 * *task_capacity : 16;
                BvhTask *p = (BvhTask *)realloc(*tasks, (size_t)cap * sizeof(BvhTask));
                if (!p) {
                    free(stack);
                    return -1;
                }
                *tasks = p;
                *task_capacity = cap;
            }
            BvhTask *task = &(*tasks)[*n_tasks];
            memset(task, 0, sizeof(*task));
            task->start = lo_start;
            task->end = hi_end;
            memset(&(*out)[node], 0, sizeof(MeshNode));
            (*out)[node].offset = (int32_t)(*n_tasks)++;
            (*out)[node].axis = BVH_DEFERRED;
            continue;
        }
        int axis = 0;
        int64_t middle = bvh_node(in, lo_start, hi_end, &(*out)[node], &axis);
        if (middle < 0)
            continue;
        if (!bvh_reserve(out, capacity, nodes + 2) ||
            (top + 6 > stack_capacity && !bvh_grow_stack(&stack, &stack_capacity))) {
            free(stack);
            return -1;
        }
        MeshNode *record = &(*out)[node];
        int64_t l = nodes++, r = nodes++;
        record->offset = (int32_t)l;
        record->count = 0;
        record->axis = (int8_t)axis;
        stack[top++] = r, stack[top++] = middle, stack[top++] = hi_end;
        stack[top++] = l, stack[top++] = lo_start, stack[top++] = middle;
    }
    free(stack);
    return nodes;
}

typedef struct {
    const BvhInput *in;
    BvhTask *tasks;
    int64_t n_tasks;
    _Atomic int64_t next;
} BvhJob;

static void *bvh_worker(void *arg)
{
    BvhJob *job = (BvhJob *)arg;
    for (;;) {
        int64_t k = atomic_fetch_add(&job->next, 1);
        if (k >= job->n_tasks)
            return NULL;
        BvhTask *task = &job->tasks[k];
        task->count = bvh_build_range(job->in, task->start, task->end, 0, &task->nodes, &task->capacity, NULL,
                                      NULL, NULL);
        task->failed = task->count < 0;
    }
}

static int bvh_larger_task_first(const void *a, const void *b)
{
    int64_t x = ((const BvhTask *)a)->end - ((const BvhTask *)a)->start;
    int64_t y = ((const BvhTask *)b)->end - ((const BvhTask *)b)->start;
    return (x < y) - (x > y);
}

/* The top part's nodes and the tasks' nodes numbered as the sequential builder numbers them, into one
 * buffer: walking the top part depth first, a task's root takes its place and its descendants the next
 * indices.  Returns the buffer (count in *total), or NULL when memory runs out. */
static MeshNode *bvh_stitch(const MeshNode *top, BvhTask *tasks, int64_t *total)
{
    MeshNode *out = (MeshNode *)malloc((size_t)*total * sizeof(MeshNode));
    int64_t capacity = 3 * 64, sp = 0, nodes = 1;
    int64_t *stack = (int64_t *)malloc((size_t)capacity * sizeof(int64_t));
    if (!out || !stack) {
        free(out);
        free(stack);
        return NULL;
    }
    stack[sp++] = 0, stack[sp++] = 0;  /* (node in the top part, its final index) */
    while (sp) {
        int64_t g = stack[--sp], t = stack[--sp];
        if (top[t].axis == BVH_DEFERRED) {
            const BvhTask *task = &tasks[top[t].offset];
            int64_t base = nodes - 1;  /* a task's node j >= 1 goes to base + j */
            for (int64_t j = 0; j < task->count; j++) {
                MeshNode record = task->nodes[j];
                if (record.count == 0)
                    record.offset = (int32_t)(base + record.offset);
                out[j == 0 ? g : base + j] = record;
            }
            nodes += task->count - 1;
            continue;
        }
        out[g] = top[t];
        if (top[t].count)
            continue;
        if (sp + 4 > capacity && !bvh_grow_stack(&stack, &capacity)) {
            free(out);
            free(stack);
            return NULL;
        }
        int64_t l = nodes;
        nodes += 2;
        out[g].offset = (int32_t)l;
        stack[sp++] = top[t].offset + 1, stack[sp++] = l + 1;
        stack[sp++] = top[t].offset, stack[sp++] = l;
    }
    free(stack);
    return out;
}

/* Below this many triangles a build runs on one thread. */
#define BVH_PARALLEL_MIN 65536

/* Build over the n triangles tri (3 vertex indices each, checked by the caller) of the vertices, on up to
 * `threads` threads: the top of the tree on one, then its subtrees of at most n / (8 threads) triangles
 * on all, then their nodes numbered as one thread numbers them, so that the tree is the same whatever the
 * thread count.  Writes order (n) and, into a buffer it allocates (*nodes_out, to be released with
 * rt_free), the MeshNode records with their boxes grown by `pad` and rounded outward.  Returns the number of
 * nodes, or -1 when memory runs out or the arguments are out of range. */
int64_t rt_build_mesh_bvh(int64_t n, const double *vertices, const int32_t *tri, int64_t leaf_size, int64_t bins,
                          double pad, int64_t threads, int32_t *order, void **nodes_out)
{
    *nodes_out = NULL;
    if (n < 0 || n > INT32_MAX || leaf_size < 1 || leaf_size > UINT16_MAX || bins < 2 || bins > BVH_MAX_BINS)
        return -1;
    for (int64_t i = 0; i < n; i++)
        order[i] = (int32_t)i;
    if (n == 0)
        return 0;
    if (threads > BVH_MAX_THREADS)
        threads = BVH_MAX_THREADS;
    int32_t *scratch = (int32_t *)malloc((size_t)n * sizeof(int32_t));
    if (!scratch)
        return -1;
    BvhInput in = {vertices, tri, leaf_size, bins, pad, order, scratch};
    MeshNode *top = NULL;
    BvhTask *tasks = NULL;
    int64_t capacity = 0, n_tasks = 0, task_capacity = 0, result = -1;
    int64_t defer = threads > 1 && n >= BVH_PARALLEL_MIN ? n / (8 * threads) : 0;
    int64_t count = bvh_build_range(&in, 0, n, defer, &top, &capacity, &tasks, &n_tasks, &task_capacity);
    if (count < 0)
        goto done;
    if (n_tasks == 0) {
        *nodes_out = top;
        top = NULL;
        result = count;
        goto done;
    }
    {
        /* (the tasks are numbered in the top part's records: sorting them needs their numbers kept) */
        int64_t *number = (int64_t *)malloc((size_t)n_tasks * sizeof(int64_t));
        BvhTask *sorted = (BvhTask *)malloc((size_t)n_tasks * sizeof(BvhTask));
        if (!number || !sorted) {
            free(number);
            free(sorted);
            goto done;
        }
        for (int64_t k = 0; k < n_tasks; k++) {
            sorted[k] = tasks[k];
            sorted[k].count = k;  /* its number, until built */
        }
        qsort(sorted, (size_t)n_tasks, sizeof(BvhTask), bvh_larger_task_first);  /* biggest first: balance */
        for (int64_t k = 0; k < n_tasks; k++)
            number[sorted[k].count] = k;
        for (int64_t k = 0; k < count; k++)
            if (top[k].axis == BVH_DEFERRED)
                top[k].offset = (int32_t)number[top[k].offset];
        free(number);
        free(tasks);
        tasks = sorted;
        for (int64_t k = 0; k < n_tasks; k++)
            tasks[k].count = 0;
    }
    BvhJob job = {&in, tasks, n_tasks, 0};
    pthread_t ids[BVH_MAX_THREADS];
    int started[BVH_MAX_THREADS] = {0};
    for (int64_t k = 1; k < threads; k++)
        started[k] = pthread_create(&ids[k], NULL, bvh_worker, &job) == 0;
    bvh_worker(&job);
    for (int64_t k = 1; k < threads; k++)
        if (started[k])
            pthread_join(ids[k], NULL);
    int64_t total = count;
    int failed = 0;
    for (int64_t k = 0; k < n_tasks; k++) {
        failed |= tasks[k].failed;
        total += tasks[k].count - 1;
    }
    if (!failed) {
        *nodes_out = bvh_stitch(top, tasks, &total);
        result = *nodes_out ? total : -1;
    }
done:
    for (int64_t k = 0; k < n_tasks; k++)
        free(tasks[k].nodes);
    free(tasks);
    free(top);
    free(scratch);
    return result;
}

/* ------------------------------------------------------------------------------------------------------
 * The object hierarchy: a binary tree of boxes over a scene's bounded objects (core.c's build_tree feeds
 * it and turns the result into PairNodes).  Binned surface-area heuristic along every axis, an in-place
 * partition; on several threads the top of the tree is built on one, its subtrees on all, and their nodes
 * numbered as one thread numbers them, so that the tree does not depend on the thread count (as for meshes
 * above). */

/* The object hierarchy while it is built. */
typedef struct {
    double lo[3], hi[3];
    int32_t left;         /* inner: left child (right = left + 1) */
    int32_t first, count; /* leaf: items[first : first + count]; count = 0 for inner nodes */
    int32_t axis;         /* inner: the split axis; BVH_DEFERRED: left is a task's number */
} TopNode;

/* Tree shape (measured on the 1k and 10k sphere benchmarks; other values within noise): 16 bins per axis,
 * single objects in the leaves where a split is possible at all, and nodes of up to LEAF_MAX objects kept
 * whole when no split has a lower surface-area cost (SAH_TRAVERSAL: the cost of a box test, in objects). */
#define SAH_BINS 16
#define LEAF_MIN 1
#define LEAF_MAX 4
#define SAH_TRAVERSAL 0.0

static double half_area(const double *lo, const double *hi)
{
    double x = hi[0] - lo[0], y = hi[1] - lo[1], z = hi[2] - lo[2];
    if (!(x >= 0.0 && y >= 0.0 && z >= 0.0))
        return 0.0;
    return x * y + y * z + z * x;
}

static void box_empty(double *lo, double *hi)
{
    for (int i = 0; i < 3; i++) {
        lo[i] = INFINITY;
        hi[i] = -INFINITY;
    }
}

static void box_grow(double *lo, double *hi, const double *blo, const double *bhi)
{
    /* (stored whether changed or not: the compiler may then use minsd/maxsd, which give these same
     * values, instead of a branch that mispredicts on every other object) */
    for (int i = 0; i < 3; i++) {
        lo[i] = blo[i] < lo[i] ? blo[i] : lo[i];
        hi[i] = bhi[i] > hi[i] ? bhi[i] : hi[i];
    }
}

static inline int64_t sah_bin(double c, double lo, double extent)
{
    int64_t k = (int64_t)((c - lo) * (SAH_BINS / extent));
    return k >= SAH_BINS ? SAH_BINS - 1 : (k < 0 ? 0 : k);
}

/* What every part of an object build reads and rearranges: per position, the object (items), its box's
 * centre (3) and its box (6: lo, hi; NaN-free, lo <= hi).  A node over positions [start, end) permutes
 * only those. */
typedef struct {
    int64_t *items;
    double *centre, *boxes;
} ObjectInput;

/* A node's record from positions [start, end): its box, and whether it is a leaf; when it splits, its
 * positions are partitioned (the left child's first) and *middle says where. */
static int object_node(const ObjectInput *in, int64_t start, int64_t end, TopNode *node, int64_t *middle)
{
    int64_t *items = in->items;
    double *centre = in->centre, *boxes = in->boxes;
    double clo[3], chi[3];
    box_empty(node->lo, node->hi);
    box_empty(clo, chi);
    for (int64_t i = start; i < end; i++) {
        const double *box = boxes + 6 * i;
        box_grow(node->lo, node->hi, box, box + 3);
        box_grow(clo, chi, centre + 3 * i, centre + 3 * i);
    }
    int64_t n = end - start;
    node->count = 0;
    node->first = -1;
    node->left = -1;
    node->axis = 0;
    if (n <= LEAF_MIN) {
        node->first = (int32_t)start;
        node->count = (int32_t)n;
        return 0;
    }
    /* the binned surface-area heuristic along every axis with some spread of centres: the three axes'
     * bins filled in one pass over the objects (each box read once) */
    int axis = -1;
    int64_t best_split = -1;
    double best_cost = INFINITY;
    int64_t count[3][SAH_BINS] = {{0}};
    double blo[3][SAH_BINS][3], bhi[3][SAH_BINS][3];
    double extent[3];
    int spread[3];
    for (int k = 0; k < 3; k++) {
        extent[k] = chi[k] - clo[k];
        spread[k] = extent[k] > 0.0;
        for (int j = 0; j < SAH_BINS; j++)
            box_empty(blo[k][j], bhi[k][j]);
    }
    for (int64_t i = start; i < end; i++) {
        const double *box = boxes + 6 * i;
        for (int k = 0; k < 3; k++) {
            if (!spread[k])
                continue;
            int64_t j = sah_bin(centre[3 * i + k], clo[k], extent[k]);
            count[k][j]++;
            box_grow(blo[k][j], bhi[k][j], box, box + 3);
        }
    }
    for (int k = 0; k < 3; k++) {
        if (!spread[k])
            continue;
        double right_area[SAH_BINS];
        int64_t right_count[SAH_BINS];
        double rlo[3], rhi[3];
        box_empty(rlo, rhi);
        int64_t rc = 0;
        for (int j = SAH_BINS - 1; j > 0; j--) {
            box_grow(rlo, rhi, blo[k][j], bhi[k][j]);
            rc += count[k][j];
            right_area[j] = half_area(rlo, rhi);
            right_count[j] = rc;
        }
        double llo[3], lhi[3];
        box_empty(llo, lhi);
        int64_t lc = 0;
        for (int j = 0; j < SAH_BINS - 1; j++) {
            box_grow(llo, lhi, blo[k][j], bhi[k][j]);
            lc += count[k][j];
            if (lc == 0 || right_count[j + 1] == 0)
                continue;
            double cost = half_area(llo, lhi) * (double)lc + right_area[j + 1] * (double)right_count[j + 1];
            if (cost < best_cost) {
                best_cost = cost;
                best_split = j;
                axis = k;
            }
        }
    }
    int64_t mid = start + n / 2;
    if (axis >= 0) {
        /* small nodes become leaves when no split beats testing every object */
        double area = half_area(node->lo, node->hi);
        if (n <= LEAF_MAX && SAH_TRAVERSAL * area + best_cost >= area * (double)n) {
            node->first = (int32_t)start;
            node->count = (int32_t)n;
            return 0;
        }
        /* partition items (and their centres and boxes) so that bins <= best_split come first */
        double lo_axis = clo[axis], extent = chi[axis] - clo[axis];
        int64_t i = start, j = end - 1;
        while (i <= j) {
            if (sah_bin(centre[3 * i + axis], lo_axis, extent) <= best_split) {
                i++;
            } else {
                int64_t x = items[i]; items[i] = items[j]; items[j] = x;
                for (int k = 0; k < 3; k++) {
                    double c = centre[3 * i + k];
                    centre[3 * i + k] = centre[3 * j + k];
                    centre[3 * j + k] = c;
                }
                for (int k = 0; k < 6; k++) {
                    double c = boxes[6 * i + k];
                    boxes[6 * i + k] = boxes[6 * j + k];
                    boxes[6 * j + k] = c;
                }
                j--;
            }
        }
        if (i > start && i < end)
            mid = i;
    } else {
        axis = 0;
        if (n <= 8) {
            node->first = (int32_t)start;
            node->count = (int32_t)n;
            return 0;
        }
    }
    node->axis = axis;
    *middle = mid;
    return 1;
}

/* A subtree of the object hierarchy still to be built (or built: its nodes, root first, numbered as the
 * sequential builder numbers them from its root). */
typedef struct {
    int64_t start, end, depth;
    TopNode *nodes;
    int64_t count, capacity, deepest;
    int failed;
} ObjectTask;

static int object_reserve(TopNode **nodes, int64_t *capacity, int64_t need)
{
    if (need <= *capacity)
        return 1;
    int64_t cap = *capacity ? *capacity : 64;
    while (cap < need)
        cap *= 2;
    TopNode *p = (TopNode *)realloc(*nodes, (size_t)cap * sizeof(TopNode));
    if (!p)
        return 0;
    *nodes = p;
    *capacity = cap;
    return 1;
}

/* The sequential builder over positions [task->start, task->end), its root at depth task->depth: nodes
 * into task->nodes, the root at index 0, each node's children numbered together when it splits, a left
 * subtree's nodes all before its right sibling's.  A node other than the root over at most `defer`
 * positions is not built: its record says BVH_DEFERRED with the number of the task appended to *tasks for
 * it.  Returns 0 when memory runs out. */
static int object_build_range(const ObjectInput *in, ObjectTask *task, int64_t defer, ObjectTask **tasks,
                              int64_t *n_tasks, int64_t *task_capacity)
{
    int64_t stack_capacity = 4 * 64, top = 0, nodes = 1;
    int64_t *stack = (int64_t *)malloc((size_t)stack_capacity * sizeof(int64_t));
    task->count = 0;
    task->deepest = task->depth;
    /* (a tree over n objects has at most 2n - 1 nodes: room for all at once, but for the top part of a
     * parallel build, which grows as it needs) */
    if (!stack || !object_reserve(&task->nodes, &task->capacity, defer ? 64 : 2 * (task->end - task->start))) {
        free(stack);
        return 0;
    }
    stack[top++] = 0, stack[top++] = task->start, stack[top++] = task->end, stack[top++] = task->depth;
    while (top) {
        int64_t depth = stack[--top], end = stack[--top], start = stack[--top], node = stack[--top];
        if (depth > task->deepest)
            task->deepest = depth;
        if (!object_reserve(&task->nodes, &task->capacity, nodes + 2)) {
            free(stack);
            return 0;
        }
        TopNode *record = &task->nodes[node];
        if (node > 0 && end - start <= defer) {
            if (*n_tasks == *task_capacity) {
                int64_t cap = *task_capacity ? 2 * *task_capacity : 16;
                ObjectTask *p = (ObjectTask *)realloc(*tasks, (size_t)cap * sizeof(ObjectTask));
                if (!p) {
                    free(stack);
                    return 0;
                }
                *tasks = p;
                *task_capacity = cap;
            }
            ObjectTask *deferred = &(*tasks)[*n_tasks];
            memset(deferred, 0, sizeof(*deferred));
            deferred->start = start, deferred->end = end, deferred->depth = depth;
            memset(record, 0, sizeof(*record));
            record->left = (int32_t)(*n_tasks)++;
            record->axis = BVH_DEFERRED;
            continue;
        }
        int64_t middle;
        if (!object_node(in, start, end, record, &middle))
            continue;
        if (top + 8 > stack_capacity && !bvh_grow_stack(&stack, &stack_capacity)) {
            free(stack);
            return 0;
        }
        record->left = (int32_t)nodes;
        nodes += 2;
        stack[top++] = record->left + 1, stack[top++] = middle, stack[top++] = end, stack[top++] = depth + 1;
        stack[top++] = record->left, stack[top++] = start, stack[top++] = middle, stack[top++] = depth + 1;
    }
    free(stack);
    task->count = nodes;
    return 1;
}

typedef struct {
    const ObjectInput *in;
    ObjectTask *tasks;
    const int64_t *queue;  /* task numbers, the largest first */
    int64_t n_tasks;
    _Atomic int64_t next;
} ObjectJob;

static void *object_worker(void *arg)
{
    ObjectJob *job = (ObjectJob *)arg;
    for (;;) {
        int64_t k = atomic_fetch_add(&job->next, 1);
        if (k >= job->n_tasks)
            return NULL;
        ObjectTask *task = &job->tasks[job->queue[k]];
        task->failed = !object_build_range(job->in, task, 0, NULL, NULL, NULL);
    }
}

/* (size, number) of a task, for ordering the queue: the largest first, then by number. */
typedef struct {
    int64_t size, number;
} ObjectQueueEntry;

static int object_larger_first(const void *a, const void *b)
{
    const ObjectQueueEntry *x = (const ObjectQueueEntry *)a, *y = (const ObjectQueueEntry *)b;
    if (x->size != y->size)
        return (x->size < y->size) - (x->size > y->size);
    return (x->number > y->number) - (x->number < y->number);
}

/* The top part's nodes and the tasks' nodes numbered as the sequential builder numbers them, into one
 * buffer of `total` nodes (each task's buffer released once copied).  NULL when memory runs out. */
static TopNode *object_stitch(const TopNode *top, ObjectTask *tasks, int64_t total)
{
    TopNode *out = (TopNode *)malloc((size_t)total * sizeof(TopNode));
    int64_t capacity = 4 * 64, sp = 0, nodes = 1;
    int64_t *stack = (int64_t *)malloc((size_t)capacity * sizeof(int64_t));
    if (!out || !stack) {
        free(out);
        free(stack);
        return NULL;
    }
    stack[sp++] = 0, stack[sp++] = 0;  /* (node in the top part, its final index) */
    while (sp) {
        int64_t g = stack[--sp], t = stack[--sp];
        if (top[t].axis == BVH_DEFERRED) {
            ObjectTask *task = &tasks[top[t].left];
            int64_t base = nodes - 1;  /* a task's node j >= 1 goes to base + j */
            for (int64_t j = 0; j < task->count; j++) {
                TopNode record = task->nodes[j];
                if (record.count == 0)
                    record.left = (int32_t)(base + record.left);
                out[j == 0 ? g : base + j] = record;
            }
            nodes += task->count - 1;
            free(task->nodes);
            task->nodes = NULL;
            continue;
        }
        out[g] = top[t];
        if (top[t].count)
            continue;
        if (sp + 4 > capacity && !bvh_grow_stack(&stack, &capacity)) {
            free(out);
            free(stack);
            return NULL;
        }
        int64_t l = nodes;
        nodes += 2;
        out[g].left = (int32_t)l;
        stack[sp++] = top[t].left + 1, stack[sp++] = l + 1;
        stack[sp++] = top[t].left, stack[sp++] = l;
    }
    free(stack);
    return out;
}

/* Below this many objects a build runs on one thread. */
#define OBJECT_PARALLEL_MIN 65536

/* Builds the hierarchy over n objects (in->items, in->centre and in->boxes by position, permuted into leaf
 * order) on up to `threads` threads; the tree is the same whatever the count.  Returns the nodes (root
 * first; *count nodes, *depth the deepest level, the root's being 1), or NULL when memory runs out. */
static TopNode *object_bvh_build(const ObjectInput *in, int64_t n, int64_t threads, int64_t *count, int64_t *depth)
{
    if (threads > BVH_MAX_THREADS)
        threads = BVH_MAX_THREADS;
    ObjectTask root = {0, n, 1, NULL, 0, 0, 0, 0};
    ObjectTask *tasks = NULL;
    int64_t n_tasks = 0, task_capacity = 0;
    int64_t defer = threads > 1 && n >= OBJECT_PARALLEL_MIN ? n / (8 * threads) : 0;
    TopNode *result = NULL;
    int64_t *queue = NULL;
    ObjectQueueEntry *order = NULL;
    if (!object_build_range(in, &root, defer, &tasks, &n_tasks, &task_capacity))
        goto done;
    if (n_tasks == 0) {
        result = root.nodes;
        root.nodes = NULL;
        *count = root.count;
        *depth = root.deepest;
        goto done;
    }
    queue = (int64_t *)malloc((size_t)n_tasks * sizeof(int64_t));
    order = (ObjectQueueEntry *)malloc((size_t)n_tasks * sizeof(ObjectQueueEntry));
    if (!queue || !order)
        goto done;
    for (int64_t k = 0; k < n_tasks; k++)
        order[k] = (ObjectQueueEntry){tasks[k].end - tasks[k].start, k};
    qsort(order, (size_t)n_tasks, sizeof(ObjectQueueEntry), object_larger_first);  /* balance */
    for (int64_t k = 0; k < n_tasks; k++)
        queue[k] = order[k].number;
    ObjectJob job = {in, tasks, queue, n_tasks, 0};
    pthread_t ids[BVH_MAX_THREADS];
    int started[BVH_MAX_THREADS] = {0};
    for (int64_t k = 1; k < threads; k++)
        started[k] = pthread_create(&ids[k], NULL, object_worker, &job) == 0;
    object_worker(&job);
    for (int64_t k = 1; k < threads; k++)
        if (started[k])
            pthread_join(ids[k], NULL);
    int64_t total = root.count, deepest = root.deepest;
    int failed = 0;
    for (int64_t k = 0; k < n_tasks; k++) {
        failed |= tasks[k].failed;
        total += tasks[k].count - 1;
        if (tasks[k].deepest > deepest)
            deepest = tasks[k].deepest;
    }
    if (!failed) {
        result = object_stitch(root.nodes, tasks, total);
        *count = total;
        *depth = deepest;
    }
done:
    for (int64_t k = 0; k < n_tasks; k++)
        free(tasks[k].nodes);
    free(tasks);
    free(root.nodes);
    free(queue);
    free(order);
    return result;
}

#endif
