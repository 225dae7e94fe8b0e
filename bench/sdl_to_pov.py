"""Write an SDL scene as a POV-Ray 3.7 scene, for timing the two tracers on the same work.

Geometry is exact: every shape is POV-Ray's primitive for the same generic shape, placed with the shape's
own 4x4 matrix (``matrix <...>``); meshes, the teapot and the polyhedra become ``mesh2`` objects with the
same triangles and vertex normals; booleans stay booleans.  The camera, resolution, lights (point lights
without attenuation, with shadows) and recursion depth are the scene's.

Shading is matched as far as POV-Ray's model allows (its highlight takes the light's colour, its ambient
and reflection terms are scaled differently), which is close enough for a timing comparison: both tracers
shoot one ray per pixel, a shadow feeler per light and hit, and reflected and refracted rays to the same
depth.  Textures become POV-Ray's nearest equivalents, in the shape's generic coordinates as ours are:
``checker`` for the checkerboard (the same cells), ``wood`` and ``marble`` with turbulence for wood grain
and marble (alike, not equal: POV-Ray's turbulence is its own noise), and ``image_map`` with bilinear
interpolation for pictures (spherical, cylindrical or planar projection, POV-Ray's closest to our per-shape
(u, v)).

    python3 bench/sdl_to_pov.py scene.sdl scene.pov [--width 1280 --height 960]
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path
from typing import Optional

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import tracer  # noqa: E402
from tracer import shapes  # noqa: E402
from tracer.camera import framing_camera  # noqa: E402
from tracer.compile import compile_scene  # noqa: E402
from tracer.model import CSG, Material, Scene, Shape  # noqa: E402


def _num(x: float) -> str:
    return repr(float(x))


def _vec(v) -> str:
    return "<" + ", ".join(_num(x) for x in v) + ">"


def _matrix(m: np.ndarray) -> str:
    """POV-Ray's matrix keyword: row vectors, p' = p M, the 12 numbers are the columns of our 3x4."""
    m = np.asarray(m, dtype=float)
    values = [m[r, c] for c in range(4) for r in range(3)]
    return "matrix <" + ", ".join(_num(v) for v in values) + ">"


def _finish(mat: Material, settings) -> str:
    diffuse = np.asarray(mat.diffuse, dtype=float)
    ambient = np.asarray(mat.ambient, dtype=float)
    # POV-Ray multiplies ambient by the pigment colour; ours is a colour of its own.
    safe = np.where(diffuse > 1e-6, diffuse, 1.0)
    parts = [f"ambient rgb {_vec(np.where(diffuse > 1e-6, ambient / safe, 0.0))}", "diffuse 1"]
    if any(mat.emissive):
        parts.append(f"emission rgb {_vec(mat.emissive)}")
    spec = float(np.mean(mat.specular))
    if spec > 0:
        parts.append(f"specular {_num(spec)} roughness {_num(1.0 / max(mat.specular_exponent, 1e-3))}")
    if mat.reflectivity > 0 and mat.reflectivity >= settings.min_reflectivity:
        parts.append(f"reflection {{ {_num(mat.reflectivity)} }}")
    return "finish { " + " ".join(parts) + " }"


_IMAGE_FORMATS = {".png": "png", ".bmp": "bmp", ".jpg": "jpeg", ".jpeg": "jpeg", ".tga": "tga", ".ppm": "ppm"}


def _textured_pigment(mat: Material, kind: str, pixmaps: dict) -> str:
    """POV-Ray's nearest pigment to an SDL texture, in generic coordinates (written before the matrix).

    The texture colour multiplies the diffuse colour in SDL; with the usual ``diffuse 1 1 1`` of textured
    shapes the pigment alone is the same thing.
    """
    from tracer.textures.solid import CHECKER_DEFAULTS, MARBLE_DEFAULTS, WOOD_DEFAULTS, with_defaults

    t = mat.texture
    if t == -1:
        size, *c = with_defaults(mat.parameters, CHECKER_DEFAULTS)
        # POV-Ray's cells are unit cubes with faces on integers; SDL's are centred on the lattice.
        return (f"pigment {{ checker rgb {_vec(c[3:6])} rgb {_vec(c[0:3])} "
                f"translate <0.5, 0.5, 0.5> scale {_num(size)} }}")
    if t == -2:
        spacing, wobble, *c = with_defaults(mat.parameters, WOOD_DEFAULTS)
        return (f"pigment {{ wood ramp_wave turbulence {_num(wobble)} "
                f"color_map {{ [0 rgb {_vec(c[0:3])}] [0.65 rgb {_vec(c[0:3])}] [1 rgb {_vec(c[3:6])}] }} "
                f"scale {_num(spacing)} }}")
    if t == -3:
        stripes, strength, octaves, *c = with_defaults(mat.parameters, MARBLE_DEFAULTS)
        return (f"pigment {{ marble turbulence {_num(strength / 4.0)} octaves {max(1, int(octaves))} "
                f"color_map {{ [0 rgb {_vec(c[3:6])}] [0.3 rgb {_vec(c[0:3])}] [1 rgb {_vec(c[0:3])}] }} "
                f"scale {_num(2.0 / max(stripes, 1e-6))} }}")
    path = Path(pixmaps[t]).resolve()
    repeat_u, repeat_v = (tuple(mat.parameters) + (1.0, 1.0))[:2]
    # gamma 1.0: texel values are used as they are, as ours are (POV-Ray would decode them as sRGB).
    image = f'image_map {{ {_IMAGE_FORMATS.get(path.suffix.lower(), "png")} "{path}" gamma 1.0 interpolate 2'
    if kind == "sphere":  # POV-Ray's spherical map has its poles on y, SDL's on z
        return f"pigment {{ {image} map_type 1 }} rotate 90*x }}"
    if kind in ("cylinder", "cone", "taperedCylinder"):  # cylindrical about y over 0 <= y <= 1; SDL's about z
        return f"pigment {{ {image} map_type 2 }} rotate 90*x }}"
    # Planar: the picture spans x, y in [0, 1]; SDL's squares, planes and cube faces span [-1, 1].
    once = "" if kind == "plane" or (repeat_u, repeat_v) != (1.0, 1.0) else " once"
    return (f"pigment {{ {image} map_type 0{once} }} "
            f"scale <{_num(2 / repeat_u)}, {_num(2 / repeat_v)}, 1> translate <-1, -1, 0> }}")


def _material(mat: Material, settings, kind: str = "", pixmaps: Optional[dict] = None) -> str:
    """texture { pigment finish }, and an interior with the index of refraction for glass."""
    transmit = mat.transparency if mat.transparency > 0 and mat.transparency >= settings.min_transparency else 0.0
    if mat.texture != 0 and pixmaps is not None and (mat.texture < 0 or mat.texture in pixmaps):
        pigment = _textured_pigment(mat, kind, pixmaps)
    else:
        pigment = f"pigment {{ rgbt <{', '.join(_num(c) for c in mat.diffuse)}, {_num(transmit)}> }}"
    interior = f" interior {{ ior {_num(1.0 / mat.speed_of_light)} }}" if transmit > 0 else ""
    return f"texture {{ {pigment} {_finish(mat, settings)} }}{interior}"


def _mesh2(shape: Shape) -> str:
    tri_v, tri_n = shape.mesh.triangles()
    vertices = np.asarray(shape.mesh.vertices, dtype=float)
    normals = np.asarray(shape.mesh.normals, dtype=float).reshape(-1, 3)
    lines = ["mesh2 {", f"  vertex_vectors {{ {len(vertices)}, " + ", ".join(_vec(v) for v in vertices) + " }"]
    smooth = len(normals) and (tri_n >= 0).all()
    if smooth:
        lines.append(f"  normal_vectors {{ {len(normals)}, " + ", ".join(_vec(n) for n in normals) + " }")
    lines.append(f"  face_indices {{ {len(tri_v)}, " + ", ".join(f"<{a}, {b}, {c}>" for a, b, c in tri_v) + " }")
    if smooth:
        lines.append(f"  normal_indices {{ {len(tri_n)}, " + ", ".join(f"<{a}, {b}, {c}>" for a, b, c in tri_n) + " }")
    return "\n".join(lines)


def _primitive(shape: Shape) -> str:
    kind = shape.kind
    if kind == "sphere":
        body = "sphere { <0, 0, 0>, 1"
    elif kind == "cube":
        body = "box { <-1, -1, -1>, <1, 1, 1>"
    elif kind == "square":
        body = "polygon { 5, <-1, -1, 0>, <1, -1, 0>, <1, 1, 0>, <-1, 1, 0>, <-1, -1, 0>"
    elif kind == "plane":
        body = "plane { <0, 0, 1>, 0"  # inside is z < 0, as SDL's half-space
    elif kind in ("taperedCylinder", "cylinder", "cone"):
        s = shapes.KINDS[kind].traced(shape.parameters)[0]
        body = ("cylinder { <0, 0, 0>, <0, 0, 1>, 1" if s == 1.0 else
                f"cone {{ <0, 0, 0>, 1, <0, 0, 1>, {_num(s)}")
    elif kind == "torus":
        body = "torus { 1, 0.2 rotate 90*x"  # POV-Ray's torus lies in the x-z plane, SDL's in x-y
    else:
        body = _mesh2(shape)
    return body


def _object(obj, settings, indent: str = "", pixmaps: Optional[dict] = None) -> str:
    if isinstance(obj, CSG):
        inner = "\n".join(_object(child, settings, indent + "  ", pixmaps) for child in (obj.left, obj.right))
        return f"{indent}{obj.op} {{\n{inner}\n{indent}}}"
    material = _material(obj.material, settings, obj.kind, pixmaps)
    if obj.material.texture != 0:  # before the matrix: the texture moves, turns and scales with the shape
        return f"{indent}{_primitive(obj)}\n{indent}  {material}\n{indent}  {_matrix(obj.matrix)}\n{indent}}}"
    return f"{indent}{_primitive(obj)}\n{indent}  {_matrix(obj.matrix)}\n{indent}  {material}\n{indent}}}"


def scene_to_pov(scene: Scene, width: int, height: int) -> str:
    settings = scene.settings
    camera = scene.camera or framing_camera(compile_scene(scene), width / height)
    aspect = width / height
    horizontal = math.degrees(2.0 * math.atan(math.tan(math.radians(camera.view_angle) / 2.0) * aspect))
    out = [
        "// Written by bench/sdl_to_pov.py from an SDL scene.",
        "#version 3.7;",
        "global_settings {",
        "  assumed_gamma 1.0",
        f"  max_trace_level {int(settings.max_recursion_depth) + 1}",
        f"  ambient_light rgb {_vec(settings.global_ambient)}",
        "}",
        f"background {{ rgb {_vec(settings.background)} }}",
        "camera {",
        "  perspective",
        f"  location {_vec(camera.eye)}",
        f"  sky {_vec(camera.up)}",
        "  up y",
        f"  right -x*{_num(aspect)}",  # SDL is right-handed; a negative right vector makes POV-Ray so too
        f"  angle {_num(horizontal)}",
        f"  look_at {_vec(camera.look)}",
        "}",
    ]
    for light in scene.lights:
        out.append(f"light_source {{ {_vec(light.position)} color rgb {_vec(light.color)} }}")
    for obj in scene.objects:
        out.append(_object(obj, settings, pixmaps=scene.pixmaps))
    return "\n".join(out) + "\n"


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scene")
    p.add_argument("output")
    p.add_argument("--width", type=int, default=1280)
    p.add_argument("--height", type=int, default=960)
    args = p.parse_args(argv)
    Path(args.output).write_text(scene_to_pov(tracer.load(args.scene), args.width, args.height))
    return 0


if __name__ == "__main__":
    sys.exit(main())
