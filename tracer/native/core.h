/* The C core of the SDL ray tracer: types shared by its parts and the functions ctypes calls.
 *
 * The scene arrives as a SceneDesc of pointers into flat, contiguous arrays that Python owns (see
 * flatten.py; its layout is generated from tracer/native/contract.py, and rt_desc_layout() reports every
 * field's offset and size so that the loader can compare them with ctypes').
 * Everything here reproduces the NumPy reference (tracer/compile.py, the tracer/intersect modules,
 * tracer/trace.py) operation for operation where the order of floating-point operations can matter.
 *
 * Conventions:
 *  - 4x4 matrices are row-major, column-vector convention (world = M generic); a primitive stores the
 *    inverse of its matrix, which maps world points to generic ones and, transposed, generic normals to
 *    world normals (n_world = n_generic @ inverse[:3, :3]).
 *  - An object reference ("ref") is a primitive index when >= 0 and CSG node -ref - 1 when < 0.
 *  - Hit lists hold only finite hits, sorted by t; normals in a Hit are in the generic coordinates of
 *    the primitive that was hit (its index is `shape`) and are carried to the world only when needed.
 */
#ifndef RT_CORE_H
#define RT_CORE_H

#include <stdint.h>

/* The shape kinds (K_*), CSG operations (OP_*), effect bits (FX_*), ray kinds (RAY_*), the constants shared
 * with the NumPy modules and the SceneDesc layout: generated from tracer/native/contract.py. */
#include "contract.h"

/* One crossing of a line with a surface. */
typedef struct {
    double t;
    double n[3];        /* outward normal in the generic coordinates of primitive `shape` (not unit) */
    double uv[2];
    int32_t part;
    int32_t shape;
    int32_t entering;
    int32_t pad;
    double err;         /* bound on the rounding error of t (tracer.numerics) */
} Hit;

int64_t rt_desc_size(void);
int64_t rt_desc_layout(int64_t *offsets, int64_t *sizes, int64_t capacity);
const char *rt_contract_digest(void);
/* NULL when the description is refused; then `error` (capacity bytes, may be NULL) says what was refused. */
void *rt_create(const SceneDesc *desc, char *error, int64_t capacity);
void *rt_create_threaded(const SceneDesc *desc, int64_t threads, char *error, int64_t capacity);
int64_t rt_object_tree(const void *scene, void *pairs, int64_t *items, int64_t *root);
void rt_destroy(void *scene);
int rt_edit(void *scene, const SceneDesc *desc, const int64_t *objects, int64_t n, int64_t flags, int64_t threads,
            char *error, int64_t capacity);
int rt_set_sealed(void *scene, const uint8_t *sealed, int64_t count);
int rt_trace(void *scene, int64_t n, const double *origins, const double *directions, double *colors,
             int64_t *counts, int64_t threads, double cutoff, int64_t savings, int64_t ray_budget,
             const int32_t *cancel);
int rt_first_hits(void *scene, int64_t n, const double *origins, const double *directions, double *t,
                  double *normal, int32_t *shape, int32_t *object, int8_t *entering, int64_t threads);
int rt_occluded(void *scene, int64_t n, const double *origins, const double *directions, double t_max,
                int8_t *blocked, int64_t threads);
int64_t rt_object_hits(void *scene, int64_t object, const double *origin, const double *direction,
                       int64_t capacity, double *t, int8_t *entering, double *normal, int32_t *shape,
                       int32_t *part, double *uv, int8_t *inside_at_start);
int rt_texture_colors(void *scene, int64_t n, const int32_t *shape, const double *points, const int32_t *part,
                      const double *bary, double *out);

#endif
