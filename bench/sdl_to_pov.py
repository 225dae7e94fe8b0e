"""Write an SDL scene as a POV-Ray 3.7 scene, for timing the two tracers on the same work.

Geometry is exact: every shape is POV-Ray's primitive for the same generic shape, placed with the shape's
own 4x4 matrix (``matrix <...>``); meshes, the teapot and the polyhedra become ``mesh2`` objects with the
same triangles and vertex normals; booleans stay booleans.  The camera, resolution, lights (point lights
without attenuation, with shadows) and recursion depth are the scene's.

Shading is matched as far as POV-Ray's model allows (its highlight takes the light's colour, its ambient
and reflection terms are scaled differently), which is close enough for a timing comparison: both tracers
shoot one ray per pixel, a shadow feeler per light and hit, and reflected and refracted rays to the same
depth.  Textures are not written.

    python3 bench/sdl_to_pov.py scene.sdl scene.pov [--width 1280 --height 960]
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent.parent))

import tracer  # noqa: E402
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


def _material(mat: Material, settings) -> str:
    """texture { pigment finish }, and an interior with the index of refraction for glass."""
    transmit = mat.transparency if mat.transparency > 0 and mat.transparency >= settings.min_transparency else 0.0
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
        s = shape.small_radius
        body = ("cylinder { <0, 0, 0>, <0, 0, 1>, 1" if s == 1.0 else
                f"cone {{ <0, 0, 0>, 1, <0, 0, 1>, {_num(s)}")
    elif kind == "torus":
        body = "torus { 1, 0.2 rotate 90*x"  # POV-Ray's torus lies in the x-z plane, SDL's in x-y
    else:
        body = _mesh2(shape)
    return body


def _object(obj, settings, indent: str = "") -> str:
    if isinstance(obj, CSG):
        inner = "\n".join(_object(child, settings, indent + "  ") for child in (obj.left, obj.right))
        return f"{indent}{obj.op} {{\n{inner}\n{indent}}}"
    return f"{indent}{_primitive(obj)}\n{indent}  {_matrix(obj.matrix)}\n{indent}  {_material(obj.material, settings)}\n{indent}}}"


def scene_to_pov(scene: Scene, width: int, height: int) -> str:
    settings = scene.settings
    camera = scene.camera or framing_camera(compile_scene(scene), width / height)
    aspect = width / height
    horizontal = math.degrees(2.0 * math.atan(math.tan(math.radians(camera.view_angle) / 2.0) * aspect))
    out = [
        "// Written by bench/sdl_to_pov.py from an SDL scene.",
        "#version 3.7;",
        "global_settings {",
        f"  assumed_gamma 1.0",
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
        out.append(_object(obj, settings))
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
