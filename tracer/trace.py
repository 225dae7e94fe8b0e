"""Whitted ray tracing, vectorised over a batch of rays (the NumPy reference path).

The recursion follows the lecture: local Phong shading with shadow feelers, then, while the ray's level
is below maxRecursionDepth, reflected and transmitted rays weighted by reflectivity and transparency.
Each effect runs only if the compiled scene says it is live, and every ray cast is counted.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, fields, replace

import numpy as np

from .batches import batches_of, firsts
from .compile import CompiledScene
from .errors import RenderCancelled
from . import fresnel, lights, numerics, terminator
from .model import MEDIA_DEPTH, traced_depth
from .raytree import MIRROR, THROUGH, RayTrees, Shaded, TooManyRays
from .savings import SKIP_REASONS, RaySavings
from .skippable import light_takers, sealed_table

RAY_KINDS = ("camera", "shadow", "reflection", "refraction")


@dataclass
class RayCounts:
    """Rays cast per kind, and rays not cast per reason (tracer.savings.SKIP_REASONS, same order)."""

    camera: int = 0
    shadow: int = 0
    reflection: int = 0
    refraction: int = 0
    skipped_cutoff: int = 0
    skipped_inside_shadow: int = 0
    skipped_shared_tir: int = 0
    skipped_dark_material: int = 0
    skipped_budget: int = 0

    def as_dict(self) -> dict[str, int]:
        return {k: int(getattr(self, k)) for k in RAY_KINDS}

    def skipped(self) -> dict[str, int]:
        return {reason: int(getattr(self, f"skipped_{reason}")) for reason in SKIP_REASONS}

    def add(self, other: "RayCounts") -> None:
        for f in fields(self):
            setattr(self, f.name, getattr(self, f.name) + getattr(other, f.name))


@dataclass
class SurfaceHits:
    """The first hit of each ray of a batch."""

    hit: np.ndarray  # (N,) bool
    t: np.ndarray
    normal: np.ndarray  # (N, 3) unit world normal, out of the solid
    entering: np.ndarray
    shape: np.ndarray  # primitive index
    obj: np.ndarray  # top-level object index
    part: np.ndarray
    uv: np.ndarray
    error: np.ndarray  # bound on the rounding error of t (tracer.numerics)
    offset: np.ndarray  # how far a secondary ray starts from the hit, before the world rounding


def first_hits(scene: CompiledScene, origins: np.ndarray, directions: np.ndarray,
               t_min: np.ndarray | float = 0.0) -> SurfaceHits:
    """The first hit of each ray: the nearest, unless another hit lies within the error interval of every hit
    found (its t at most the least t + error, the *reach*); then, of those, the hit of the object that comes
    first in the scene, however the two round.  Coplanar faces (a decal on a wall) look the same from any
    position, on both backends (the C core's scene_first); only rays with such a tie are asked again.

    Objects are asked one by one, in scene order, each only for hits up to the reach so far (a hit beyond it
    changes neither the nearest nor whether there is a tie), and many primitives of one kind at once
    (tracer.batches), which gives the same hits: neither the least t nor whether another lies within reach of it
    depends on the order, and a tie goes to the first object in the scene."""
    n = origins.shape[0]
    t_min = np.broadcast_to(np.asarray(t_min, dtype=float), (n,))
    best = SurfaceHits(hit=np.zeros(n, bool), t=np.full(n, np.inf), normal=np.zeros((n, 3)),
                       entering=np.zeros(n, bool), shape=np.full(n, -1), obj=np.full(n, -1),
                       part=np.full(n, -1), uv=np.zeros((n, 2)), error=np.zeros(n), offset=np.zeros(n))
    nearest = _Nearest(best, np.full(n, np.inf), np.full(n, np.inf))
    batches, alone = batches_of(scene.objects, scene.table)
    every_ray = np.arange(n)
    for index in alone.tolist():
        h = scene.objects[index].first_hit(origins, directions, t_min, np.nextafter(nearest.reach, np.inf))
        nearest.offer(every_ray, index, h)
    for batch in batches:
        for rays, objects, h in batch.first_hits(origins, directions, t_min, np.nextafter(nearest.reach, np.inf),
                                                 every_ray):
            nearest.offer_many(rays, objects, h)
    tie = np.nonzero((best.obj >= 0) & (nearest.second <= nearest.reach))[0]
    if tie.size:
        _earliest_in_reach(scene, (batches, alone), best, tie, origins, directions, t_min,
                           np.nextafter(nearest.reach, np.inf))
    best.hit = np.isfinite(best.t)
    length = numerics.norm3(best.normal)[:, None]  # (a shape scaled by 1e-200: |n M^-1|^2 overflows)
    best.normal = np.divide(best.normal, length, out=np.zeros_like(best.normal), where=length > 0)
    return best


@dataclass
class _Nearest:
    """What first_hits has found so far: the best hit of each ray, the least t of the other hits (``second``)
    and the least t + error of all (``reach``)."""

    best: SurfaceHits
    second: np.ndarray
    reach: np.ndarray

    def offer(self, rays: np.ndarray, objects, h) -> None:
        """First hits ``h`` (K = 1) of the objects ``objects`` (one, or one per ray: np.ndim tells) for the rays
        ``rays`` (each at most once)."""
        best = self.best
        t = h.t[:, 0]
        best_t = best.t[rays]
        closer = t < best_t  # (a hit at the same t as the best is a tie: _earliest_in_reach decides it)
        self.second[rays] = np.where(closer, np.minimum(self.second[rays], best_t), np.minimum(self.second[rays], t))
        self.reach[rays] = np.minimum(self.reach[rays], t + h.error[:, 0])
        if closer.any():
            chosen = np.nonzero(closer)[0]
            _take(best, rays[chosen], h, chosen, objects if np.ndim(objects) == 0 else objects[chosen])

    def offer_many(self, rays: np.ndarray, objects: np.ndarray, h) -> None:
        """As offer, with any number of hits per ray: each ray's least (t, object) is offered, the others are
        counted in ``second`` and ``reach``.  (Errors are never NaN: a NaN reach would shut out the objects
        after it, in the order they were asked; np.minimum keeps it, as the C core's nan_min does.)"""
        lead = firsts(rays, objects, h.t[:, 0])
        rest = np.ones(rays.size, dtype=bool)
        rest[lead] = False
        np.minimum.at(self.second, rays[rest], h.t[rest, 0])
        np.minimum.at(self.reach, rays[rest], h.t[rest, 0] + h.error[rest, 0])
        self.offer(rays[lead], objects[lead], h.subset(lead))


def _take(best: SurfaceHits, rows: np.ndarray, h, source: np.ndarray, index) -> None:
    """Rays ``rows`` of ``best`` take the first hits ``source`` of ``h``, those of object ``index`` (one, or one
    per row)."""
    best.t[rows] = h.t[source, 0]
    best.normal[rows] = h.normal[source, 0]
    best.entering[rows] = h.entering[source, 0]
    best.shape[rows] = h.shape[source, 0]
    best.obj[rows] = index
    best.part[rows] = h.part[source, 0]
    best.uv[rows] = h.uv[source, 0]
    best.error[rows] = h.error[source, 0]
    best.offset[rows] = h.offset[source, 0]


def _rows_of(hits: SurfaceHits, rows: np.ndarray) -> SurfaceHits:
    """The hits of the rays ``rows``."""
    return SurfaceHits(**{f.name: getattr(hits, f.name)[rows] for f in fields(SurfaceHits)})


def _earliest_in_reach(scene, grouped, best: SurfaceHits, rows, origins, directions, t_min, limit) -> None:
    """The rays ``rows`` have a tie: the first object in the scene with a hit before ``limit`` wins it.
    ``grouped``: the batches and the objects asked alone (tracer.batches.batches_of)."""
    batches, alone = grouped
    for batch in batches:  # (only objects before each ray's best so far can win: the others are not asked)
        for rays, objects, h in batch.first_hits(origins, directions, t_min, limit, rows, before=best.obj):
            first = firsts(rays, objects)
            first = first[objects[first] < best.obj[rays[first]]]  # (an earlier chunk may have found one)
            _take(best, rays[first], h, first, objects[first])
    for index in alone.tolist():
        rows = rows[index < best.obj[rows]]
        if rows.size == 0:
            break
        h = scene.objects[index].first_hit(origins[rows], directions[rows], t_min[rows], limit[rows])
        found = np.nonzero(np.isfinite(h.t[:, 0]))[0]
        _take(best, rows[found], h, found, index)


def occluded(scene: CompiledScene, origins: np.ndarray, directions: np.ndarray,
             t_max: np.ndarray | float = 1.0) -> np.ndarray:
    """Shadow feelers: is any object on each segment origin + t * direction, 0 < t < t_max, with its whole
    error interval (compile.blocks_between)?"""
    n = origins.shape[0]
    t_max = np.broadcast_to(np.asarray(t_max, dtype=float), (n,))
    blocked = np.zeros(n, dtype=bool)
    batches, alone = batches_of(scene.objects, scene.table)
    for index in alone.tolist():
        open_rays = np.nonzero(~blocked)[0]
        if open_rays.size == 0:
            break
        m = open_rays.size
        blocked[open_rays] = scene.objects[index].occludes(origins[open_rays], directions[open_rays], np.zeros(m),
                                                           t_max[open_rays])
    for batch in batches:
        open_rays = np.nonzero(~blocked)[0]
        if open_rays.size == 0:
            break
        blocked[open_rays] = batch.blocked(origins, directions, t_max, open_rays)
    return blocked


@dataclass
class Shading:
    """The shaded points of a batch, as the lights see them: position, normal facing the ray, unit vector to
    the eye, material, diffuse colour (textured), where shadow feelers start, and the object each ray was
    inside (-1: none; tracer.savings)."""

    point: np.ndarray
    normal: np.ndarray
    to_eye: np.ndarray
    mat: np.ndarray
    diffuse: np.ndarray
    feeler_start: np.ndarray
    inside_of: np.ndarray


@dataclass
class Media:
    """The transparent objects each ray is inside, innermost last (a small stack per ray)."""

    objects: np.ndarray  # (N, MEDIA_DEPTH) int, -1 = empty
    speeds: np.ndarray  # (N, MEDIA_DEPTH)
    depth: np.ndarray  # (N,)

    @classmethod
    def air(cls, n: int) -> "Media":
        return cls(np.full((n, MEDIA_DEPTH), -1), np.ones((n, MEDIA_DEPTH)), np.zeros(n, dtype=int))

    def subset(self, rows) -> "Media":
        return Media(self.objects[rows], self.speeds[rows], self.depth[rows])

    def current_speed(self) -> np.ndarray:
        top = np.maximum(self.depth - 1, 0)
        return np.where(self.depth > 0, self.speeds[np.arange(self.depth.size), top], 1.0)

    def entered(self, obj: np.ndarray, speed: np.ndarray) -> "Media":
        out = Media(self.objects.copy(), self.speeds.copy(), self.depth.copy())
        room = out.depth < MEDIA_DEPTH
        rows = np.nonzero(room)[0]
        out.objects[rows, out.depth[rows]] = obj[rows]
        out.speeds[rows, out.depth[rows]] = speed[rows]
        out.depth[rows] += 1
        return out

    def left(self, obj: np.ndarray) -> "Media":
        """Without the innermost entry for ``obj`` (unchanged where the ray was not known to be inside it)."""
        out = Media(self.objects.copy(), self.speeds.copy(), self.depth.copy())
        cols = np.arange(MEDIA_DEPTH)[None, :]
        match = (out.objects == obj[:, None]) & (cols < out.depth[:, None])
        has = match.any(axis=1)
        last = MEDIA_DEPTH - 1 - np.argmax(match[:, ::-1], axis=1)
        rows = np.nonzero(has)[0]
        for j in range(MEDIA_DEPTH - 1):  # close the gap left by the removed entry
            shift = rows[last[rows] <= j]
            out.objects[shift, j] = out.objects[shift, j + 1]
            out.speeds[shift, j] = out.speeds[shift, j + 1]
        out.objects[rows, MEDIA_DEPTH - 1] = -1
        out.depth[rows] -= 1
        return out


def _dot(a, b):
    # (summed left to right, as the C core sums: where a sign decides, a light in the surface's plane or a
    # grazing ray, einsum's order could decide it otherwise)
    return numerics.dot3(a, b)


def reflect(direction: np.ndarray, normal: np.ndarray) -> np.ndarray:
    """Mirror (N, 3) directions about unit normals: r = d - 2 (d . m) m."""
    return direction - 2.0 * _dot(direction, normal)[:, None] * normal


def cook_torrance(normal, to_light, to_eye, specular, roughness) -> np.ndarray:
    """Cook–Torrance specular light per unit light colour, already multiplied by cos(theta_light).

    Beckmann distribution D with slope ``roughness``, Schlick's Fresnel F with the specular colour as the
    reflectance at normal incidence, the V-cavity shadowing term G, and the microfacet form
    F D G / (4 (m.s)(m.v)) times (m.s).  All arguments are per-row arrays.
    """
    half = to_light + to_eye
    half /= np.maximum(np.linalg.norm(half, axis=1, keepdims=True), 1e-300)
    n_h = np.clip(_dot(normal, half), 1e-12, 1.0)
    n_v = np.clip(_dot(normal, to_eye), 1e-12, 1.0)
    n_l = np.clip(_dot(normal, to_light), 0.0, 1.0)
    v_h = np.clip(_dot(to_eye, half), 1e-12, 1.0)
    m2 = np.maximum(roughness, 1e-6) ** 2
    cos2 = n_h * n_h
    with np.errstate(under="ignore"):
        distribution = np.exp((cos2 - 1.0) / (cos2 * m2)) / (np.pi * m2 * cos2 * cos2)
    shadowing = np.minimum(1.0, np.minimum(2.0 * n_h * n_v / v_h, 2.0 * n_h * n_l / v_h))
    fresnel = specular + (1.0 - specular) * ((1.0 - v_h) ** 5)[:, None]
    return fresnel * (distribution * shadowing / (4.0 * n_v))[:, None] * (n_l > 0)[:, None]


def refract(direction: np.ndarray, normal: np.ndarray, ratio: np.ndarray):
    """Transmitted unit directions by Snell's law with speeds, and where total internal reflection occurs.

    ``normal`` faces the incoming ray (d . m < 0); ``ratio`` = c2 / c1 = sin(theta2) / sin(theta1).
    Returns ``(transmitted, total_internal)``; transmitted rows are NaN where total_internal is True.
    """
    unit = direction / np.linalg.norm(direction, axis=1, keepdims=True)
    cos1 = -_dot(unit, normal)
    cos2_squared = 1.0 - ratio * ratio * (1.0 - cos1 * cos1)
    total_internal = cos2_squared < 0.0
    with np.errstate(invalid="ignore"):
        transmitted = ratio[:, None] * unit + (ratio * cos1 - np.sqrt(cos2_squared))[:, None] * normal
    return transmitted, total_internal


class Tracer:
    """Shades batches of rays for one compiled scene, counting every ray it casts (and every ray that
    ``savings`` lets it skip, see tracer.savings)."""

    def __init__(self, scene: CompiledScene, savings: RaySavings | None = None):
        self.scene = scene
        self.counts = RayCounts()
        self.effects = scene.effects
        self.savings = RaySavings() if savings is None else savings
        table = scene.table  # (each primitive's material id, without making the primitives)
        self.material_of = (np.asarray(table.material_ids, dtype=int) if table is not None and len(table) else
                            np.array([p.material_id for p in scene.primitives] or [0], dtype=int))
        self.background = np.asarray(scene.settings.background, dtype=float)
        self.ambient_light = np.asarray(scene.settings.global_ambient, dtype=float)
        #: Per material: whether it takes a light's diffuse term, and its highlight (tracer.skippable).
        self.takes_diffuse, self.takes_glossy = light_takers(scene)
        #: The lights' switches that are off (LightTable.off), where they count (the effect light-switches).
        off = scene.lights.off
        self.switched_off = off if "light-switches" in self.effects else np.zeros_like(off)
        self.sealed = sealed_table(scene) if self.savings.inside_shadows and "shadows" in self.effects else None
        #: ``cancel() -> bool``, asked now and then while a batch is traced: True stops it (RenderCancelled).
        self.cancel = None
        self._next_cancel_check = 0.0
        self.depth = traced_depth(scene.settings.max_recursion_depth)  # (the deepest level shaded)
        #: The ray trees of the last batch shaded (tracer.raytree; its ``batches`` counts shade_batch calls).
        self.trees: RayTrees | None = None

    def camera_rays(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        n = origins.shape[0]
        self.counts.camera += n
        return self.shade(origins, directions, 0, Media.air(n), np.ones(n))

    def shade(self, origins: np.ndarray, directions: np.ndarray, level: int, media: Media,
              weight: np.ndarray | None = None) -> np.ndarray:
        """Colours of the rays at ``level`` in ``media``, each with the ray tree below it (tracer.raytree: a
        generation of all the trees per batch, and each tree with the ray budget of a camera ray);
        ``weight``: each ray's share of its pixel (for the contribution cutoff; default 1)."""
        n = origins.shape[0]
        weight = np.ones(n) if weight is None else weight
        before = replace(self.counts)
        self.trees = RayTrees(self, level, self.depth, self.savings.ray_budget)
        try:
            return self.trees.trace(origins, directions, media, weight)
        except TooManyRays:  # (trees too large to hold at once: in parts, the same rays and colours)
            pass
        for f in fields(RayCounts):  # (the rays of the attempt are not counted)
            setattr(self.counts, f.name, getattr(before, f.name))
        bounds = np.linspace(0, n, min(n, 4) + 1).astype(int)  # (quarters: a tree of halves wastes more tries)
        return np.concatenate([self.shade(origins[a:b], directions[a:b], level, media.subset(slice(a, b)), weight[a:b])
                               for a, b in zip(bounds[:-1], bounds[1:])])

    def shade_batch(self, origins: np.ndarray, directions: np.ndarray, level, media: Media,
                    weight: np.ndarray, refracted: np.ndarray | None = None) -> Shaded:
        """One batch of ray-tree nodes (``level``: theirs, one for all or one per ray): each ray's own colour
        (the background, or the local shading at its first hit) and, where it hits below the depth limit, the
        children it wants (tracer.raytree traces those and adds their colours).  ``refracted``: which rays are
        transmitted rays (the other rays above level 0 are reflected ones; None: none is)."""
        self._check_cancel()
        out = Shaded.empty(self.background, media)
        if origins.shape[0] == 0:
            return out
        hits = first_hits(self.scene, origins, directions)
        if "seen-lights" in self.effects:  # (a reflected or refracted ray may see a light instead)
            if "light-switches" in self.effects and refracted is None:
                refracted = np.zeros(origins.shape[0], dtype=bool)
            seen, radiance = lights.seen_lights(self.scene.lights, origins, directions, hits.t,
                                                refracted if "light-switches" in self.effects else None)
            seen &= np.broadcast_to(level, origins.shape[:1]) > 0
            out.color[seen] = radiance[seen]
            hits.hit &= ~seen
        idx = np.nonzero(hits.hit)[0]
        if idx.size == 0:
            return out
        o, d = origins[idx], directions[idx]
        t = hits.t[idx]
        point = o + t[:, None] * d
        outward = hits.normal[idx]
        # Shade the side the ray arrives on: the normal faces the incoming ray.
        facing = np.where((_dot(outward, d) > 0.0)[:, None], -outward, outward)
        mats = self.scene.materials
        mat = self.material_of[hits.shape[idx]]
        # Secondary rays start off the surface by the bound on the hit point's rounding error.
        offset = numerics.offset_distance(hits.offset[idx], t, o, d, self.scene.tolerances)[:, None]
        ambient, diffuse = mats.ambient[mat], mats.diffuse[mat]
        if "textures" in self.effects:
            texture = self.scene.textures.colors(hits.shape[idx], point, hits.part[idx], hits.uv[idx])
            ambient, diffuse = ambient * texture, diffuse * texture
        local = mats.emissive[mat] + self.ambient_light * ambient
        if "lighting" in self.effects:
            inside_of = np.where(hits.entering[idx], -1, hits.obj[idx])  # the object the ray was inside
            base = point  # where feelers start, before the rounding offset
            if "smooth-terminator" in self.effects:
                base = terminator.lifted_points(self.scene, hits.shape[idx], hits.part[idx], hits.uv[idx],
                                                hits.entering[idx], point)
            local += self._direct_light(point, facing, d, mat, diffuse, offset, inside_of, base)
        out.color[idx] = local
        if not self.effects & {"reflection", "refraction"}:
            return out
        deep = np.nonzero(np.broadcast_to(level, origins.shape[:1])[idx] < self.depth)[0]  # (hits above the limit)
        if deep.size:
            at = tuple(a[deep] for a in (point, facing, d, mat, offset))
            idx, hits = idx[deep], _rows_of(hits, idx[deep])
            out.secondary[idx] = True
            self._children(out, idx, at, media.subset(idx), hits.entering, hits.obj, weight[idx],
                           (hits.shape, hits.part))
        return out

    def _skip_shadow(self, mat, inside_of, light: int) -> np.ndarray:
        """Rows whose feeler towards ``light`` need not be cast (counted per reason); they get no light.  A
        material is dark to a light when it takes neither of the terms the light adds (its switches)."""
        skip = np.zeros(mat.shape[0], dtype=bool)
        if self.savings.dark_materials:
            off = int(self.switched_off[light])
            skip = ~((self.takes_diffuse[mat] & ((off & lights.OFF_DIFFUSE) == 0))
                     | (self.takes_glossy[mat] & ((off & lights.OFF_GLOSSY) == 0)))
            self.counts.skipped_dark_material += int(skip.sum())
        if self.sealed is not None:
            inside = (inside_of >= 0) & ~skip
            inside[inside] = self.sealed[inside_of[inside], light]
            self.counts.skipped_inside_shadow += int(inside.sum())
            skip = skip | inside
        return skip

    def _direct_light(self, point, normal, direction, mat, diffuse, offset, inside_of, base) -> np.ndarray:
        total = np.zeros_like(point)
        to_eye = -direction / np.linalg.norm(direction, axis=1, keepdims=True)
        feeler_start = base + offset * normal
        kinds = self.scene.lights.kind
        shading = Shading(point, normal, to_eye, mat, diffuse, feeler_start, inside_of)
        for light, (light_pos, light_color) in enumerate(zip(self.scene.light_positions, self.scene.light_colors)):
            off = int(self.switched_off[light])
            if (off & lights.OFF_SHADING) == lights.OFF_SHADING:  # (it adds nothing to any surface)
                continue
            if kinds[light] != lights.POINT:
                self._physical_light(light, shading, total, off)
                continue
            to_light = light_pos - point
            distance = numerics.norm3(to_light)  # (a light at 1e300: |s|^2 overflows)
            s = to_light / distance[:, None]
            lambert = _dot(s, normal)
            # A light behind the surface does not reach it (the surface itself is in the way).
            lit = lambert > 0.0
            if "shadows" in self.effects and not off & lights.OFF_SHADOW and lit.any():
                rows = np.nonzero(lit)[0]
                skip = self._skip_shadow(mat[rows], inside_of[rows], light)
                lit[rows[skip]] = False
                rows = rows[~skip]
                self.counts.shadow += rows.size
                to_light, reach = numerics.feeler_to(feeler_start[rows], light_pos, distance[rows])
                lit[rows] &= ~occluded(self.scene, feeler_start[rows], to_light, reach)
            rows = np.nonzero(lit)[0]
            if rows.size == 0:
                continue
            total[rows] += self._response(lambert[rows], s[rows], normal[rows], to_eye[rows], mat[rows],
                                          diffuse[rows], off) * light_color
        return total

    def _response(self, lambert, s, normal, to_eye, m, diffuse, off: int) -> np.ndarray:
        """What a surface sends to the eye per unit light colour from unit direction ``s`` (rows lit by it,
        ``lambert`` = s . normal > 0): Lambert's diffuse term and Blinn's highlight (mixed with Cook-Torrance's
        where it is live), each only where the light's switches ``off`` (LightTable.off) leave it on."""
        mats = self.scene.materials
        contribution = lambert[:, None] * diffuse
        if off & lights.OFF_GLOSSY:
            return contribution
        half = s + to_eye
        half /= np.maximum(np.linalg.norm(half, axis=1, keepdims=True), 1e-300)
        h_dot_m = _dot(half, normal)
        with np.errstate(under="ignore"):
            phong = np.where(h_dot_m > 0.0, np.power(np.maximum(h_dot_m, 0.0), mats.specular_exponent[m]), 0.0)
        specular = phong[:, None] * mats.specular[m]
        if "cook-torrance" in self.effects:
            fraction = mats.specular_fraction[m][:, None]
            rough = cook_torrance(normal, s, to_eye, mats.specular[m], mats.surface_roughness[m])
            specular = (1.0 - fraction) * specular + fraction * rough
        if off & lights.OFF_DIFFUSE:
            return specular
        return contribution + specular

    # -- the physical lights (tracer.lights; docs/tracer.md, "Lights") -------------------------------------

    def _physical_light(self, light: int, at: "Shading", total: np.ndarray, off: int) -> None:
        """Add light number ``light`` (a sphere, spot, sun or area light) to ``total`` at the shaded points;
        ``off``: its switches that are off (LightTable.off)."""
        table = self.scene.lights
        kind = table.kind[light]
        if kind == lights.AREA:
            return self._area_light(light, at, total, off)
        if kind == lights.SUN:
            s = np.broadcast_to(-table.frame[light, :3], at.point.shape)
            scale = np.ones(len(at.point))
        else:
            to_light = table.position[light] - at.point
            distance2 = numerics.dot3(to_light, to_light)
            s = to_light / np.sqrt(distance2)[:, None]
            radius = table.param[light, 0]
            falloff = distance2 + radius * radius  # (Cycles': a disk of the radius facing the point)
            scale = 1.0 / falloff
        lambert = numerics.dot3(s, at.normal)
        lit = lambert > 0.0
        if kind == lights.SPOT:
            _, cos_half, blend_width, _ = table.param[light]
            factor = lights.spot_factor(-numerics.dot3(s, table.frame[light, :3]), cos_half, blend_width)
            lit &= factor > 0.0
            scale = factor / falloff
        rows = np.nonzero(lit)[0]
        visible = np.ones(rows.size)
        if "shadows" in self.effects and not off & lights.OFF_SHADOW and rows.size:
            skip = self._skip_shadow(at.mat[rows], at.inside_of[rows], light)
            rows = rows[~skip]
            visible = self._visible_share(light, at.point[rows], s[rows], at.feeler_start[rows])
        keep = visible > 0.0
        rows, visible = rows[keep], visible[keep]
        if rows.size == 0:
            return
        response = self._response(lambert[rows], s[rows], at.normal[rows], at.to_eye[rows], at.mat[rows],
                                  at.diffuse[rows], off)
        total[rows] += (response * table.color[light]) * (scale[rows] * visible)[:, None]

    def _visible_share(self, light: int, point, s, feeler_start) -> np.ndarray:
        """The share of a sphere, spot or sun light's shadow rays from each point that reach it (soft shadows:
        its samples over the disk facing the point, or over the sun's cone)."""
        table = self.scene.lights
        kind, n = table.kind[light], int(table.samples[light])
        sun = kind == lights.SUN
        extent = table.param[light, 0]  # the radius; the sun's 1 - cos(angle / 2)
        reach = np.inf  # (the sun's feelers never end)
        if extent == 0.0:  # a point, or a sun of no angle: one feeler
            self.counts.shadow += len(point)
            towards = s
            if not sun:
                towards, reach = numerics.feeler_to(feeler_start, table.position[light])
            return np.where(occluded(self.scene, feeler_start, towards, reach), 0.0, 1.0)
        xi1, xi2 = lights.sample_shifts(point, light)
        t1, t2 = lights.basis(s)
        unblocked = np.zeros(len(point))
        for k in range(n):
            u, v = lights.lattice(k, n, xi1, xi2)
            if sun:
                towards = lights.cone_direction(u, v, s, t1, t2, extent)
            else:
                target = table.position[light] + lights.disk_point(u, v, t1 * extent, t2 * extent)
                towards, reach = numerics.feeler_to(feeler_start, target)
            self.counts.shadow += len(point)
            unblocked += ~occluded(self.scene, feeler_start, towards, reach)
        return unblocked / n

    def _area_light(self, light: int, at: "Shading", total: np.ndarray, off: int) -> None:
        """An area light: the sum over its stratified sample points, each a small light of its share of the
        area, facing along the light's direction (Lambert's cosine at both ends, 1/r^2)."""
        table = self.scene.lights
        n = int(table.samples[light])
        direction, u_side, v_side = table.frame[light, :3], table.frame[light, 3:6], table.frame[light, 6:9]
        area, ellipse = table.param[light, 0], table.param[light, 1] != 0.0
        rows = np.arange(len(at.point))
        shadows = "shadows" in self.effects and not off & lights.OFF_SHADOW
        if shadows:
            rows = rows[~self._skip_shadow(at.mat, at.inside_of, light)]
        point = at.point[rows]
        xi1, xi2 = lights.sample_shifts(point, light)
        share = area / n
        for k in range(n):
            u, v = lights.lattice(k, n, xi1, xi2)
            if ellipse:
                offset = lights.disk_point(u, v, np.broadcast_to(u_side, point.shape),
                                           np.broadcast_to(v_side, point.shape))
            else:
                offset = (2.0 * u - 1.0)[:, None] * u_side + (2.0 * v - 1.0)[:, None] * v_side
            sample = table.position[light] + offset
            to_light = sample - point
            distance2 = numerics.dot3(to_light, to_light)
            s = to_light / np.sqrt(distance2)[:, None]
            lambert = numerics.dot3(s, at.normal[rows])
            cos_light = -numerics.dot3(s, direction)
            lit = np.nonzero((lambert > 0.0) & (cos_light > 0.0))[0]
            if shadows and lit.size:
                self.counts.shadow += lit.size
                start = at.feeler_start[rows[lit]]
                towards, reach = numerics.feeler_to(start, sample[lit])
                lit = lit[~occluded(self.scene, start, towards, reach)]
            if lit.size == 0:
                continue
            r = rows[lit]
            response = self._response(lambert[lit], s[lit], at.normal[r], at.to_eye[r], at.mat[r], at.diffuse[r],
                                      off)
            total[r] += (response * table.color[light]) * (cos_light[lit] * share / distance2[lit])[:, None]

    def _check_cancel(self) -> None:
        """RenderCancelled if ``self.cancel`` says stop (asked at most every 50 ms: it may be slow)."""
        if self.cancel is None:
            return
        now = time.monotonic()
        if now >= self._next_cancel_check:
            self._next_cancel_check = now + 0.05
            if self.cancel():
                raise RenderCancelled("render cancelled")

    def _worth_tracing(self, wanted: np.ndarray, weight: np.ndarray) -> np.ndarray:
        """Which of ``wanted`` have a weight that reaches the contribution cutoff (the others are counted)."""
        keep = wanted & (weight >= self.savings.cutoff)
        self.counts.skipped_cutoff += int(np.count_nonzero(wanted & ~keep))
        return keep

    def _children(self, out: Shaded, idx, at, media, entering, obj, weight, surface) -> None:
        """The children the hits ``idx`` of ``out`` want, into ``out``: the mirror ray and the transmitted
        one (under total internal reflection the mirror ray again), which of them pass the cutoff, their
        weights and the weights of their colours.  ``at``: the hits' points, normals facing the rays, ray
        directions, materials and offsets; ``surface``: their (shape, part), for the true surface's normals
        (terminator.geometric_normals)."""
        point, normal, direction, mat, offset = at
        settings = self.scene.settings
        mats = self.scene.materials
        n = point.shape[0]
        kr, kt = mats.reflectivity[mat], mats.transparency[mat]
        reflects = ("reflection" in self.effects) & (kr >= settings.min_reflectivity) & (kr > 0.0)
        transmits = ("refraction" in self.effects) & (kt >= settings.min_transparency) & (kt > 0.0)
        # The weights of the mirror ray (per channel) and of the transmitted ray: the coefficients, or, for
        # the Fresnel modes of Blender scenes, the coefficients times the reflectance at this angle.
        kr_color, kr_max = kr[:, None], kr
        if "fresnel" in self.effects:
            kr_color, kt = self._fresnel_weights(direction, normal, mat, media, entering, obj, kr, kt,
                                                 reflects | transmits)
            kr_max = kr_color.max(axis=1)
        # The true surface's normal: mirror rays start off it and must not cross it back (smooth mesh triangles).
        wanted = np.nonzero(reflects | transmits)[0]
        geometric, smooth = normal.copy(), np.zeros(n, dtype=bool)
        geometric[wanted], smooth[wanted] = terminator.geometric_normals(
            self.scene, surface[0][wanted], surface[1][wanted], direction[wanted], normal[wanted])
        # Snell's law first: under total internal reflection the transmitted ray is the mirror ray.
        rows = np.nonzero(transmits)[0]
        c1 = media.subset(rows).current_speed()
        inside = media.subset(rows).entered(obj[rows], mats.speed_of_light[mat[rows]])
        outside = media.subset(rows).left(obj[rows])
        ent = entering[rows]
        after = Media(np.where(ent[:, None], inside.objects, outside.objects),
                      np.where(ent[:, None], inside.speeds, outside.speeds),
                      np.where(ent, inside.depth, outside.depth))
        c2 = np.where(ent, mats.speed_of_light[mat[rows]], outside.current_speed())
        through, total_internal = refract(direction[rows], normal[rows], c2 / c1)
        tir = np.zeros(n, dtype=bool)
        tir[rows] = total_internal
        shared = tir & reflects if self.savings.shared_tir else np.zeros(n, dtype=bool)
        self.counts.skipped_shared_tir += int(shared.sum())
        # Which rays are wanted (the cutoff), decided before any is traced: they share the ray budget.
        # The mirror ray is weighted by both coefficients where it also stands for the internal reflection.
        mirror_weight = weight * np.where(shared, kr_max + kt, kr_max)
        through_weight = weight * kt
        out.want[idx, MIRROR] = self._worth_tracing(reflects, mirror_weight)
        out.want[idx, THROUGH] = self._worth_tracing(transmits & ~shared, through_weight)
        out.weight[idx, MIRROR], out.weight[idx, THROUGH] = mirror_weight, through_weight
        out.krc[idx], out.kt[idx], out.shared[idx], out.bounce[idx] = kr_color, kt, shared, tir
        # The mirror ray leaves off the true surface, bent to leave it where smooth (terminator.bent_above);
        # the transmitted ray starts on the far side, in the medium it enters.
        mirror_start = point + offset * geometric
        mirror = terminator.bent_above(reflect(direction, normal), geometric, smooth)
        out.start[idx, MIRROR], out.direction[idx, MIRROR] = mirror_start, mirror
        out.start[idx, THROUGH], out.direction[idx, THROUGH] = mirror_start, mirror
        go = rows[~total_internal]
        out.start[idx[go], THROUGH] = point[go] - offset[go] * normal[go]
        out.direction[idx[go], THROUGH] = through[~total_internal]
        media_through = Media(out.media.objects.copy(), out.media.speeds.copy(), out.media.depth.copy())
        media_through.objects[idx[go]], media_through.speeds[idx[go]] = after.objects[~total_internal], \
            after.speeds[~total_internal]
        media_through.depth[idx[go]] = after.depth[~total_internal]
        out.through_media = media_through

    def _fresnel_weights(self, direction, normal, mat, media, entering, obj, kr, kt, rows_wanted):
        """The mirror ray's weight per channel (N, 3) and the transmitted ray's (N,) where Material.fresnel
        asks for them (tracer.fresnel): a metal's Schlick reflectance from its tint, a dielectric's exact
        reflectance F splitting reflectivity (times F) and transparency (times 1 - F)."""
        mats = self.scene.materials
        kr_color = np.repeat(kr[:, None], 3, axis=1)
        kt = kt.copy()
        mode = mats.fresnel[mat]
        rows = np.nonzero(rows_wanted & (mode != fresnel.CONSTANT))[0]
        if rows.size == 0:
            return kr_color, kt
        d = direction[rows]
        unit = d / np.sqrt(numerics.dot3(d, d))[:, None]
        cos1 = -numerics.dot3(unit, normal[rows])
        metal = mode[rows] == fresnel.METAL
        metal_rows = rows[metal]
        kr_color[metal_rows] = kr[metal_rows, None] * fresnel.schlick(cos1[metal], mats.fresnel_tint[mat[metal_rows]])
        glass = rows[~metal]
        if glass.size:
            around = media.subset(glass)
            c2 = np.where(entering[glass], mats.speed_of_light[mat[glass]], around.left(obj[glass]).current_speed())
            reflectance = fresnel.dielectric(cos1[~metal], c2 / around.current_speed())
            kr_color[glass] = (kr[glass] * reflectance)[:, None]
            kt[glass] = kt[glass] * (1.0 - reflectance)
        return kr_color, kt
