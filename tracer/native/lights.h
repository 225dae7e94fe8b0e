/* The physical lights (sphere, spot, sun, area): the C form of tracer.lights and of Tracer._physical_light,
 * _visible_share and _area_light in tracer/trace.py, the same arithmetic in the same order (docs/tracer.md,
 * "Lights").  Included by shade.h, which defines ShadePoint and light_response. */

/* SplitMix64's finaliser (tracer.lights._mix). */
static inline uint64_t light_mix(uint64_t z)
{
    z += 0x9E3779B97F4A7C15ULL;
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ULL;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBULL;
    return z ^ (z >> 31);
}

/* tracer.lights.sample_shifts: the lattice shift of a shaded point for light `l`. */
static inline void light_shift(const double *point, int64_t l, double *xi1, double *xi2)
{
    uint64_t bits[3];
    for (int i = 0; i < 3; i++) {  /* the bits of the coordinates rounded to single precision */
        float single = (float)point[i];
        uint32_t b;
        memcpy(&b, &single, sizeof b);
        bits[i] = b;
    }
    uint64_t h = light_mix(bits[2] ^ ((uint64_t)(l + 1) * 0x9E3779B97F4A7C15ULL));
    h = light_mix(bits[1] ^ h);
    h = light_mix(bits[0] ^ h);
    uint64_t second = light_mix(h);
    *xi1 = (double)(h >> 11) * 0x1p-53;
    *xi2 = (double)(second >> 11) * 0x1p-53;
}

/* tracer.lights.lattice: sample k of n. */
static inline void light_lattice(int64_t k, int64_t n, double xi1, double xi2, double *u, double *v)
{
    *u = ((double)k + xi1) / (double)n;
    double w = (double)k * LIGHT_GOLDEN + xi2;
    *v = w - floor(w);
}

/* tracer.lights.basis: two unit vectors perpendicular to the unit vector s and to each other. */
static inline void light_basis(const double *s, double *t1, double *t2)
{
    double sign = copysign(1.0, s[2]);
    double a = -1.0 / (sign + s[2]);
    double b = s[0] * s[1] * a;
    t1[0] = 1.0 + sign * s[0] * s[0] * a;
    t1[1] = sign * b;
    t1[2] = -sign * s[0];
    t2[0] = b;
    t2[1] = sign + s[1] * s[1] * a;
    t2[2] = -s[1];
}

/* tracer.lights.disk_point: the sample (u, v) on the disk spanned by e1, e2. */
static inline void light_disk(double u, double v, const double *e1, const double *e2, double *out)
{
    double rho = sqrt(u), angle = LIGHT_TWO_PI * v;
    double c = rho * cos(angle), s = rho * sin(angle);
    for (int i = 0; i < 3; i++)
        out[i] = c * e1[i] + s * e2[i];
}

/* tracer.lights.cone_direction. */
static inline void light_cone(double u, double v, const double *axis, const double *t1, const double *t2,
                              double one_minus_cos, double *out)
{
    double w = u * one_minus_cos;
    double sin_theta = sqrt(w * (2.0 - w)), angle = LIGHT_TWO_PI * v;
    double c = sin_theta * cos(angle), s = sin_theta * sin(angle);
    for (int i = 0; i < 3; i++)
        out[i] = (1.0 - w) * axis[i] + c * t1[i] + s * t2[i];
}

/* tracer.lights.spot_factor: Blender's spot cone. */
static inline double spot_factor(double cos_alpha, double cos_half, double blend_width)
{
    double x = cos_alpha - cos_half, smooth = 1.0;
    if (blend_width > 0.0) {
        double t = nan_min(x / blend_width, 1.0);
        smooth = t * t * (3.0 - 2.0 * t);
    }
    return x > 0.0 ? smooth : 0.0;
}

/* Tracer._visible_share: the share of a sphere, spot or sun light's shadow rays from the point that reach
 * it (`s`: the unit vector to its centre, or the sun's). */
static double visible_share(const Scene *S, Work *w, const ShadePoint *p, int64_t l, const double *s)
{
    const SceneDesc *D = &S->d;
    int sun = D->light_kind[l] == LIGHT_SUN;
    int64_t n = D->light_samples[l];
    double extent = D->light_param[4 * l], reach = INFINITY;  /* (the sun's feelers never end) */
    const double *pos = D->light_pos + 3 * l;
    int64_t *cache = l < SHADOW_CACHE ? &w->last_blocker[l] : NULL;
    double towards[3];
    if (extent == 0.0) {  /* a point, or a sun of no angle: one feeler */
        if (sun)
            memcpy(towards, s, sizeof towards);
        else
            reach = feeler_to(p->feeler, pos, towards);
        w->counts[RAY_SHADOW]++;
        return scene_occluded(S, w, p->feeler, towards, reach, cache) ? 0.0 : 1.0;
    }
    double xi1, xi2, t1[3], t2[3], e1[3], e2[3], unblocked = 0.0;
    light_shift(p->point, l, &xi1, &xi2);
    light_basis(s, t1, t2);
    for (int i = 0; i < 3; i++) {
        e1[i] = t1[i] * extent;
        e2[i] = t2[i] * extent;
    }
    for (int64_t k = 0; k < n; k++) {
        double u, v, offset[3], target[3];
        light_lattice(k, n, xi1, xi2, &u, &v);
        if (sun) {
            light_cone(u, v, s, t1, t2, extent, towards);
        } else {
            light_disk(u, v, e1, e2, offset);
            for (int i = 0; i < 3; i++)
                target[i] = pos[i] + offset[i];
            reach = feeler_to(p->feeler, target, towards);
        }
        w->counts[RAY_SHADOW]++;
        if (!scene_occluded(S, w, p->feeler, towards, reach, cache))
            unblocked += 1.0;
    }
    return unblocked / (double)n;
}

/* tracer.lights._area_meets: the distance along the ray (units of d) at which it meets the front of area light
 * `l`, or 0 where it does not (its back, or its plane, is not seen). */
static double area_meets(const SceneDesc *D, int64_t l, const double *o, const double *d)
{
    const double *normal = D->light_frame + 9 * l, *u = normal + 3, *v = normal + 6;
    const double *pos = D->light_pos + 3 * l;
    double facing = dot3(d, normal), to[3] = {pos[0] - o[0], pos[1] - o[1], pos[2] - o[2]};
    double t = dot3(to, normal) / facing, q[3];
    for (int i = 0; i < 3; i++)
        q[i] = o[i] + t * d[i] - pos[i];
    double a = dot3(q, u) / dot3(u, u), b = dot3(q, v) / dot3(v, v);
    int inside = D->light_param[4 * l + 1] != 0.0 ? a * a + b * b <= 1.0 : fabs(a) <= 1.0 && fabs(b) <= 1.0;
    return facing < 0.0 && t > 0.0 && inside ? t : 0.0;
}

/* tracer.lights._sphere_meets: the nearest positive root of |o + t d - centre|^2 = radius^2 (the discriminant
 * as radius^2 |d|^2 - |d x (o - centre)|^2, which keeps its digits for a light far from the ray's origin), or 0
 * where the ray misses the sphere. */
static double sphere_meets(const double *centre, double r2, const double *o, const double *d)
{
    double oc[3] = {o[0] - centre[0], o[1] - centre[1], o[2] - centre[2]}, across[3];
    cross3(d, oc, across);
    double a = dot3(d, d), b = dot3(d, oc), disc = a * r2 - dot3(across, across);
    if (!(disc >= 0.0))
        return 0.0;
    double root = sqrt(disc), t = (-b - root) / a;
    if (!(t > 0.0))
        t = (-b + root) / a;
    return t > 0.0 ? t : 0.0;
}

/* tracer.lights.seen_lights: whether a reflected or refracted ray sees a light with an extent (Cycles' lights
 * are seen by glossy and transmission rays, not by the camera's); then `out` is the radiance of the nearest,
 * in the tracer's units (a colour is what the Lambert sum of a white diffuse surface takes: radiance over pi):
 * - the front of an area light, before t_max: pi times its colour (a white surface under a sky of it would
 *   look like it);
 * - the sphere of a sphere or spot light of radius r > 0, before t_max: colour / r^2 (its colour lights a white
 *   surface facing it at distance x with colour / (x^2 + r^2), irradiance pi colour / (x^2 + r^2), which is
 *   pi L r^2 / (x^2 + r^2) for a sphere (a disk facing the point, as Cycles takes it) of radiance L: L =
 *   colour / r^2, the intensity pi colour over the disk's area pi r^2), a spot's times the spot factor of the
 *   direction from the light to the ray's origin, as its own light is cut (not seen outside its cone);
 * - a sun of angle > 0, where the ray meets nothing else (t_max infinite, no light before) and its direction
 *   lies within angle/2 of the sun's: colour / (2 (1 - cos(angle/2))) (its colour lights a white surface facing
 *   it with colour: irradiance pi colour, spread over the disk's solid angle 2 pi (1 - cos(angle/2))).
 * The lights in their order; a later one is seen where it is strictly nearer.  Where use_switches, a refracted
 * ray (`refracted`) does not see a light with visible_transmission off, a reflected one a light with
 * visible_glossy off. */
static int seen_light(const SceneDesc *D, const double *o, const double *d, double t_max, int use_switches,
                      int refracted, double *out)
{
    int seen = 0;
    int32_t unseen = refracted ? LIGHT_OFF_VISIBLE_TRANSMISSION : LIGHT_OFF_VISIBLE_GLOSSY;
    for (int64_t l = 0; l < D->n_lights; l++) {
        int32_t kind = D->light_kind[l];
        const double *param = D->light_param + 4 * l, *lc = D->light_color + 3 * l;
        if (kind == LIGHT_POINT || (use_switches && (D->light_off[l] & unseen)))
            continue;
        if (kind == LIGHT_AREA) {
            double t = area_meets(D, l, o, d);
            if (t > 0.0 && t < t_max) {
                t_max = t;
                seen = 1;
                for (int c = 0; c < 3; c++)
                    out[c] = M_PI_VALUE * lc[c];
            }
        } else if (kind == LIGHT_SUN) {
            if (!(param[0] > 0.0) || seen || t_max != INFINITY)
                continue;
            double cos_alpha = -dot3(d, D->light_frame + 9 * l) / sqrt(dot3(d, d));
            if (1.0 - cos_alpha <= param[0]) {
                seen = 1;  /* (t_max stays infinite: a light met at any distance is in front of the sun) */
                for (int c = 0; c < 3; c++)
                    out[c] = lc[c] / (2.0 * param[0]);
            }
        } else {  /* a sphere or spot light */
            const double *pos = D->light_pos + 3 * l;
            double r2 = param[0] * param[0], t = r2 > 0.0 ? sphere_meets(pos, r2, o, d) : 0.0, factor = 1.0;
            if (!(t > 0.0 && t < t_max))
                continue;
            if (kind == LIGHT_SPOT) {
                double to[3] = {pos[0] - o[0], pos[1] - o[1], pos[2] - o[2]};
                double length = sqrt(dot3(to, to)), s[3] = {to[0] / length, to[1] / length, to[2] / length};
                factor = spot_factor(-dot3(s, D->light_frame + 9 * l), param[1], param[2]);
                if (!(factor > 0.0))
                    continue;
            }
            t_max = t;
            seen = 1;
            for (int c = 0; c < 3; c++)
                out[c] = lc[c] / r2 * factor;
        }
    }
    return seen;
}

/* Tracer._area_light: the sum over the light's stratified sample points. */
static void area_light(const Scene *S, Work *w, const ShadePoint *p, int64_t l, int use_shadows,
                       int use_cook_torrance, int32_t off, double *total)
{
    const SceneDesc *D = &S->d;
    if (use_shadows && skip_feeler(S, w, p->mat, p->inside_of, l, use_cook_torrance, off))
        return;
    const double *frame = D->light_frame + 9 * l, *param = D->light_param + 4 * l;
    const double *pos = D->light_pos + 3 * l, *lc = D->light_color + 3 * l;
    int64_t n = D->light_samples[l];
    int64_t *cache = l < SHADOW_CACHE ? &w->last_blocker[l] : NULL;
    double xi1, xi2, share = param[0] / (double)n;
    light_shift(p->point, l, &xi1, &xi2);
    for (int64_t k = 0; k < n; k++) {
        double u, v, offset[3], sample[3], to[3], s[3];
        light_lattice(k, n, xi1, xi2, &u, &v);
        if (param[1] != 0.0) {
            light_disk(u, v, frame + 3, frame + 6, offset);
        } else {
            double a = 2.0 * u - 1.0, b = 2.0 * v - 1.0;
            for (int i = 0; i < 3; i++)
                offset[i] = a * frame[3 + i] + b * frame[6 + i];
        }
        for (int i = 0; i < 3; i++) {
            sample[i] = pos[i] + offset[i];
            to[i] = sample[i] - p->point[i];
        }
        double distance2 = dot3(to, to), length = sqrt(distance2);
        for (int i = 0; i < 3; i++)
            s[i] = to[i] / length;
        double lambert = dot3(s, p->facing), cos_light = -dot3(s, frame);
        if (!(lambert > 0.0 && cos_light > 0.0))
            continue;
        if (use_shadows) {
            double towards[3], reach = feeler_to(p->feeler, sample, towards);
            w->counts[RAY_SHADOW]++;
            if (scene_occluded(S, w, p->feeler, towards, reach, cache))
                continue;
        }
        double response[3], weight = cos_light * share / distance2;
        light_response(D, p, s, lambert, use_cook_torrance, off, response);
        for (int c = 0; c < 3; c++)
            total[c] += response[c] * lc[c] * weight;
    }
}

/* Tracer._physical_light: light `l` (a sphere, spot, sun or area light) added to `total`; `off`: its switches
 * that are off (use_shadows already says whether it casts shadows). */
static void physical_light(const Scene *S, Work *w, const ShadePoint *p, int64_t l, int use_shadows,
                           int use_cook_torrance, int32_t off, double *total)
{
    const SceneDesc *D = &S->d;
    int32_t kind = D->light_kind[l];
    if (kind == LIGHT_AREA) {
        area_light(S, w, p, l, use_shadows, use_cook_torrance, off, total);
        return;
    }
    const double *frame = D->light_frame + 9 * l, *lc = D->light_color + 3 * l;
    double s[3], scale = 1.0, falloff = 1.0;
    if (kind == LIGHT_SUN) {
        for (int i = 0; i < 3; i++)
            s[i] = -frame[i];
    } else {
        const double *pos = D->light_pos + 3 * l;
        double to[3] = {pos[0] - p->point[0], pos[1] - p->point[1], pos[2] - p->point[2]};
        double distance2 = dot3(to, to), length = sqrt(distance2), radius = D->light_param[4 * l];
        for (int i = 0; i < 3; i++)
            s[i] = to[i] / length;
        falloff = distance2 + radius * radius;  /* (Cycles': a disk of the radius facing the point) */
        scale = 1.0 / falloff;
    }
    double lambert = dot3(s, p->facing);
    if (!(lambert > 0.0))
        return;
    if (kind == LIGHT_SPOT) {
        const double *param = D->light_param + 4 * l;
        double factor = spot_factor(-dot3(s, frame), param[1], param[2]);
        if (!(factor > 0.0))
            return;
        scale = factor / falloff;
    }
    double visible = 1.0;
    if (use_shadows) {
        if (skip_feeler(S, w, p->mat, p->inside_of, l, use_cook_torrance, off))
            return;
        visible = visible_share(S, w, p, l, s);
    }
    if (!(visible > 0.0))
        return;
    double response[3], weight = scale * visible;
    light_response(D, p, s, lambert, use_cook_torrance, off, response);
    for (int c = 0; c < 3; c++)
        total[c] += response[c] * lc[c] * weight;
}
