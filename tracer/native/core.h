/* The C core of the SDL ray tracer: types shared by its parts and the functions ctypes calls.
 *
 * The scene arrives as a SceneDesc of pointers into flat, contiguous arrays that Python owns (see
 * flatten.py; its layout is generated from tracer/native/contract.py, and rt_struct_layout() reports every
 * field's offset and size so that the loader can compare them with ctypes').  The functions ctypes calls are
 * declared in contract.h, generated from contract.py's FUNCTIONS (ctypes declares them from the same table).
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
 * with the NumPy modules, the SceneDesc and SdlResult layouts and the exported functions' prototypes:
 * generated from tracer/native/contract.py. */
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
    double err;         /* bound on the rounding error of t (tracer.numerics); shapes: their own root's */
    /* From a shape routine to its primitive's error bound (tracer.intersect.hits.HitArrays): with n the
     * gradient of the shape's function G on the surface, G's second derivative along the generic direction
     * (0 for a flat face). */
    double bend;
    /* Shapes: the residual of the computed hit point, |G| to first order (|G| / |n| is its distance from
     * the surface); after the primitive: how far the point may be from the surface in generic units (the
     * shading's world_unit_normal maps it to the world). */
    double offset;
} Hit;

#endif
