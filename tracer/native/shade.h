/* Whitted shading of one ray: the C form of tracer.trace.Tracer.shade (with cook_torrance, refract and
 * the texture colours of TextureSet.colors, see texture.h; the physical lights in lights.h).
 *
 * shade_body is always inlined into one small function per combination of live effects (see the
 * SHADE_VARIANT list in core.c) with the effect flags as constants, so the choice is made once per batch
 * and dead effects cost nothing per ray; `self` is that function, for the recursion.  The effects of
 * Blender scenes (physical lights, soft shadows) are traced by one more function, shade_general, whose
 * flags are read from the scene at run time.
 * Included by core.c after the scene queries it uses. */

typedef void (*ShadeFn)(const Scene *, Work *, const double *, const double *, int64_t, const Media *, double,
                        double *);

/* A light with both switched off adds nothing to any surface (tracer.lights.OFF_SHADING). */
#define LIGHT_OFF_SHADING (LIGHT_OFF_VISIBLE_DIFFUSE | LIGHT_OFF_VISIBLE_GLOSSY)

/* tracer.savings, the shadow feelers: whether the feeler from a hit on material `mat` towards light `l`
 * need not be cast (counted per reason; the light then adds nothing).  `inside_of`: the object the ray
 * was inside when it hit (it left that object there), or -1; `off`: the light's switches that are off
 * (LIGHT_OFF_*: a material is dark to a light when it takes neither of the terms the light adds). */
static inline int skip_feeler(const Scene *S, Work *w, int64_t mat, int64_t inside_of, int64_t l,
                              const int use_cook_torrance, int32_t off)
{
    const SceneDesc *D = &S->d;
    if (w->savings & SAVE_DARK_MATERIALS) {
        const double *diffuse = D->mat_diffuse + 3 * mat, *specular = D->mat_specular + 3 * mat;
        int no_diffuse = (diffuse[0] == 0.0 && diffuse[1] == 0.0 && diffuse[2] == 0.0) ||
                         (off & LIGHT_OFF_VISIBLE_DIFFUSE);
        int no_glossy = (specular[0] == 0.0 && specular[1] == 0.0 && specular[2] == 0.0 &&
                         (!use_cook_torrance || D->mat_specular_fraction[mat] == 0.0)) ||
                        (off & LIGHT_OFF_VISIBLE_GLOSSY);
        if (no_diffuse && no_glossy) {
            w->counts[SKIP_DARK_MATERIAL]++;
            return 1;
        }
    }
    if ((w->savings & SAVE_INSIDE_SHADOWS) && inside_of >= 0 && S->sealed &&
        S->sealed[inside_of * D->n_lights + l]) {
        w->counts[SKIP_INSIDE_SHADOW]++;
        return 1;
    }
    return 0;
}

/* tracer.savings, the contribution cutoff: whether a secondary ray of this cumulative weight is traced. */
static inline int worth_tracing(Work *w, double weight)
{
    if (weight >= w->cutoff)
        return 1;
    w->counts[SKIP_CUTOFF]++;
    return 0;
}

/* Cook-Torrance specular per unit light colour, times cos(theta_light), for one colour channel set. */
static inline void cook_torrance(const double *normal, const double *to_light, const double *to_eye,
                                 const double *specular, double roughness, double *out)
{
    double half[3] = {to_light[0] + to_eye[0], to_light[1] + to_eye[1], to_light[2] + to_eye[2]};
    double hl = sqrt(half[0] * half[0] + half[1] * half[1] + half[2] * half[2]);
    if (hl < 1e-300)
        hl = 1e-300;
    half[0] /= hl;
    half[1] /= hl;
    half[2] /= hl;
    double n_h = clip(dot3(normal, half), 1e-12, 1.0);
    double n_v = clip(dot3(normal, to_eye), 1e-12, 1.0);
    double n_l = clip(dot3(normal, to_light), 0.0, 1.0);
    double v_h = clip(dot3(to_eye, half), 1e-12, 1.0);
    double m = roughness < 1e-6 ? 1e-6 : roughness;
    double m2 = m * m;
    double cos2 = n_h * n_h;
    double distribution = exp((cos2 - 1.0) / (cos2 * m2)) / (M_PI_VALUE * m2 * cos2 * cos2);
    double a = 2.0 * n_h * n_v / v_h, b = 2.0 * n_h * n_l / v_h;
    double shadowing = fmin_np(1.0, fmin_np(a, b));
    double common = distribution * shadowing / (4.0 * n_v);
    double lit = n_l > 0.0 ? 1.0 : 0.0;
    double schlick = pow(1.0 - v_h, 5.0);
    for (int c = 0; c < 3; c++)
        out[c] = (specular[c] + (1.0 - specular[c]) * schlick) * common * lit;
}

/* A shaded point as the lights see it (tracer.trace.Shading). */
typedef struct {
    double point[3], facing[3], to_eye[3], feeler[3];
    const double *diffuse;  /* textured */
    int64_t mat, inside_of; /* inside_of: the object the ray was inside (tracer.savings), or -1 */
} ShadePoint;

/* Tracer._response: what the surface sends to the eye per unit light colour from unit direction s
 * (lambert = s . facing > 0): Lambert's term and Blinn's highlight, mixed with Cook-Torrance's where live,
 * each only where the light's switches `off` (LIGHT_OFF_*) leave it on. */
static inline __attribute__((always_inline)) void
light_response(const SceneDesc *D, const ShadePoint *p, const double *s, double lambert, const int use_cook_torrance,
               int32_t off, double *out)
{
    int64_t mat = p->mat;
    if (off & LIGHT_OFF_VISIBLE_GLOSSY) {
        for (int c = 0; c < 3; c++)
            out[c] = lambert * p->diffuse[c];
        return;
    }
    const double *specular = D->mat_specular + 3 * mat;
    double half[3] = {s[0] + p->to_eye[0], s[1] + p->to_eye[1], s[2] + p->to_eye[2]};
    double hl = sqrt(half[0] * half[0] + half[1] * half[1] + half[2] * half[2]);
    if (hl < 1e-300)  /* np.maximum(|half|, 1e-300) */
        hl = 1e-300;
    half[0] /= hl;
    half[1] /= hl;
    half[2] /= hl;
    double hm = dot3(half, p->facing);
    double phong = hm > 0.0 ? pow(hm, D->mat_exponent[mat]) : 0.0;
    double spec[3];
    for (int c = 0; c < 3; c++)
        spec[c] = phong * specular[c];
    if (use_cook_torrance) {
        double fraction = D->mat_specular_fraction[mat], rough[3];
        cook_torrance(p->facing, s, p->to_eye, specular, D->mat_roughness[mat], rough);
        for (int c = 0; c < 3; c++)
            spec[c] = (1.0 - fraction) * spec[c] + fraction * rough[c];
    }
    for (int c = 0; c < 3; c++)
        out[c] = (off & LIGHT_OFF_VISIBLE_DIFFUSE) ? spec[c] : lambert * p->diffuse[c] + spec[c];
}

#include "lights.h"

/* tracer.terminator.lifted_points for one hit: where its feelers start before the rounding offset (the hit
 * point, lifted onto the smooth surface on a smooth mesh triangle hit from its outer side). */
static inline void feeler_base(const Scene *S, const Hit *h, const double *point, double *base)
{
    const SceneDesc *D = &S->d;
    double lift[3], world[3];
    memcpy(base, point, 3 * sizeof(double));
    if (D->prim_kind[h->shape] != K_MESH || !h->entering ||
        !mesh_smooth_lift(&S->meshes[D->prim_aux[2 * h->shape]], h->part, h->uv[0], h->uv[1], lift))
        return;
    double own[16];
    generic_to_world_vector(prim_inverse_of(D, h->shape, own), lift, world);
    for (int i = 0; i < 3; i++)
        base[i] = point[i] + world[i];
}

/* Tracer._direct_light: every light's share at the point, added to `color`.  SDL's point lights here, the
 * physical ones (only where use_physical) in lights.h; the lights' switches read only where use_switches. */
static inline __attribute__((always_inline)) void
direct_light(const Scene *S, Work *w, const ShadePoint *p, const int use_shadows, const int use_cook_torrance,
             const int use_physical, const int use_switches, double *color)
{
    const SceneDesc *D = &S->d;
    double total[3] = {0.0, 0.0, 0.0};
    for (int64_t l = 0; l < D->n_lights; l++) {
        int32_t off = use_switches ? D->light_off[l] : 0;
        if ((off & LIGHT_OFF_SHADING) == LIGHT_OFF_SHADING)  /* (it adds nothing to any surface) */
            continue;
        int shadows = use_shadows && !(off & LIGHT_OFF_CAST_SHADOW);
        if (use_physical && D->light_kind[l] != LIGHT_POINT) {
            physical_light(S, w, p, l, shadows, use_cook_torrance, off, total);
            continue;
        }
        const double *lp = D->light_pos + 3 * l, *lc = D->light_color + 3 * l;
        double s[3] = {lp[0] - p->point[0], lp[1] - p->point[1], lp[2] - p->point[2]};
        double sl = norm3(s);  /* (a light at 1e300: |s|^2 overflows) */
        s[0] /= sl;
        s[1] /= sl;
        s[2] /= sl;
        double lambert = dot3(s, p->facing);
        if (!(lambert > 0.0))  /* a light behind the surface does not reach it */
            continue;
        if (shadows) {
            if (skip_feeler(S, w, p->mat, p->inside_of, l, use_cook_torrance, off))
                continue;
            w->counts[RAY_SHADOW]++;
            double to_light[3];
            double reach = feeler_to_known(p->feeler, lp, sl, to_light);
            if (scene_occluded(S, w, p->feeler, to_light, reach, l < SHADOW_CACHE ? &w->last_blocker[l] : NULL))
                continue;
        }
        double response[3];
        light_response(D, p, s, lambert, use_cook_torrance, off, response);
        for (int c = 0; c < 3; c++)
            total[c] += response[c] * lc[c];
    }
    for (int c = 0; c < 3; c++)
        color[c] += total[c];
}

/* tracer.terminator.geometric_normals for one hit: the unit world normal g of the true surface, facing the
 * ray d (the plane of the smooth mesh triangle hit); returns 0 and g = facing for every other hit (analytic
 * shapes, flat triangles: their shading normal is the geometric one). */
static inline int geometric_normal(const Scene *S, const Hit *h, const double *d, const double *facing, double *g)
{
    const SceneDesc *D = &S->d;
    double c[3][3], generic[3], world[3];
    memcpy(g, facing, 3 * sizeof(double));
    if (D->prim_kind[h->shape] != K_MESH ||
        !mesh_geometric_normal(&S->meshes[D->prim_aux[2 * h->shape]], h->part, c, generic))
        return 0;
    double own[16];
    normal_to_world(prim_inverse_of(D, h->shape, own), generic, world);
    double length = norm3(world);
    if (!(length > 0.0))
        return 0;
    for (int i = 0; i < 3; i++)
        world[i] /= length;
    double side = dot3(world, d) > 0.0 ? -1.0 : 1.0;
    for (int i = 0; i < 3; i++)
        g[i] = side * world[i];
    return 1;
}

#define MIN_RISE 1e-3 /* tracer.terminator.MIN_RISE */

/* tracer.terminator.bent_above for one ray: r, if it rises less than MIN_RISE |r| above the plane of unit
 * normal g, moved to rise exactly that much (its part along the plane kept), at its own length. */
static inline void bend_above(double *r, const double *g)
{
    double rise = dot3(r, g), length = norm3(r), moved[3];
    if (!(rise < MIN_RISE * length))
        return;
    for (int i = 0; i < 3; i++)
        moved[i] = (r[i] - rise * g[i]) + (MIN_RISE * length) * g[i];
    double scale = length / norm3(moved);
    for (int i = 0; i < 3; i++)
        r[i] = moved[i] * scale;
}

/* The mirror ray of d about the facing normal, and where it starts: off the surface on the ray's side, along
 * the geometric normal geo (which is `facing` except on smooth mesh triangles, where the ray is also bent to
 * leave above the triangle's plane: about the interpolated normal it can point into the mesh). */
static inline void mirror_ray(const double *d, const double *facing, const double *geo, int smooth,
                              const double *point, double offset, double *mirror, double *start)
{
    double dn = 2.0 * dot3(d, facing);
    for (int i = 0; i < 3; i++) {
        mirror[i] = d[i] - dn * facing[i];
        start[i] = point[i] + offset * geo[i];
    }
    if (smooth)
        bend_above(mirror, geo);
}

/* Tracer._fresnel_weights for one hit (tracer.fresnel): the mirror ray's weight per channel and the
 * transmitted ray's, for a material whose fresnel mode is metal or dielectric. */
static void fresnel_weights(const SceneDesc *D, const double *d, const Hit *h, int64_t obj, const double *facing,
                            const Media *media, int64_t mat, double kr, double *kr_color, double *kt)
{
    double length = sqrt(dot3(d, d)), unit[3] = {d[0] / length, d[1] / length, d[2] / length};
    double cos1 = -dot3(unit, facing);
    if (D->mat_fresnel[mat] == FRESNEL_METAL) {
        const double *tint = D->mat_fresnel_tint + 3 * mat;
        double m = 1.0 - cos1, m2 = m * m, m5 = m2 * m2 * m;
        for (int c = 0; c < 3; c++)
            kr_color[c] = kr * (tint[c] + (1.0 - tint[c]) * m5);
        return;
    }
    double c2 = D->mat_speed[mat];
    if (!h->entering) {
        Media around = *media;
        media_leave(&around, obj);
        c2 = media_speed(&around);
    }
    double ratio = c2 / media_speed(media), reflectance = 1.0;
    double cos2_squared = 1.0 - ratio * ratio * (1.0 - cos1 * cos1);
    if (!(cos2_squared < 0.0)) {  /* (past the critical angle everything is reflected) */
        double cos2 = sqrt(nan_max2(cos2_squared, 0.0)), a = ratio * cos1, b = ratio * cos2;
        double rs = (a - cos2) / (a + cos2), rp = (cos1 - b) / (cos1 + b);
        reflectance = 0.5 * (rs * rs + rp * rp);
    }
    for (int c = 0; c < 3; c++)
        kr_color[c] = kr * reflectance;
    *kt = *kt * (1.0 - reflectance);
}

/* The ray budget (tracer.raytree is the NumPy side, the same arithmetic, breadth first): a camera ray's
 * tree traces at most Work.ray_budget reflected and transmitted rays, whatever the depth and the weights (two
 * mirrors of reflectivity 1 facing each other, or glass of reflectivity and transparency 0.95, double the rays
 * at every level, and the cutoff never stops them).  A ray's descendants may bring w->rays_used up to `limit`
 * (w->ray_limit when the ray was shaded).  Of two wanted children, the first (the mirror ray) may give its own
 * descendants a part of what is left after both children's rays in proportion to its weight, but at least a
 * chain as long as the levels left (`chain`); the second child gets everything left after the first's
 * subtree.  A wanted ray over the budget is not traced (counted as SKIP_BUDGET).  Returns whether to trace
 * the ray; if so, it is counted as used and w->ray_limit is set for its descendants. */
static inline int take_ray(Work *w, int64_t limit, int sibling_wanted, double weight, double sibling_weight,
                           int64_t chain)
{
    int64_t left = limit - w->rays_used;
    if (left <= 0) {
        w->counts[SKIP_BUDGET]++;
        return 0;
    }
    int64_t share = left - 1;
    if (sibling_wanted) {
        double ratio = weight / (weight + sibling_weight);
        if (!(ratio >= 0.0 && ratio <= 1.0))  /* (weights of 0 or infinity: an even split) */
            ratio = 0.5;
        int64_t by_weight = (int64_t)floor((double)(left - 2) * ratio);
        int64_t by_depth = left - 2 < chain ? left - 2 : chain;
        share = by_weight > by_depth ? by_weight : by_depth;
    }
    w->rays_used++;
    w->ray_limit = w->rays_used + (share > 0 ? share : 0);
    return 1;
}

/* Tracer._secondary: the reflected and transmitted colours, each times its coefficient, added to `color`. */
static inline __attribute__((always_inline)) void
secondary(const Scene *S, Work *w, const double *d, const Hit *h, int64_t obj, const double *point,
          const double *facing, double offset, int64_t level, const Media *media, double weight, int64_t mat,
          const int use_reflection, const int use_refraction, const int use_fresnel, ShadeFn self, double *color)
{
    const SceneDesc *D = &S->d;
    double kr = D->mat_reflectivity[mat], kt = D->mat_transparency[mat];
    int reflects = use_reflection && kr >= D->min_reflectivity && kr > 0.0;
    int transmits = use_refraction && kt >= D->min_transparency && kt > 0.0;
    if (!reflects && !transmits)
        return;
    double geo[3];  /* the true surface's normal: mirror rays start off it and must not cross it back */
    int smooth = geometric_normal(S, h, d, facing, geo);
    /* the mirror ray's weight per channel and its largest (the Fresnel modes'), and the transmitted ray's */
    double kr_color[3] = {kr, kr, kr}, kr_max = kr;
    if (use_fresnel && (reflects || transmits) && D->mat_fresnel[mat] != FRESNEL_CONSTANT) {
        fresnel_weights(D, d, h, obj, facing, media, mat, kr, kr_color, &kt);
        kr_max = nan_max2(nan_max2(kr_color[0], kr_color[1]), kr_color[2]);
    }
    /* Snell's law first: under total internal reflection the transmitted ray is the mirror ray. */
    Media after;
    double ratio = 1.0, cos1 = 0.0, cos2_squared = 0.0, unit[3] = {0.0, 0.0, 0.0};
    if (transmits) {
        double c1 = media_speed(media), speed = D->mat_speed[mat];
        after = *media;
        if (h->entering)
            media_enter(&after, obj, speed);
        else
            media_leave(&after, obj);
        double c2 = h->entering ? speed : media_speed(&after);
        ratio = c2 / c1;
        double length = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]);
        unit[0] = d[0] / length;
        unit[1] = d[1] / length;
        unit[2] = d[2] / length;
        cos1 = -dot3(unit, facing);
        cos2_squared = 1.0 - ratio * ratio * (1.0 - cos1 * cos1);
    }
    int total_internal = transmits && cos2_squared < 0.0;
    int shared = total_internal && reflects && (w->savings & SAVE_SHARED_TIR);
    double mirrored[3] = {0.0, 0.0, 0.0}, mirror[3], start[3];
    if (shared)
        w->counts[SKIP_SHARED_TIR]++;
    /* Which of the two rays are wanted (the cutoff), decided before either is traced: they share what is left
     * of the ray budget (take_ray). */
    double mirror_weight = weight * (shared ? kr_max + kt : kr_max), through_weight = weight * kt;
    int want_mirror = reflects && worth_tracing(w, mirror_weight);
    int want_through = transmits && !shared && worth_tracing(w, through_weight);
    int64_t limit = w->ray_limit, chain = D->max_depth - level;
    if (want_mirror && take_ray(w, limit, want_through, mirror_weight, through_weight, chain)) {
        mirror_ray(d, facing, geo, smooth, point, offset, mirror, start);
        w->counts[RAY_REFLECTION]++;
        w->refracted = 0;
        self(S, w, start, mirror, level + 1, media, mirror_weight, mirrored);
        w->ray_limit = limit;
    }
    if (reflects)
        for (int i = 0; i < 3; i++)
            color[i] += kr_color[i] * mirrored[i];
    if (!transmits)
        return;
    double c[3] = {0.0, 0.0, 0.0};
    if (shared) {
        c[0] = mirrored[0];
        c[1] = mirrored[1];
        c[2] = mirrored[2];
    } else if (want_through && take_ray(w, limit, 0, through_weight, 0.0, chain)) {
        if (total_internal) {  /* total internal reflection: stays in the medium it came from */
            mirror_ray(d, facing, geo, smooth, point, offset, mirror, start);
            w->counts[RAY_REFLECTION]++;
            w->refracted = 0;
            self(S, w, start, mirror, level + 1, media, through_weight, c);
        } else {
            double along = ratio * cos1 - sqrt(cos2_squared), next[3];
            for (int i = 0; i < 3; i++) {
                next[i] = ratio * unit[i] + along * facing[i];
                start[i] = point[i] - offset * facing[i];
            }
            w->counts[RAY_REFRACTION]++;
            w->refracted = 1;
            self(S, w, start, next, level + 1, &after, through_weight, c);
        }
        w->ray_limit = limit;
    }
    for (int i = 0; i < 3; i++)
        color[i] += kt * c[i];
}

static inline __attribute__((always_inline)) void
shade_body(const Scene *S, Work *w, const double *o, const double *d, int64_t level, const Media *media,
           double weight, double *out,
           const int use_lighting, const int use_shadows, const int use_cook_torrance, const int use_reflection,
           const int use_refraction, const int use_textures, const int use_physical, const int use_fresnel,
           const int use_terminator, const int use_seen_lights, const int use_switches, ShadeFn self)
{
    const SceneDesc *D = &S->d;
    out[0] = D->background[0];
    out[1] = D->background[1];
    out[2] = D->background[2];
    if (stop_requested(w)) {  /* a signal or a cancel: nothing more is traced, the colours are dropped */
        w->stopped = 1;
        return;
    }
    Hit h;
    int64_t obj;
    int found = scene_first(S, w, o, d, &h, &obj);
    /* (w->refracted: set by the caller for this ray, read before this call shades any other) */
    if (use_seen_lights && level > 0 && seen_light(D, o, d, found ? h.t : INFINITY, use_switches, w->refracted, out))
        return;
    if (!found)
        return;
    ShadePoint p;
    for (int i = 0; i < 3; i++)
        p.point[i] = o[i] + h.t * d[i];
    double gap = world_unit_normal(S, &h, p.facing);
    if (dot3(p.facing, d) > 0.0) {  /* shade the side the ray arrives on */
        p.facing[0] = -p.facing[0];
        p.facing[1] = -p.facing[1];
        p.facing[2] = -p.facing[2];
    }
    p.mat = D->prim_material[h.shape];
    p.inside_of = h.entering ? -1 : obj;
    /* secondary rays start off the surface by the bound on the hit point's rounding error */
    double offset = offset_distance(gap, h.t, o, d, D->tol_offset_ulps);
    const double *ambient = D->mat_ambient + 3 * p.mat, *emissive = D->mat_emissive + 3 * p.mat;
    p.diffuse = D->mat_diffuse + 3 * p.mat;
    double textured_ambient[3], textured_diffuse[3];
    if (use_textures) {  /* the texture colour multiplies ambient and diffuse (1 where untextured) */
        double texture[3];
        texture_color(S, h.shape, p.point, h.part, h.uv, texture);
        for (int c = 0; c < 3; c++) {
            textured_ambient[c] = ambient[c] * texture[c];
            textured_diffuse[c] = p.diffuse[c] * texture[c];
        }
        ambient = textured_ambient;
        p.diffuse = textured_diffuse;
    }
    double color[3];
    for (int c = 0; c < 3; c++)
        color[c] = emissive[c] + D->global_ambient[c] * ambient[c];
    if (use_lighting) {
        double length = sqrt(d[0] * d[0] + d[1] * d[1] + d[2] * d[2]), base[3];
        if (use_terminator)
            feeler_base(S, &h, p.point, base);
        else
            memcpy(base, p.point, sizeof base);
        for (int i = 0; i < 3; i++) {
            p.to_eye[i] = -d[i] / length;
            p.feeler[i] = base[i] + offset * p.facing[i];
        }
        direct_light(S, w, &p, use_shadows, use_cook_torrance, use_physical, use_switches, color);
    }
    if ((use_reflection || use_refraction) && level < D->max_depth)
        secondary(S, w, d, &h, obj, p.point, p.facing, offset, level, media, weight, p.mat, use_reflection,
                  use_refraction, use_fresnel, self, color);
    out[0] = color[0];
    out[1] = color[1];
    out[2] = color[2];
}
