/* Bounding volume hierarchies built in C: one builder for a mesh's triangles and for a scene's objects.
 *
 * The builder (bvh_build) makes a binary tree of BvhNode records, numbered depth first with each node's two
 * children together; what differs between meshes and objects is only how a node is made from its items and
 * split (a BvhSource's `split`), and that is all each of them writes:
 *
 *  - mesh_split: the same tree, node for node, as _build_bvh_numpy in tracer/intersect/mesh.py (binned
 *    surface-area heuristic along the centroids' longest axis, stable partitions).  Every floating-point
 *    step is the NumPy code's, in its order (bucket = min(trunc((c - lo) * (bins / width)), bins - 1); half
 *    area = sx sy + sy sz + sz sx of the clamped sizes; cost = left area * left count + right area * right
 *    count; the first minimum wins), so the two builders agree exactly and the tests compare their arrays.
 *  - object_split: the scene's object hierarchy (core.c's build_tree): binned surface-area heuristic along
 *    every axis, an in-place partition, small nodes kept whole when no split is cheaper.
 *
 * On several threads the top of the tree is built on one, then its subtrees of at most n / (8 threads) items
 * on all, then their nodes are numbered as one thread numbers them, so that the tree does not depend on the
 * thread count.  Node boxes are kept in single precision, rounded outward so that they still hold their
 * items. */
#ifndef RT_BVH_BUILD_H
#define RT_BVH_BUILD_H

#include <math.h>
#include <pthread.h>
#include <stdatomic.h>
#include <stddef.h>
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "numeric.h"

/* One node of a built tree (tracer.intersect.mesh.NODE): the box in single precision (rounded outward); an
 * inner node (count 0) has its children at offset and offset + 1 and was split along axis; a leaf (axis -1)
 * holds the items offset .. offset + count - 1 of the leaf order. */
typedef struct {
    float lo[3], hi[3];
    int32_t offset;
    uint16_t count;
    int8_t axis;
    uint8_t pad;
} BvhNode;

_Static_assert(sizeof(BvhNode) == 32 && offsetof(BvhNode, hi) == 12 && offsetof(BvhNode, offset) == 24 &&
                   offsetof(BvhNode, count) == 28 && offsetof(BvhNode, axis) == 30,
               "BvhNode must match tracer.intersect.mesh.NODE");

#define BVH_MAX_BINS 64
#define BVH_MAX_THREADS 256
/* Below this many items a build runs on one thread. */
#define BVH_PARALLEL_MIN 65536
/* A node's axis while its subtree is a task of its own (its offset: the task's number). */
#define BVH_DEFERRED (-2)

/* The nearest float at or below / at or above x (mesh.py's _single_outward): node boxes are kept in
 * single precision, rounded outward so that they still hold every item.  NaN stays NaN. */
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

/* ------------------------------------------------------------------------------------------------------
 * The builder */

/* What a build splits.  split(input, start, end, record) makes the record of the node over the items in
 * leaf-order positions [start, end) (its box; a leaf's range and axis -1) and returns where the range splits
 * (the left child takes [start, middle)), or -1 for a leaf; it rearranges only the items of its range.
 * per_leaf: about how many items a leaf holds (to size the first node buffer). */
typedef struct {
    int64_t (*split)(const void *input, int64_t start, int64_t end, BvhNode *record);
    const void *input;
    int64_t per_leaf;
} BvhSource;

/* A subtree to be built (or built: its nodes, root first, numbered as the sequential builder numbers them
 * from its root; depth: its root's, the tree's root being 1; deepest: its deepest node's). */
typedef struct {
    int64_t start, end, depth;
    BvhNode *nodes;
    int64_t count, capacity, deepest;
    int failed;
} BvhTask;

/* The subtrees the top part left to the workers. */
typedef struct {
    BvhTask *task;
    int64_t n, capacity;
} BvhTasks;

static int bvh_grow_stack(int64_t **stack, int64_t *capacity)
{
    int64_t *p = (int64_t *)realloc(*stack, (size_t)(2 * *capacity) * sizeof(int64_t));
    if (!p)
        return 0;
    *stack = p;
    *capacity *= 2;
    return 1;
}

/* Room for at least `need` nodes in task->nodes (grown by doubling); 0 when memory runs out. */
static int bvh_reserve(BvhTask *task, int64_t need)
{
    if (need <= task->capacity)
        return 1;
    int64_t cap = task->capacity ? task->capacity : 64;
    while (cap < need)
        cap *= 2;
    BvhNode *p = (BvhNode *)realloc(task->nodes, (size_t)cap * sizeof(BvhNode));
    if (!p)
        return 0;
    task->nodes = p;
    task->capacity = cap;
    return 1;
}

/* Appends the subtree over [start, end) at `depth` to the deferred tasks and marks `record` as standing for
 * it; 0 when memory runs out. */
static int bvh_defer(BvhTasks *deferred, int64_t start, int64_t end, int64_t depth, BvhNode *record)
{
    if (deferred->n == deferred->capacity) {
        int64_t cap = deferred->capacity ? 2 * deferred->capacity : 16;
        BvhTask *p = (BvhTask *)realloc(deferred->task, (size_t)cap * sizeof(BvhTask));
        if (!p)
            return 0;
        deferred->task = p;
        deferred->capacity = cap;
    }
    BvhTask *task = &deferred->task[deferred->n];
    memset(task, 0, sizeof(*task));
    task->start = start, task->end = end, task->depth = depth;
    memset(record, 0, sizeof(*record));
    record->offset = (int32_t)deferred->n++;
    record->axis = BVH_DEFERRED;
    return 1;
}

/* The sequential builder over [task->start, task->end): nodes into task->nodes, the root at index 0, each
 * node's children numbered together when it splits, a left subtree's nodes all before its right sibling's.
 * A node other than the root over at most `defer` items is not built but appended to *deferred (which may
 * be NULL when defer is 0).  Returns 0 when memory runs out. */
static int bvh_build_range(const BvhSource *src, BvhTask *task, int64_t defer, BvhTasks *deferred)
{
    int64_t stack_capacity = 4 * 64, top = 0, nodes = 1;
    int64_t *stack = (int64_t *)malloc((size_t)stack_capacity * sizeof(int64_t));
    int64_t size = task->end - task->start;
    task->count = 0;
    task->deepest = task->depth;
    /* (room for the whole subtree at once, but for the top part of a parallel build, which grows as it needs) */
    if (!stack || !bvh_reserve(task, defer ? 64 : 2 * (size / src->per_leaf) + 1)) {
        free(stack);
        return 0;
    }
    stack[top++] = 0, stack[top++] = task->start, stack[top++] = task->end, stack[top++] = task->depth;
    while (top) {
        int64_t depth = stack[--top], end = stack[--top], start = stack[--top], node = stack[--top];
        if (depth > task->deepest)
            task->deepest = depth;
        if (node > 0 && end - start <= defer) {
            if (!bvh_defer(deferred, start, end, depth, &task->nodes[node])) {
                free(stack);
                return 0;
            }
            continue;
        }
        int64_t middle = src->split(src->input, start, end, &task->nodes[node]);
        if (middle < 0)
            continue;
        if (!bvh_reserve(task, nodes + 2) || (top + 8 > stack_capacity && !bvh_grow_stack(&stack, &stack_capacity))) {
            free(stack);
            return 0;
        }
        int64_t left = nodes;
        nodes += 2;
        task->nodes[node].offset = (int32_t)left;
        task->nodes[node].count = 0;
        stack[top++] = left + 1, stack[top++] = middle, stack[top++] = end, stack[top++] = depth + 1;
        stack[top++] = left, stack[top++] = start, stack[top++] = middle, stack[top++] = depth + 1;
    }
    free(stack);
    task->count = nodes;
    return 1;
}

typedef struct {
    const BvhSource *src;
    BvhTask *tasks;
    const int64_t *queue;  /* task numbers, the largest first */
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
        BvhTask *task = &job->tasks[job->queue[k]];
        task->failed = !bvh_build_range(job->src, task, 0, NULL);
    }
}

/* (size, number) of a task, for ordering the queue: the largest first, then by number. */
typedef struct {
    int64_t size, number;
} BvhQueueEntry;

static int bvh_larger_first(const void *a, const void *b)
{
    const BvhQueueEntry *x = (const BvhQueueEntry *)a, *y = (const BvhQueueEntry *)b;
    if (x->size != y->size)
        return (x->size < y->size) - (x->size > y->size);
    return (x->number > y->number) - (x->number < y->number);
}

/* Builds the deferred tasks on up to `threads` threads (the caller's among them), the largest first. 0 when
 * memory runs out (or a task failed). */
static int bvh_run_tasks(const BvhSource *src, BvhTasks *deferred, int64_t threads)
{
    int64_t n = deferred->n;
    int64_t *queue = (int64_t *)malloc((size_t)n * sizeof(int64_t));
    BvhQueueEntry *order = (BvhQueueEntry *)malloc((size_t)n * sizeof(BvhQueueEntry));
    if (!queue || !order) {
        free(queue);
        free(order);
        return 0;
    }
    for (int64_t k = 0; k < n; k++)
        order[k] = (BvhQueueEntry){deferred->task[k].end - deferred->task[k].start, k};
    qsort(order, (size_t)n, sizeof(BvhQueueEntry), bvh_larger_first);  /* balance */
    for (int64_t k = 0; k < n; k++)
        queue[k] = order[k].number;
    free(order);
    BvhJob job = {src, deferred->task, queue, n, 0};
    pthread_t ids[BVH_MAX_THREADS];
    int started[BVH_MAX_THREADS] = {0};
    for (int64_t k = 1; k < threads; k++)
        started[k] = pthread_create(&ids[k], NULL, bvh_worker, &job) == 0;
    bvh_worker(&job);
    for (int64_t k = 1; k < threads; k++)
        if (started[k])
            pthread_join(ids[k], NULL);
    free(queue);
    int failed = 0;
    for (int64_t k = 0; k < n; k++)
        failed |= deferred->task[k].failed;
    return !failed;
}

/* The top part's nodes and the tasks' nodes numbered as the sequential builder numbers them, into one
 * buffer of `total` nodes (each task's buffer released once copied).  NULL when memory runs out. */
static BvhNode *bvh_stitch(const BvhNode *top, BvhTask *tasks, int64_t total)
{
    BvhNode *out = (BvhNode *)malloc((size_t)total * sizeof(BvhNode));
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
            BvhTask *task = &tasks[top[t].offset];
            int64_t base = nodes - 1;  /* a task's node j >= 1 goes to base + j */
            for (int64_t j = 0; j < task->count; j++) {
                BvhNode record = task->nodes[j];
                if (record.count == 0)
                    record.offset = (int32_t)(base + record.offset);
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
        out[g].offset = (int32_t)l;
        stack[sp++] = top[t].offset + 1, stack[sp++] = l + 1;
        stack[sp++] = top[t].offset, stack[sp++] = l;
    }
    free(stack);
    return out;
}

/* The tree over the n >= 1 items of `src` on up to `threads` threads (the same tree whatever the count):
 * its nodes (root first; *count of them, *depth the deepest level, the root's being 1), to be released with
 * free(), or NULL when memory runs out. */
static BvhNode *bvh_build(const BvhSource *src, int64_t n, int64_t threads, int64_t *count, int64_t *depth)
{
    if (threads > BVH_MAX_THREADS)
        threads = BVH_MAX_THREADS;
    BvhTask root = {0, n, 1, NULL, 0, 0, 0, 0};
    BvhTasks deferred = {NULL, 0, 0};
    int64_t defer = threads > 1 && n >= BVH_PARALLEL_MIN ? n / (8 * threads) : 0;
    BvhNode *result = NULL;
    if (!bvh_build_range(src, &root, defer, &deferred))
        goto done;
    if (deferred.n == 0) {
        BvhNode *fitted = (BvhNode *)realloc(root.nodes, (size_t)root.count * sizeof(BvhNode));
        result = fitted ? fitted : root.nodes;  /* (the buffer without its spare room) */
        root.nodes = NULL;
        *count = root.count;
        *depth = root.deepest;
        goto done;
    }
    if (!bvh_run_tasks(src, &deferred, threads))
        goto done;
    int64_t total = root.count, deepest = root.deepest;
    for (int64_t k = 0; k < deferred.n; k++) {
        total += deferred.task[k].count - 1;
        if (deferred.task[k].deepest > deepest)
            deepest = deferred.task[k].deepest;
    }
    result = bvh_stitch(root.nodes, deferred.task, total);
    *count = total;
    *depth = deepest;
done:
    for (int64_t k = 0; k < deferred.n; k++)
        free(deferred.task[k].nodes);
    free(deferred.task);
    free(root.nodes);
    return result;
}

/* ------------------------------------------------------------------------------------------------------
 * A mesh's triangles: the tree of _build_bvh_numpy */

static double mesh_half_area(const double *lo, const double *hi)
{
    double s[3];
    for (int k = 0; k < 3; k++) {
        double size = hi[k] - lo[k];
        size = size > 0.0 ? size : (size != size ? size : 0.0);  /* np.maximum(size, 0): NaN stays */
        s[k] = isfinite(size) ? size : 0.0;
    }
    return s[0] * s[1] + s[1] * s[2] + s[2] * s[0];
}

static inline int64_t mesh_bucket(double c, double c_lo, double scale, int64_t bins)
{
    int64_t b = (int64_t)((c - c_lo) * scale);
    return b < bins - 1 ? b : bins - 1;
}

/* What a mesh build reads and rearranges: the triangles, the parameters, the leaf order (each subtree
 * rearranges only its own range of it) and a scratch array of the same length (likewise). */
typedef struct {
    const double *vertices;
    const int32_t *tri;
    int64_t leaf_size, bins;
    double pad;
    int32_t *order, *scratch;
} MeshInput;

/* A triangle's box (min and max of its corners, NaN-propagating as np.minimum and np.maximum) and its
 * centroid's coordinate on one axis ((P0 + P1 + P2) / 3 summed in corner order), from the vertices: what
 * TriangleMesh._build_bvh computes for the NumPy builder, without keeping it for every triangle. */
static inline void mesh_tri_box(const MeshInput *in, int64_t t, double *lo, double *hi)
{
    const double *v = in->vertices;
    const int32_t *tri = in->tri + 3 * t;
    const double *p0 = v + 3 * (int64_t)tri[0], *p1 = v + 3 * (int64_t)tri[1], *p2 = v + 3 * (int64_t)tri[2];
    for (int k = 0; k < 3; k++) {
        lo[k] = nan_min2(nan_min2(p0[k], p1[k]), p2[k]);
        hi[k] = nan_max2(nan_max2(p0[k], p1[k]), p2[k]);
    }
}

static inline double mesh_centroid(const MeshInput *in, int64_t t, int k)
{
    const double *v = in->vertices;
    const int32_t *tri = in->tri + 3 * t;
    return ((v[3 * (int64_t)tri[0] + k] + v[3 * (int64_t)tri[1] + k]) + v[3 * (int64_t)tri[2] + k]) / 3.0;
}

/* The box of the triangles at [start, end) (lo, hi) and of their centroids (c_lo, c_hi). */
static void mesh_bounds(const MeshInput *in, int64_t start, int64_t end, double *lo, double *hi, double *c_lo,
                        double *c_hi)
{
    for (int k = 0; k < 3; k++)
        lo[k] = c_lo[k] = INFINITY, hi[k] = c_hi[k] = -INFINITY;
    for (int64_t i = start; i < end; i++) {
        int64_t t = in->order[i];
        double t_lo[3], t_hi[3];
        mesh_tri_box(in, t, t_lo, t_hi);
        for (int k = 0; k < 3; k++) {
            double a = t_lo[k], b = t_hi[k], c = mesh_centroid(in, t, k);
            lo[k] = a < lo[k] ? a : lo[k];
            hi[k] = b > hi[k] ? b : hi[k];
            c_lo[k] = c < c_lo[k] ? c : c_lo[k];
            c_hi[k] = c > c_hi[k] ? c : c_hi[k];
        }
    }
}

/* The cheapest split of [start, end) along `axis` (centroids from c_lo, `scale` bins per unit): the last
 * bucket of its left side. */
static int64_t mesh_best_bucket(const MeshInput *in, int64_t start, int64_t end, int axis, double c_lo, double scale)
{
    int64_t bins = in->bins, size = end - start;
    double box_lo[BVH_MAX_BINS][3], box_hi[BVH_MAX_BINS][3];
    int64_t in_bin[BVH_MAX_BINS] = {0};
    for (int64_t b = 0; b < bins; b++)
        for (int k = 0; k < 3; k++)
            box_lo[b][k] = INFINITY, box_hi[b][k] = -INFINITY;
    for (int64_t i = start; i < end; i++) {
        int64_t t = in->order[i];
        int64_t b = mesh_bucket(mesh_centroid(in, t, axis), c_lo, scale, bins);
        double t_lo[3], t_hi[3];
        mesh_tri_box(in, t, t_lo, t_hi);
        in_bin[b]++;
        for (int k = 0; k < 3; k++) {
            box_lo[b][k] = t_lo[k] < box_lo[b][k] ? t_lo[k] : box_lo[b][k];
            box_hi[b][k] = t_hi[k] > box_hi[b][k] ? t_hi[k] : box_hi[b][k];
        }
    }
    /* Candidate b splits after bucket b: areas of the prefix and suffix boxes. */
    double right_area[BVH_MAX_BINS];
    double acc_lo[3] = {INFINITY, INFINITY, INFINITY}, acc_hi[3] = {-INFINITY, -INFINITY, -INFINITY};
    for (int64_t b = bins - 1; b >= 1; b--) {
        for (int k = 0; k < 3; k++) {
            acc_lo[k] = box_lo[b][k] < acc_lo[k] ? box_lo[b][k] : acc_lo[k];
            acc_hi[k] = box_hi[b][k] > acc_hi[k] ? box_hi[b][k] : acc_hi[k];
        }
        right_area[b - 1] = mesh_half_area(acc_lo, acc_hi);
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
                          : mesh_half_area(acc_lo, acc_hi) * (double)left_count + right_area[b] * (double)right_count;
        if (best < 0 || cost < best_cost) {  /* np.argmin: the first minimum */
            best = b;
            best_cost = cost;
        }
    }
    return best;
}

/* Stable partition of [start, end): the triangles in buckets up to `best` keep their order at the front,
 * the rest follows; returns where the second part starts. */
static int64_t mesh_partition(const MeshInput *in, int64_t start, int64_t end, int axis, double c_lo, double scale,
                              int64_t best)
{
    int32_t *order = in->order, *scratch = in->scratch;
    int64_t kept = start, moved = 0;
    for (int64_t i = start; i < end; i++) {
        int64_t t = order[i];
        if (mesh_bucket(mesh_centroid(in, t, axis), c_lo, scale, in->bins) <= best)
            order[kept++] = (int32_t)t;
        else
            scratch[start + moved++] = (int32_t)t;
    }
    for (int64_t i = 0; i < moved; i++)
        order[kept + i] = scratch[start + i];
    return kept;
}

/* BvhSource.split of a mesh (_build_bvh_numpy's node). */
static int64_t mesh_split(const void *input, int64_t start, int64_t end, BvhNode *record)
{
    const MeshInput *in = (const MeshInput *)input;
    double lo[3], hi[3], c_lo[3], c_hi[3];
    mesh_bounds(in, start, end, lo, hi, c_lo, c_hi);
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
    record->axis = (int8_t)axis;
    double width = c_hi[axis] - c_lo[axis];
    double scale = (double)in->bins / width;
    if (!(width > 0.0) || !isfinite(width) || !isfinite(scale))
        return start + size / 2;  /* all centroids in one place (or spread past a double): halve the range */
    int64_t best = mesh_best_bucket(in, start, end, axis, c_lo[axis], scale);
    int64_t kept = mesh_partition(in, start, end, axis, c_lo[axis], scale, best);
    /* (a split with an empty side would never end: halve instead; the order is then unchanged) */
    return kept == start || kept == end ? start + size / 2 : kept;
}

/* Build over the n triangles tri (3 vertex indices each, checked by the caller) of the vertices, on up to
 * `threads` threads (the same tree whatever the count).  Writes order (n) and, into a buffer it allocates
 * (*nodes_out, to be released with rt_free), the BvhNode records with their boxes grown by `pad` and rounded
 * outward.  Returns the number of nodes, or -1 when memory runs out or the arguments are out of range. */
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
    int32_t *scratch = (int32_t *)malloc((size_t)n * sizeof(int32_t));
    if (!scratch)
        return -1;
    MeshInput in = {vertices, tri, leaf_size, bins, pad, order, scratch};
    BvhSource src = {mesh_split, &in, leaf_size + 1};
    int64_t count = -1, depth = 0;
    *nodes_out = bvh_build(&src, n, threads, &count, &depth);
    free(scratch);
    return *nodes_out ? count : -1;
}

/* ------------------------------------------------------------------------------------------------------
 * A scene's objects: the object hierarchy (core.c's build_tree feeds it) */

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

/* The bin of centre coordinate c in a node whose centres span [lo, lo + extent] along the axis; `scale` is
 * SAH_BINS / extent, divided once per node and axis (a division per object and axis took ~20 cycles in the
 * binning loop), the same number. */
/* box_grow by a box kept in single precision (each bound widened to double exactly: the same numbers). */
static void box_grow_single(double *lo, double *hi, const float *blo, const float *bhi)
{
    for (int i = 0; i < 3; i++) {
        double l = blo[i], h = bhi[i];
        lo[i] = l < lo[i] ? l : lo[i];
        hi[i] = h > hi[i] ? h : hi[i];
    }
}

static inline int64_t sah_bin(double c, double lo, double scale)
{
    int64_t k = (int64_t)((c - lo) * scale);
    return k >= SAH_BINS ? SAH_BINS - 1 : (k < 0 ? 0 : k);
}

/* What an object build reads and rearranges: per position, the object (items), its box's centre (3) and its
 * box (6: lo, hi; NaN-free, lo <= hi; the objects' boxes are single precision, and so kept: half the bytes of
 * doubles to move in every pass over a node).  A node over positions [start, end) permutes only those. */
typedef struct {
    int64_t *items;
    double *centre;
    float *boxes;
} ObjectInput;

/* A split candidate: after bin `split` along `axis` (-1: none), at `cost`. */
typedef struct {
    int axis;
    int64_t split;
    double cost;
} ObjectSplit;

/* The cheapest split of [start, end) by the binned surface-area heuristic along every axis with some spread
 * of centres (clo, chi: the centres' box): the three axes' bins filled in one pass (each box read once). */
static ObjectSplit object_best_split(const ObjectInput *in, int64_t start, int64_t end, const double *clo,
                                     const double *chi)
{
    ObjectSplit best = {-1, -1, INFINITY};
    int64_t count[3][SAH_BINS] = {{0}};
    double blo[3][SAH_BINS][3], bhi[3][SAH_BINS][3];
    double extent[3], scale[3];
    int spread[3];
    for (int k = 0; k < 3; k++) {
        extent[k] = chi[k] - clo[k];
        spread[k] = extent[k] > 0.0;
        scale[k] = spread[k] ? SAH_BINS / extent[k] : 0.0;
        for (int j = 0; j < SAH_BINS; j++)
            box_empty(blo[k][j], bhi[k][j]);
    }
    for (int64_t i = start; i < end; i++) {
        const float *box = in->boxes + 6 * i;
        for (int k = 0; k < 3; k++) {
            if (!spread[k])
                continue;
            int64_t j = sah_bin(in->centre[3 * i + k], clo[k], scale[k]);
            count[k][j]++;
            box_grow_single(blo[k][j], bhi[k][j], box, box + 3);
        }
    }
    for (int k = 0; k < 3; k++) {
        if (!spread[k])
            continue;
        double right_area[SAH_BINS], rlo[3], rhi[3], llo[3], lhi[3];
        int64_t right_count[SAH_BINS], rc = 0, lc = 0;
        box_empty(rlo, rhi);
        for (int j = SAH_BINS - 1; j > 0; j--) {
            box_grow(rlo, rhi, blo[k][j], bhi[k][j]);
            rc += count[k][j];
            right_area[j] = half_area(rlo, rhi);
            right_count[j] = rc;
        }
        box_empty(llo, lhi);
        for (int j = 0; j < SAH_BINS - 1; j++) {
            box_grow(llo, lhi, blo[k][j], bhi[k][j]);
            lc += count[k][j];
            if (lc == 0 || right_count[j + 1] == 0)
                continue;
            double cost = half_area(llo, lhi) * (double)lc + right_area[j + 1] * (double)right_count[j + 1];
            if (cost < best.cost)
                best = (ObjectSplit){k, j, cost};
        }
    }
    return best;
}

/* Nodes of up to this many objects take object_best_split_few. */
#define FEW_OBJECTS 16

/* object_best_split of a node of 2..FEW_OBJECTS objects, the same split at the same cost, without the 3 x 16
 * bins: per axis the objects sorted by bin, a candidate between each two neighbouring bins that hold objects.
 * (The dense sweep's candidates across empty bins repeat the same two sides at the same cost, and the first
 * of them, after the last bin holding objects, is the one it keeps; its fixed cost, the bins emptied and
 * swept twice on every axis, was most of the build's time in the nodes near the leaves, of which there are
 * about as many as objects.) */
static ObjectSplit object_best_split_few(const ObjectInput *in, int64_t start, int64_t end, const double *clo,
                                         const double *chi)
{
    ObjectSplit best = {-1, -1, INFINITY};
    int64_t n = end - start, bin[FEW_OBJECTS], order[FEW_OBJECTS];
    double right_area[FEW_OBJECTS];
    for (int k = 0; k < 3; k++) {
        double extent = chi[k] - clo[k];
        if (!(extent > 0.0))
            continue;
        double scale = SAH_BINS / extent;
        for (int64_t i = 0; i < n; i++) {  /* (insertion sort by bin, stable) */
            int64_t j = sah_bin(in->centre[3 * (start + i) + k], clo[k], scale), p = i;
            for (; p > 0 && bin[p - 1] > j; p--) {
                bin[p] = bin[p - 1];
                order[p] = order[p - 1];
            }
            bin[p] = j;
            order[p] = start + i;
        }
        double rlo[3], rhi[3], llo[3], lhi[3];
        box_empty(rlo, rhi);
        for (int64_t p = n - 1; p > 0; p--) {
            const float *box = in->boxes + 6 * order[p];
            box_grow_single(rlo, rhi, box, box + 3);
            right_area[p] = half_area(rlo, rhi);
        }
        box_empty(llo, lhi);
        for (int64_t p = 0; p < n - 1; p++) {
            const float *box = in->boxes + 6 * order[p];
            box_grow_single(llo, lhi, box, box + 3);
            if (bin[p + 1] == bin[p])
                continue;
            double cost = half_area(llo, lhi) * (double)(p + 1) + right_area[p + 1] * (double)(n - p - 1);
            if (cost < best.cost)
                best = (ObjectSplit){k, bin[p], cost};
        }
    }
    return best;
}

/* Partitions the objects of [start, end) (with their centres and boxes) so that those in bins up to
 * split.split along split.axis come first; returns where the others start. */
static int64_t object_partition(const ObjectInput *in, int64_t start, int64_t end, ObjectSplit split, double lo_axis,
                                double scale)
{
    int64_t *items = in->items;
    double *centre = in->centre;
    float *boxes = in->boxes;
    int axis = split.axis;
    int64_t i = start, j = end - 1;
    while (i <= j) {
        if (sah_bin(centre[3 * i + axis], lo_axis, scale) <= split.split) {
            i++;
            continue;
        }
        int64_t x = items[i]; items[i] = items[j]; items[j] = x;
        for (int k = 0; k < 3; k++) {
            double c = centre[3 * i + k];
            centre[3 * i + k] = centre[3 * j + k];
            centre[3 * j + k] = c;
        }
        for (int k = 0; k < 6; k++) {
            float c = boxes[6 * i + k];
            boxes[6 * i + k] = boxes[6 * j + k];
            boxes[6 * j + k] = c;
        }
        j--;
    }
    return i;
}

/* BvhSource.split of the object hierarchy. */
static int64_t object_split(const void *input, int64_t start, int64_t end, BvhNode *record)
{
    const ObjectInput *in = (const ObjectInput *)input;
    double lo[3], hi[3], clo[3], chi[3];
    box_empty(lo, hi);
    box_empty(clo, chi);
    for (int64_t i = start; i < end; i++) {
        const float *box = in->boxes + 6 * i;
        box_grow_single(lo, hi, box, box + 3);
        box_grow(clo, chi, in->centre + 3 * i, in->centre + 3 * i);
    }
    memset(record, 0, sizeof(*record));
    for (int k = 0; k < 3; k++) {
        record->lo[k] = bvh_single_below(lo[k]);
        record->hi[k] = bvh_single_above(hi[k]);
    }
    int64_t n = end - start;
    record->offset = (int32_t)start;
    record->count = (uint16_t)n;
    record->axis = -1;
    if (n <= LEAF_MIN)
        return -1;
    ObjectSplit split = n <= FEW_OBJECTS ? object_best_split_few(in, start, end, clo, chi)
                                         : object_best_split(in, start, end, clo, chi);
    int64_t middle = start + n / 2;
    if (split.axis >= 0) {
        /* small nodes become leaves when no split beats testing every object */
        double area = half_area(lo, hi);
        if (n <= LEAF_MAX && SAH_TRAVERSAL * area + split.cost >= area * (double)n)
            return -1;
        double extent = chi[split.axis] - clo[split.axis];
        int64_t i = object_partition(in, start, end, split, clo[split.axis], SAH_BINS / extent);
        if (i > start && i < end)
            middle = i;
    } else if (n <= 8) {
        return -1;
    }
    record->axis = (int8_t)(split.axis >= 0 ? split.axis : 0);
    return middle;
}

/* Builds the hierarchy over n >= 1 objects (in->items, in->centre and in->boxes by position, permuted into
 * leaf order) on up to `threads` threads; the tree is the same whatever the count.  Returns the nodes (root
 * first; *count nodes, *depth the deepest level, the root's being 1), or NULL when memory runs out. */
static BvhNode *object_bvh_build(const ObjectInput *in, int64_t n, int64_t threads, int64_t *count, int64_t *depth)
{
    BvhSource src = {object_split, in, 1};
    return bvh_build(&src, n, threads, count, depth);
}

#endif
