/* Textures: the C form of tracer.textures (noise.py, solid.py, mapping.py, images.py and TextureSet.colors).
 *
 * A texture colour multiplies a hit's ambient and diffuse colours.  Solid textures (-1 checkerboard,
 * -2 wood, -3 marble) are evaluated at the hit in the primitive's generic coordinates; image textures
 * (i > 0) map the generic point to the shape's (u, v) and look the picture up bilinearly.
 *
 * The noise permutation and gradients, the pictures and the material parameters (defaults already filled
 * in by flatten.py with tracer.textures.solid.with_defaults) all come from Python, so both backends read
 * the same tables.  Each formula follows the NumPy code operation for operation; where NumPy's own result
 * depends on the machine (its SIMD sin / arcsin / arctan2, its BLAS matrix product for the generic point),
 * the two agree to a few units in the last place, which no 8-bit image shows.
 *
 * Included by core.c after the Scene type and world_unit_normal. */

#ifndef RT_TEXTURE_H
#define RT_TEXTURE_H

/* np.mod for floats (Python's rule: the result takes the divisor's sign; a zero result is +0 for b > 0). */
static inline double np_mod(double a, double b)
{
    double mod = fmod(a, b);
    if (b == 0.0)
        return mod;
    if (mod != 0.0) {  /* NaN included, as NumPy's `if (mod)` */
        if ((b < 0.0) != (mod < 0.0))
            mod += b;
    } else {
        mod = copysign(0.0, b);
    }
    return mod;
}

/* x.astype(np.int64) on x86-64: truncation, and INT64_MIN for NaN and anything out of range (the
 * cvttsd2si result), without C's undefined behaviour. */
static inline int64_t np_to_int64(double x)
{
    if (!(x >= -9223372036854775808.0 && x < 9223372036854775808.0))
        return INT64_MIN;
    return (int64_t)x;
}

/* Python's a % n for n > 0 (NumPy's integer remainder): in [0, n). */
static inline int64_t py_mod_i64(int64_t a, int64_t n)
{
    int64_t r = a % n;
    return r < 0 ? r + n : r;
}

/* ------------------------------------------------------------------------------------------------------
 * Gradient noise (tracer.textures.noise) */

static inline double noise_fade(double t) { return t * t * t * (t * (t * 6.0 - 15.0) + 10.0); }

/* perm: 512 entries (the permutation twice); grad: 12 x 3 edge directions. */
static double noise3(const int64_t *perm, const double *grad, const double *p)
{
    double f[3], u[3];
    int64_t cell[3];
    for (int k = 0; k < 3; k++) {
        double c = floor(p[k]);
        f[k] = p[k] - c;
        /* np.mod(cell, 256.0).astype(np.int64); the later "% 256" keeps any index in the table */
        cell[k] = np_to_int64(np_mod(c, 256.0));
        u[k] = noise_fade(f[k]);
    }
    double result = 0.0;
    for (int dx = 0; dx < 2; dx++)
        for (int dy = 0; dy < 2; dy++)
            for (int dz = 0; dz < 2; dz++) {
                int64_t h = perm[py_mod_i64(cell[0] + dx, 256)];
                h = perm[h + py_mod_i64(cell[1] + dy, 256)];
                h = perm[h + py_mod_i64(cell[2] + dz, 256)];
                const double *g = grad + 3 * py_mod_i64(h, 12);
                /* one gradient component is 0, so the order of this sum cannot change its value */
                double dot = g[0] * (f[0] - (double)dx) + g[1] * (f[1] - (double)dy) + g[2] * (f[2] - (double)dz);
                double wx = dx ? u[0] : 1.0 - u[0];
                double wy = dy ? u[1] : 1.0 - u[1];
                double wz = dz ? u[2] : 1.0 - u[2];
                result = result + wx * wy * wz * dot;
            }
    return result;
}

static double turbulence3(const int64_t *perm, const double *grad, const double *p, int64_t octaves)
{
    double total = 0.0, scale = 1.0;
    if (octaves < 1)
        octaves = 1;
    for (int64_t k = 0; k < octaves; k++) {
        double q[3] = {p[0] * scale, p[1] * scale, p[2] * scale};
        total += fabs(noise3(perm, grad, q)) / scale;
        scale *= 2.0;
    }
    return total;
}

/* _mix: a + (b - a) * weight per channel. */
static inline void tex_mix(const double *a, const double *b, double weight, double *out)
{
    for (int c = 0; c < 3; c++)
        out[c] = a[c] + (b[c] - a[c]) * weight;
}

/* ------------------------------------------------------------------------------------------------------
 * Solid textures (tracer.textures.solid); q: parameters with defaults. */

static void tex_checkerboard(const double *q, const double *p, double *out)
{
    double size = q[0];
    /* the int64 sum wraps in NumPy; unsigned arithmetic wraps the same way without undefined behaviour,
     * and its low bit is the parity that NumPy's "cells % 2" gives */
    uint64_t cells = 0;
    for (int k = 0; k < 3; k++)
        cells += (uint64_t)np_to_int64(floor(p[k] / size + 0.5));
    tex_mix(q + 1, q + 4, (double)(cells & 1u), out);
}

static void tex_wood(const int64_t *perm, const double *grad, const double *q, const double *p, double *out)
{
    double spacing = q[0], wobble = q[1];
    double stretched[3] = {p[0] * 2.0, p[1] * 2.0, p[2] * 0.5};
    double radius = hypot(p[0], p[1]) + wobble * noise3(perm, grad, stretched);
    double phase = radius / spacing;
    double ring = phase - floor(phase);
    double dark = clip((ring - 0.65) / 0.35, 0.0, 1.0);
    tex_mix(q + 2, q + 5, dark * dark, out);  /* ** 2 is NumPy's square */
}

static void tex_marble(const int64_t *perm, const double *grad, const double *q, const double *p, double *out)
{
    double stripes = q[0], strength = q[1];
    /* int(min(octaves, MAX_OCTAVES)): truncation (turbulence3 keeps at least 1) */
    int64_t octaves = q[2] >= MAX_OCTAVES ? MAX_OCTAVES : np_to_int64(q[2]);
    double doubled[3] = {p[0] * 2.0, p[1] * 2.0, p[2] * 2.0};
    double wave = sin(stripes * M_PI_VALUE * p[0] + strength * turbulence3(perm, grad, doubled, octaves));
    double vein = pow(1.0 - fabs(wave), 3.0);
    tex_mix(q + 3, q + 6, vein, out);
}

/* ------------------------------------------------------------------------------------------------------
 * Image textures: (u, v) per shape (tracer.textures.mapping) and the bilinear lookup (images.py) */

#define TWO_PI_VALUE (2.0 * M_PI_VALUE)

/* atan2 mapped to [0, 1), the seam at angle 0 (+x) */
static inline double angle01(double y, double x) { return np_mod(atan2(y, x) / TWO_PI_VALUE, 1.0); }

/* Each kind's (u, v) at a generic point hit on `part`, and whether each wraps: the C form of the mappings in
 * tracer/textures/mapping.py, which tracer/shapes.py names for each kind (contract.h's RT_SHAPE_UV). */

static void sphere_uv(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u, int *wrap_v)
{
    (void)part;
    *u = angle01(y, x);
    *v = 0.5 + asin(clip(z, -1.0, 1.0)) / M_PI_VALUE;
    *wrap_u = 1;
    *wrap_v = 0;
}

static void square_uv(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u, int *wrap_v)
{
    (void)z;
    (void)part;
    *u = (x + 1.0) / 2.0;
    *v = (y + 1.0) / 2.0;
    *wrap_u = *wrap_v = 0;
}

static void plane_uv(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u, int *wrap_v)
{
    (void)z;
    (void)part;
    *u = np_mod((x + 1.0) / 2.0, 1.0);
    *v = np_mod((y + 1.0) / 2.0, 1.0);
    *wrap_u = *wrap_v = 1;
}

/* part = 2 * axis + (1 on the + side); each face upright and unmirrored from outside */
static void cube_uv(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u, int *wrap_v)
{
    switch (part) {
    case 0: *u = (z + 1) / 2; *v = (y + 1) / 2; break;
    case 1: *u = (1 - z) / 2; *v = (y + 1) / 2; break;
    case 2: *u = (x + 1) / 2; *v = (z + 1) / 2; break;
    case 3: *u = (x + 1) / 2; *v = (1 - z) / 2; break;
    case 4: *u = (1 - x) / 2; *v = (y + 1) / 2; break;
    case 5: *u = (x + 1) / 2; *v = (y + 1) / 2; break;
    default: *u = 0.0; *v = 0.0; break;
    }
    *wrap_u = *wrap_v = 0;
}

static void torus_uv(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u, int *wrap_v)
{
    (void)part;
    *u = angle01(y, x);
    *v = angle01(z, hypot(x, y) - 1.0);
    *wrap_u = *wrap_v = 1;
}

/* polyhedra, meshes: the direction from the generic centre, as on a globe */
static void direction_uv(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u,
                         int *wrap_v)
{
    (void)part;
    double r = sqrt(x * x + y * y + z * z);  /* np.linalg.norm sums left to right */
    if (!(r >= 1e-300))  /* np.maximum: NaN stays NaN */
        r = r != r ? r : 1e-300;
    *u = angle01(y, x);
    *v = 0.5 + asin(clip(z / r, -1.0, 1.0)) / M_PI_VALUE;
    *wrap_u = 1;
    *wrap_v = 0;
}

/* mapping.wall_and_discs_uv: a wall about z (part 0) by angle and height, its discs as squares; u wraps on
 * all parts.  The tapered cylinders' mapping, and any registered shape's that names it. */
static void wall_and_discs_uv(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u,
                              int *wrap_v)
{
    if (part == 0) {
        *u = angle01(y, x);
        *v = clip(z, 0.0, 1.0);
    } else {
        *u = (x + 1.0) / 2.0;
        *v = (y + 1.0) / 2.0;
    }
    *wrap_u = 1;
    *wrap_v = 0;
}

/* hyperboloid.hyperboloid_uv: the tapered cylinders' mapping with the wall's height -1..1 as 0..1. */
static void hyperboloid_uv(double x, double y, double z, int32_t part, double *u, double *v, int *wrap_u,
                           int *wrap_v)
{
    wall_and_discs_uv(x, y, (z + 1.0) / 2.0, part, u, v, wrap_u, wrap_v);
}

/* surface_uv for one generic point on a primitive of kind `kind`, hit on `part`. */
static void surface_uv(int kind, const double *p, int32_t part, double *u, double *v, int *wrap_u, int *wrap_v)
{
    double x = p[0], y = p[1], z = p[2];
    switch (kind) {
#define REGISTERED_UV(shape_kind, mapping) case shape_kind: mapping(x, y, z, part, u, v, wrap_u, wrap_v); return;
    RT_SHAPE_UV(REGISTERED_UV)  /* every kind's mapping, as tracer/shapes.py names it */
#undef REGISTERED_UV
    default:  /* (no such kind: rt_create refuses it) */
        *u = *v = 0.0;
        *wrap_u = *wrap_v = 0;
    }
}

/* One axis of sample_bilinear: texel indices i0, i1 and the weight of i1. */
static inline void bilinear_axis(double coord, int64_t size, int wrap, int64_t *i0, int64_t *i1, double *frac)
{
    double x = coord * (double)size - 0.5;  /* in texel-centre units */
    double x0 = floor(x);
    *frac = x - x0;
    int64_t a = np_to_int64(x0);
    /* a + 1 as NumPy's int64 (wrapping at INT64_MAX, which an in-range floor never reaches) */
    int64_t b = (int64_t)((uint64_t)a + 1u);
    if (wrap) {
        a = py_mod_i64(a, size);
        b = py_mod_i64(b, size);
    } else {
        a = a < 0 ? 0 : (a > size - 1 ? size - 1 : a);
        b = b < 0 ? 0 : (b > size - 1 ? size - 1 : b);
    }
    *i0 = a;
    *i1 = b;
}

/* image: height x width x 3 bytes, row 0 at the bottom; a texel's value is its byte / 255, as in images.py. */
static void sample_bilinear(const uint8_t *image, int64_t width, int64_t height, double u, double v, int wrap_u,
                            int wrap_v, double *out)
{
    if (!isfinite(u))
        u = 0.0;
    if (!isfinite(v))
        v = 0.0;
    int64_t x0, x1, y0, y1;
    double fx, fy;
    bilinear_axis(u, width, wrap_u, &x0, &x1, &fx);
    bilinear_axis(v, height, wrap_v, &y0, &y1, &fy);
    const uint8_t *a = image + 3 * (y1 * width + x0), *b = image + 3 * (y1 * width + x1);
    const uint8_t *c = image + 3 * (y0 * width + x0), *e = image + 3 * (y0 * width + x1);
    for (int k = 0; k < 3; k++) {
        double top = a[k] / 255.0 * (1 - fx) + b[k] / 255.0 * fx;
        double bottom = c[k] / 255.0 * (1 - fx) + e[k] / 255.0 * fx;
        out[k] = bottom * (1 - fy) + top * fy;
    }
}

/* ------------------------------------------------------------------------------------------------------
 * TextureSet.colors for one hit: the colour at world `point` on primitive `shape` (hit on `part`, at
 * barycentrics `bary` on a mesh, or NULL); 1 where the primitive's material has no texture. */

/* TriangleMesh.texture_uv: a hit's texture coordinates on a mesh that has them (`bary`: its barycentrics);
 * 0 where the mesh has none (or the triangle is not one of it). */
static inline int mesh_uv(const Scene *S, int64_t shape, int32_t part, const double *bary, double *u, double *v)
{
    const SceneDesc *D = &S->d;
    if (!bary || !(D->effects & FX_MESH_UV) || D->prim_kind[shape] != K_MESH)
        return 0;
    const MeshView *m = &S->meshes[D->prim_aux[2 * shape]];
    if (!m->tri_uv || part < 0 || part >= m->n_tris)
        return 0;
    const double *c = m->tri_uv + 6 * (int64_t)part;
    double b1 = bary[0], b2 = bary[1], w0 = 1.0 - b1 - b2;
    *u = (w0 * c[0] + b1 * c[2]) + b2 * c[4];
    *v = (w0 * c[1] + b1 * c[3]) + b2 * c[5];
    return 1;
}

static void texture_color(const Scene *S, int64_t shape, const double *point, int32_t part, const double *bary,
                          double *out)
{
    const SceneDesc *D = &S->d;
    int64_t mat = D->prim_material[shape];
    int32_t texture = D->mat_texture[mat];
    if (texture == 0) {
        out[0] = out[1] = out[2] = 1.0;
        return;
    }
    double generic[3];
    double own[16];
    affine_point(prim_inverse_of(D, shape, own), point, generic);
    const double *q = D->mat_tex_param + TEX_PARAMS * mat;
    switch (texture) {
    case -1: tex_checkerboard(q, generic, out); return;
    case -2: tex_wood(D->noise_perm, D->noise_gradients, q, generic, out); return;
    case -3: tex_marble(D->noise_perm, D->noise_gradients, q, generic, out); return;
    }
    int64_t image = D->mat_tex_image[mat];
    if (texture < 0 || image < 0) {  /* rt_create refuses these; stay harmless */
        out[0] = out[1] = out[2] = 1.0;
        return;
    }
    double u, v;
    int wrap_u, wrap_v;
    if (mesh_uv(S, shape, part, bary, &u, &v))  /* a mesh's own texture coordinates repeat both ways */
        wrap_u = wrap_v = 1;
    else
        surface_uv(D->prim_kind[shape], generic, part, &u, &v, &wrap_u, &wrap_v);
    double repeat_u = q[0], repeat_v = q[1];
    if (!(repeat_u == 1.0 && repeat_v == 1.0)) {  /* tiled: both directions wrap */
        u = u * repeat_u;
        v = v * repeat_v;
        wrap_u = wrap_v = 1;
    }
    const int64_t *info = D->image_info + 2 * image;
    sample_bilinear(D->image_data[image], info[0], info[1], u, v, wrap_u, wrap_v, out);
}

#endif
