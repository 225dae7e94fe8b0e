"""SDL materials as UsdPreviewSurface and back: the approximation other tools see.

The two models differ (SDL: Phong with separate ambient, diffuse, specular and emissive colours, mirror
reflectivity and transparency; UsdPreviewSurface: a physically based surface), so neither direction is
exact.  Our own files do not depend on it: they keep every SDL value in ``sdl:*`` attributes as well.
"""
from __future__ import annotations

from typing import Callable

from ..appearance import display_roughness
from ..model import Material

#: UsdPreviewSurface's fallback values (its specification), for inputs a shader does not author.
PREVIEW_DEFAULTS = {"diffuseColor": (0.18, 0.18, 0.18), "emissiveColor": (0.0, 0.0, 0.0),
                    "specularColor": (0.0, 0.0, 0.0), "useSpecularWorkflow": 0, "metallic": 0.0,
                    "roughness": 0.5, "opacity": 1.0, "ior": 1.5}

#: Phong exponents read from a roughness are kept within these.
EXPONENT_RANGE = (1.0, 10000.0)


def _clamp(x: float, low: float = 0.0, high: float = 1.0) -> float:
    return min(high, max(low, x))


def preview_inputs(material: Material) -> dict[str, object]:
    """The shader inputs for an SDL material, by name: floats, colour triples, and the one int.

    The specular workflow keeps SDL's specular colour; opacity is 1 - transparency; the index of refraction
    is 1 / speedOfLight (SDL's speeds are relative to the medium outside)."""
    inputs: dict[str, object] = {
        "diffuseColor": tuple(material.diffuse), "emissiveColor": tuple(material.emissive),
        "useSpecularWorkflow": 1, "specularColor": tuple(material.specular), "metallic": 0.0,
        "opacity": _clamp(1.0 - material.transparency), "roughness": display_roughness(material)}
    if material.speed_of_light > 0:
        inputs["ior"] = 1.0 / material.speed_of_light
    if material.fresnel == "metal":  # a tinted mirror: the metallic workflow with the tint as its colour
        inputs.update(useSpecularWorkflow=0, metallic=_clamp(material.reflectivity),
                      diffuseColor=tuple(material.fresnel_tint))
    return inputs


def material_from_preview(value: Callable[[str], object]) -> Material:
    """An SDL material from a UsdPreviewSurface's inputs (``value(name)`` gives an input's value, or None
    where it is not authored).

    The ambient colour is the diffuse one (lit by SDL's globalAmbient); the metallic workflow's specular
    colour is 4 % white for a dielectric and the base colour for a metal, and ``metallic`` becomes mirror
    reflectivity; the roughness r becomes the Phong exponent 2 / r^2 - 2 (the inverse of
    :func:`tracer.appearance.display_roughness`); opacity below 1 becomes transparency, with speedOfLight 1 / ior."""
    def get(name):
        got = value(name)
        return PREVIEW_DEFAULTS[name] if got is None else got

    diffuse = tuple(float(x) for x in get("diffuseColor"))
    metallic = _clamp(float(get("metallic")))
    if int(get("useSpecularWorkflow")):
        specular = tuple(float(x) for x in get("specularColor"))
    else:
        specular = tuple(0.04 * (1.0 - metallic) + metallic * d for d in diffuse)
    roughness = max(float(get("roughness")), 0.01)
    exponent = _clamp(2.0 / roughness ** 2 - 2.0, *EXPONENT_RANGE)
    transparency = _clamp(1.0 - float(get("opacity")))
    ior = float(get("ior"))
    speed = 1.0 / ior if transparency > 0.0 and ior > 0.0 else 1.0
    return Material(ambient=diffuse, diffuse=diffuse, specular=specular,
                    emissive=tuple(float(x) for x in get("emissiveColor")), specular_exponent=exponent,
                    reflectivity=metallic, transparency=transparency, speed_of_light=speed)
