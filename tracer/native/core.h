/* The C core of the SDL ray tracer: types shared by its parts and the functions ctypes calls.
 *
 * The scene arrives as a SceneDesc of pointers into flat, contiguous arrays that Python owns (see
 * flatten.py, which mirrors this struct field for field and checks its size against rt_desc_size()).
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

enum { K_SPHERE = 0, K_CUBE = 1, K_SQUARE = 2, K_PLANE = 3, K_TAPERED = 4, K_TORUS = 5,
       K_POLYHEDRON = 6, K_MESH = 7 };
enum { OP_UNION = 0, OP_INTERSECTION = 1, OP_DIFFERENCE = 2 };
enum { FX_LIGHTING = 1, FX_SHADOWS = 2, FX_REFLECTION = 4, FX_REFRACTION = 8, FX_COOK_TORRANCE = 16,
       FX_TEXTURES = 32 };
enum { RAY_CAMERA = 0, RAY_SHADOW = 1, RAY_REFLECTION = 2, RAY_REFRACTION = 3,
       /* rays not cast, per reason (tracer.savings.SKIP_REASONS; RayCounts' skipped_* fields) */
       SKIP_CUTOFF = 4, SKIP_INSIDE_SHADOW = 5, SKIP_SHARED_TIR = 6, SKIP_DARK_MATERIAL = 7, N_COUNTS = 8 };
/* tracer.savings.RaySavings.flags() */
enum { SAVE_INSIDE_SHADOWS = 1, SAVE_SHARED_TIR = 2, SAVE_DARK_MATERIALS = 4 };

/* Keep in step with flatten.py's _SceneDesc (same order, same types). */
typedef struct {
    /* primitives */
    int64_t n_prims;
    const int32_t *prim_kind;
    const double *prim_inverse;      /* 16 per primitive */
    const double *prim_sphere;       /* 4: bounding-sphere centre, radius (inf: unbounded) */
    const double *prim_param;        /* 1: tapered cylinder's small radius */
    const int64_t *prim_aux;         /* 2: polyhedron (first plane, count) or mesh (mesh index, 0) */
    const int32_t *prim_material;
    /* convex polyhedra: face planes n . p <= offset */
    const double *planes;            /* 4 per plane: normal, offset */
    /* triangle meshes (TriangleMesh arrays, concatenated; indices inside stay mesh-local) */
    int64_t n_meshes;
    const int64_t *mesh_info;        /* 4 per mesh: node base, node count, triangle base, triangle count */
    const double *mesh_extent;
    /* tracer.intersect.mesh constants: ROUNDING_FACTOR, BARYCENTRIC_EPSILON_MAX, PARALLEL_EPSILON,
     * DEDUPE_RELATIVE, DEDUPE_RELATIVE_ADJACENT */
    double mesh_constants[5];
    const double *node_lo;           /* 3 per node */
    const double *node_hi;
    const int64_t *node_left;
    const int64_t *node_right;
    const int64_t *node_first;
    const int64_t *node_count;
    const int8_t *node_axis;
    const int64_t *tri_order;        /* leaf order -> original triangle */
    const double *tri_p0;            /* leaf order, 3 each */
    const double *tri_e1;
    const double *tri_e2;
    const uint8_t *tri_flip;
    const double *tri_edge_scale;
    const double *tri_radius;        /* leaf order: largest vertex norm */
    const double *tri_slack1;        /* leaf order: |e2| + radius */
    const double *tri_slack2;        /* leaf order: |e1| + radius */
    const int64_t *tri_welded;       /* leaf order, 3 each: vertex ids after welding equal positions */
    const double *tri_geometric;     /* original order, 3 each */
    const double *tri_corners;       /* original order, 9 each (three unit corner normals) */
    const uint8_t *tri_has_normals;
    /* CSG */
    int64_t n_csg;
    const int32_t *csg_op;
    const int64_t *csg_left;
    const int64_t *csg_right;
    /* top-level objects */
    int64_t n_objects;
    const int64_t *object_ref;
    const double *object_box;        /* 6: lo, hi (padded); ignored when not bounded */
    const uint8_t *object_bounded;
    /* materials */
    int64_t n_materials;
    const double *mat_ambient;       /* 3 each */
    const double *mat_diffuse;
    const double *mat_specular;
    const double *mat_emissive;
    const double *mat_exponent;      /* 1 each */
    const double *mat_reflectivity;
    const double *mat_transparency;
    const double *mat_speed;
    const double *mat_specular_fraction;
    const double *mat_roughness;
    /* lights */
    int64_t n_lights;
    const double *light_pos;         /* 3 each */
    const double *light_color;
    /* settings */
    double background[3];
    double global_ambient[3];
    double min_reflectivity;
    double min_transparency;
    int64_t max_depth;
    int64_t effects;                 /* FX_* bits */
    /* textures (tracer.textures; see texture.h) */
    const int32_t *mat_texture;      /* per material: 0 none, -1/-2/-3 solid, i > 0 the image makePixmap i */
    const double *mat_tex_param;     /* 9 per material: the texture's parameters, defaults filled in */
    const int64_t *mat_tex_image;    /* per material: index into image_data, -1 for none */
    int64_t n_images;
    const int64_t *image_info;       /* 2 per image: width, height */
    const double *const *image_data; /* per image: height x width x 3 floats in [0, 1], row 0 at the bottom */
    const int64_t *noise_perm;       /* 512: tracer.textures.noise.PERM */
    const double *noise_gradients;   /* 12 x 3: tracer.textures.noise.GRADIENTS */
    /* Tolerances, read from the Python modules when the scene is flattened (so that a measurement can
     * change them): tracer.numerics.RELATIVE_EPSILON and tracer.intersect.torus.NEWTON_STEPS. */
    double relative_epsilon;
    int64_t torus_newton_steps;
} SceneDesc;

/* One crossing of a line with a surface. */
typedef struct {
    double t;
    double n[3];        /* outward normal in the generic coordinates of primitive `shape` (not unit) */
    double uv[2];
    int32_t part;
    int32_t shape;
    int32_t entering;
    int32_t pad;
} Hit;

int64_t rt_desc_size(void);
void *rt_create(const SceneDesc *desc);
void rt_destroy(void *scene);
int rt_set_savings(void *scene, double cutoff, int64_t flags, const uint8_t *sealed);
int rt_trace(void *scene, int64_t n, const double *origins, const double *directions, double *colors,
             int64_t *counts, int64_t threads);
int rt_first_hits(void *scene, int64_t n, const double *origins, const double *directions, double *t,
                  double *normal, int32_t *shape, int32_t *object, int8_t *entering, int64_t threads);
int rt_occluded(void *scene, int64_t n, const double *origins, const double *directions, double t_max,
                int8_t *blocked, int64_t threads);
int64_t rt_object_hits(void *scene, int64_t object, const double *origin, const double *direction,
                       int64_t capacity, double *t, int8_t *entering, double *normal, int32_t *shape,
                       int32_t *part, double *uv, int8_t *inside_at_start);
int rt_texture_colors(void *scene, int64_t n, const int32_t *shape, const double *points, const int32_t *part,
                      double *out);

#endif
