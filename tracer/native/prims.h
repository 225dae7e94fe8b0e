/* Where a primitive's numbers are: its inverse matrix, bounding sphere and rounding terms are its row of the
 * primitive tables, or, for an instance row (tracer.instances; SceneDesc.instance_rows), computed from its
 * float32 affine and box when a ray reaches it, into the caller's buffer (16, 4 and 4 doubles). */
#ifndef RT_PRIMS_H
#define RT_PRIMS_H

#include "core.h"
#include "numeric.h"

/* p's row of prim_inverse, prim_sphere and prim_rounding, or -1 for an instance row. */
static inline int64_t prim_row(const SceneDesc *D, int64_t p)
{
    return D->instance_rows ? D->prim_slot[p] : p;
}

static inline const double *prim_inverse_of(const SceneDesc *D, int64_t p, double *own)
{
    int64_t r = prim_row(D, p);
    if (r >= 0)
        return D->prim_inverse + 16 * r;
    instance_inverse(D->instance_affine + 12 * p, own);
    return own;
}

static inline const double *prim_sphere_of(const SceneDesc *D, int64_t p, double *own)
{
    int64_t r = prim_row(D, p);
    if (r >= 0)
        return D->prim_sphere + 4 * r;
    instance_sphere(D->instance_box + 6 * p, own);
    return own;
}

/* (`inverse`: what prim_inverse_of gave for p) */
static inline const double *prim_rounding_of(const SceneDesc *D, int64_t p, const double *inverse, double *own)
{
    int64_t r = prim_row(D, p);
    if (r >= 0)
        return D->prim_rounding + 4 * r;
    instance_rounding(inverse, D->instance_affine + 12 * p, D->mesh_generic_size[D->prim_aux[2 * p]], own);
    return own;
}

#endif
