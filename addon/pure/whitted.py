"""Blender's shaders as Whitted materials: the one table of rules (docs/blender.md, "Blender materials").

No ``bpy`` here: ``shader_nodes`` reads a material's node tree into :class:`Surface` values (one per BSDF
node) and :class:`Mix` / :class:`Add` of them; :func:`whitted` turns that into the tracer Material's fields
(a dict, for ``tracer.model.Material(**fields)``).

The rules, for a Principled BSDF of Base Color b, Metallic m, Transmission t, Roughness r, IOR n, dielectric
reflectance at normal incidence F0 (from Specular IOR Level, or 3.x's Specular), Emission e and Alpha a;
the surface is three layers, weighted m (metal), (1 - m) t (glass) and (1 - m)(1 - t) (opaque dielectric):

* diffuse = ambient = b (1 - m)(1 - t)(1 - F0): Lambert (less what the dielectric's own reflection takes),
  lit by the lights and by the world (the ambient term);
* emissive = e (colour x strength);
* the highlight of each light: Blinn-Phong of exponent f = 2 / r^4 - 2 (GGX's alpha = r^2 matched to a
  normalised Blinn-Phong lobe), specular colour (f + 2) / 8 x (m b + (1 - m) F0), which is the GGX
  highlight's peak under this engine's light units; none at Roughness 0 (a mirror shows a point light only
  where it sees it, which no ray does);
* mirror rays: a metal (m > 0) reflects with Schlick's Fresnel from its base colour ("metal");
  glass (t > 0) reflects and refracts with the exact dielectric Fresnel of its IOR ("dielectric",
  speedOfLight 1/n); an opaque dielectric reflects with Schlick's F0, weighted 1 - r: a rough one reflects a
  blur, whose mean a sharp mirror ray stands for only in part (fitted against Cycles: the red cube of
  tests/test_addon_cycles.py is 16/255 off without it, 10/255 with the full weight, 5/255 with 1 - r);
* Alpha a < 1 lets 1 - a of the light straight through (transparency 1 - a, speedOfLight 1, no Fresnel),
  the rest being the surface above, times a.

The other shaders are the same layers alone: Diffuse BSDF is the opaque layer with F0 = 0, Glossy BSDF the
metal layer of its colour, Glass BSDF the glass layer, Emission only e, Transparent BSDF a = 0.  A Mix
Shader mixes the two sides' fields (colours and weights linearly); an Add Shader adds them.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Optional, Union

Color = tuple[float, float, float]

#: An opaque dielectric's mirror ray is weighted 1 - Roughness / COAT_FADE (none from this roughness on).
COAT_FADE = 1.0
#: The highest Blinn-Phong exponent used (Roughness ~0.12); a smaller roughness keeps this highlight.
MAX_EXPONENT = 10000.0
#: Below this Roughness there is no highlight: a point light's reflection in a mirror is a point.
MIN_HIGHLIGHT_ROUGHNESS = 0.01
BLACK: Color = (0.0, 0.0, 0.0)


def dielectric_f0(ior: float) -> float:
    """Reflectance at normal incidence of an interface from air to index ``ior``: ((n - 1) / (n + 1))^2."""
    n = max(float(ior), 1e-6)
    return ((n - 1.0) / (n + 1.0)) ** 2


@dataclass(frozen=True)
class Surface:
    """One shader node's surface, in Blender's terms (a Principled BSDF's inputs; other BSDFs set the inputs
    that say what they are: a Glass BSDF is transmission 1, a Glossy BSDF metallic 1, ...)."""

    base_color: Color = (0.8, 0.8, 0.8)
    metallic: float = 0.0
    transmission: float = 0.0
    roughness: float = 0.5
    ior: float = 1.5
    #: The opaque dielectric layer's reflectance at normal incidence (0.04 for Principled's defaults).
    specular_f0: float = 0.04
    emission: Color = BLACK
    alpha: float = 1.0
    #: A texture on Base Color, as the reader describes it (shader_nodes: a Picture); the colour multiplies it.
    image: Optional[object] = None


@dataclass(frozen=True)
class Mix:
    """A Mix Shader: ``(1 - factor) first + factor second``."""

    factor: float
    first: "Shader"
    second: "Shader"


@dataclass(frozen=True)
class Add:
    """An Add Shader: the sum of both."""

    first: "Shader"
    second: "Shader"


Shader = Union[Surface, Mix, Add, None]


@dataclass
class Whitted:
    """A Whitted material's fields, kept so that two can be mixed: colours and weights linearly, the highlight's
    exponent weighted by its colour, the Fresnel mode by the mirror's weight."""

    diffuse: Color = BLACK
    specular: Color = BLACK
    specular_exponent: float = 1.0
    emissive: Color = BLACK
    reflectivity: float = 0.0
    #: metal mode: reflectivity x tint is the mirror's colour at normal incidence
    fresnel_tint: Color = (1.0, 1.0, 1.0)
    transparency: float = 0.0
    #: how much of ``transparency`` is glass (refracting, Fresnel-split) rather than Alpha (straight through)
    glass: float = 0.0
    speed_of_light: float = 1.0
    image: Optional[object] = None

    def scaled(self, k: float) -> "Whitted":
        return Whitted(_scale(self.diffuse, k), _scale(self.specular, k), self.specular_exponent,
                       _scale(self.emissive, k), self.reflectivity * k, self.fresnel_tint, self.transparency * k,
                       self.glass * k, self.speed_of_light, self.image)

    def plus(self, other: "Whitted") -> "Whitted":
        spec_a, spec_b = sum(self.specular), sum(other.specular)
        exponent = (self.specular_exponent * spec_a + other.specular_exponent * spec_b) / (spec_a + spec_b) \
            if spec_a + spec_b > 0 else max(self.specular_exponent, other.specular_exponent)
        reflect = self.reflectivity + other.reflectivity
        tint = tuple((self.reflectivity * a + other.reflectivity * b) / reflect
                     for a, b in zip(self.fresnel_tint, other.fresnel_tint)) if reflect > 0 else self.fresnel_tint
        speed = self.speed_of_light if self.glass >= other.glass else other.speed_of_light
        return Whitted(_add(self.diffuse, other.diffuse), _add(self.specular, other.specular), exponent,
                       _add(self.emissive, other.emissive), reflect, tint, self.transparency + other.transparency,
                       self.glass + other.glass, speed, self.image or other.image)


def _scale(color: Color, k: float) -> Color:
    return tuple(float(c) * k for c in color)


def _add(a: Color, b: Color) -> Color:
    return tuple(float(x) + float(y) for x, y in zip(a, b))


def _clamp(value: float, low: float = 0.0, high: float = 1.0) -> float:
    return min(high, max(low, float(value)))


def highlight_exponent(roughness: float) -> float:
    """The Blinn-Phong exponent whose lobe matches GGX of alpha = roughness^2: 2 / alpha^2 - 2."""
    r = max(float(roughness), 1e-3)
    return min(MAX_EXPONENT, max(1.0, 2.0 / r ** 4 - 2.0))


def layers(surface: Surface) -> Whitted:
    """The Whitted fields of one surface (the rules in this module's docstring)."""
    b = tuple(_clamp(c, 0.0, 1e6) for c in surface.base_color)
    m = _clamp(surface.metallic)
    t = _clamp(surface.transmission) * (1.0 - m)
    opaque = (1.0 - m) - t
    r = _clamp(surface.roughness)
    f0 = _clamp(surface.specular_f0)
    # (the dielectric's own reflection takes its share of the light first: F0 at normal incidence)
    out = Whitted(diffuse=_scale(b, opaque * (1.0 - f0)), emissive=tuple(float(c) for c in surface.emission),
                  image=surface.image)
    if r >= MIN_HIGHLIGHT_ROUGHNESS:
        out.specular_exponent = highlight_exponent(r)
        peak = (out.specular_exponent + 2.0) / 8.0
        glass_f0 = dielectric_f0(surface.ior)
        out.specular = tuple(peak * (m * c + opaque * f0 + t * glass_f0) for c in b)
    # The opaque dielectric's mirror fades with roughness: a rough one reflects a blur, whose mean a sharp
    # mirror ray stands for only in part (GGX's masking darkens it at grazing angles, where Schlick peaks).
    coat = opaque * max(0.0, 1.0 - r / COAT_FADE) if f0 > 0.0 else 0.0
    if t > 0.0:  # glass: both rays, split by the exact Fresnel of its IOR
        out.reflectivity, out.transparency, out.glass = 1.0, t, t
        out.speed_of_light = 1.0 / max(float(surface.ior), 1e-6)
        out.fresnel_tint = (f0,) * 3
    else:
        mirror = m + coat
        if mirror > 0.0:
            out.reflectivity = mirror
            out.fresnel_tint = tuple((m * c + coat * f0) / mirror for c in b)
    alpha = _clamp(surface.alpha)
    if alpha < 1.0:
        out = out.scaled(alpha)
        out.transparency += 1.0 - alpha
    return out


def combine(shader: Shader) -> Whitted:
    """The Whitted fields of a shader tree (None, an unconnected or unknown shader: black)."""
    if isinstance(shader, Surface):
        return layers(shader)
    if isinstance(shader, Mix):
        k = _clamp(shader.factor)
        return combine(shader.first).scaled(1.0 - k).plus(combine(shader.second).scaled(k))
    if isinstance(shader, Add):
        return combine(shader.first).plus(combine(shader.second))
    return Whitted()


def whitted(shader: Shader) -> dict:
    """The tracer Material's fields (``tracer.model.Material(**fields)``) for a shader tree, and ``image``:
    the picture on its Base Color, or None (the caller numbers it as the material's texture)."""
    w = combine(shader)
    glass_share = w.glass / w.transparency if w.transparency > 0 else 0.0
    if w.glass > 0.0 and glass_share >= 0.5:
        fresnel = "dielectric"
    elif w.reflectivity > 0.0 and w.transparency == 0.0:
        fresnel = "metal"
    else:  # straight through (Alpha): no Fresnel on either ray
        fresnel = "constant"
    reflectivity = _clamp(w.reflectivity)
    if fresnel == "constant" and reflectivity > 0.0:  # a mirror's weight at normal incidence
        reflectivity *= sum(w.fresnel_tint) / 3.0
    return {"ambient": w.diffuse, "diffuse": w.diffuse, "specular": w.specular,
            "specular_exponent": w.specular_exponent, "emissive": w.emissive, "reflectivity": reflectivity,
            "transparency": _clamp(w.transparency), "speed_of_light": w.speed_of_light if w.glass > 0 else 1.0,
            "fresnel": fresnel, "fresnel_tint": tuple(_clamp(c) for c in w.fresnel_tint), "image": w.image}
