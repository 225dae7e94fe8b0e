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
#include <stdint.h>
#include <stdlib.h>
#include <string.h>

#include "mesh.h"

#define BVH_MAX_BINS 64

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

/* Build over the n triangles tri (3 vertex indices each, checked by the caller) of the vertices.  Writes
 * order (n) and, into a buffer it allocates (*nodes_out, to be released with rt_free), the MeshNode records
 * with their boxes grown by `pad` and rounded outward.  Returns the number of nodes, or -1 when memory runs
 * out or the arguments are out of range. */
int64_t rt_build_mesh_bvh(int64_t n, const double *vertices, const int32_t *tri, int64_t leaf_size, int64_t bins,
                          double pad, int32_t *order, MeshNode **nodes_out)
{
    *nodes_out = NULL;
    if (n < 0 || n > INT32_MAX || leaf_size < 1 || leaf_size > UINT16_MAX || bins < 2 || bins > BVH_MAX_BINS)
        return -1;
    for (int64_t i = 0; i < n; i++)
        order[i] = (int32_t)i;
    if (n == 0)
        return 0;
    MeshNode *out = NULL;
    int64_t capacity = 0, stack_capacity = 3 * 64;
    int32_t *scratch = (int32_t *)malloc((size_t)n * sizeof(int32_t));
    int64_t *stack = (int64_t *)malloc((size_t)stack_capacity * sizeof(int64_t));
    if (!scratch || !stack || !bvh_reserve(&out, &capacity, 2 * (n / (leaf_size + 1)) + 1)) {
        free(scratch);
        free(stack);
        free(out);
        return -1;
    }
    int64_t nodes = 1, top = 0;
    memset(&out[0], 0, sizeof(MeshNode));
    stack[top++] = 0, stack[top++] = 0, stack[top++] = n;
    while (top) {
        int64_t end = stack[--top], start = stack[--top], node = stack[--top];
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
        MeshNode *record = &out[node];
        for (int k = 0; k < 3; k++) {
            record->lo[k] = bvh_single_below(lo[k] - pad);
            record->hi[k] = bvh_single_above(hi[k] + pad);
        }
        int64_t size = end - start;
        if (size <= leaf_size) {
            record->offset = (int32_t)start;
            record->count = (uint16_t)size;
            record->axis = -1;
            continue;
        }
        int axis = 0;
        for (int k = 1; k < 3; k++)
            if (c_hi[k] - c_lo[k] > c_hi[axis] - c_lo[axis])
                axis = k;
        double width = c_hi[axis] - c_lo[axis];
        double scale = (double)bins / width;
        int64_t middle;
        if (!(width > 0.0) || !isfinite(scale)) {
            middle = start + size / 2;  /* all centroids in one place: halve the range */
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
                    scratch[moved++] = t;
            }
            for (int64_t i = 0; i < moved; i++)
                order[kept + i] = scratch[i];
            middle = kept;
        }
        if (!bvh_reserve(&out, &capacity, nodes + 2) ||
            (top + 6 > stack_capacity && !bvh_grow_stack(&stack, &stack_capacity))) {
            free(scratch);
            free(stack);
            free(out);
            return -1;
        }
        record = &out[node];  /* (the buffer may have moved) */
        int64_t l = nodes++, r = nodes++;
        memset(&out[l], 0, 2 * sizeof(MeshNode));
        record->offset = (int32_t)l;
        record->count = 0;
        record->axis = (int8_t)axis;
        stack[top++] = r, stack[top++] = middle, stack[top++] = end;
        stack[top++] = l, stack[top++] = start, stack[top++] = middle;
    }
    free(scratch);
    free(stack);
    *nodes_out = out;
    return nodes;
}

#endif
