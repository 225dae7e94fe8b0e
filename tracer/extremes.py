"""The extreme cases of docs/tracer.md ("Rounding error"): one scene moved, scaled or seen from far away,
rendered and compared with its plain render, pixel by pixel.

A similarity map (scale and translation) applied to every shape, light and the camera leaves the image
unchanged in exact arithmetic, and so does moving the eye back along its line of sight while narrowing the
view angle to keep the framing (except for the perspective, which is why the telephoto cases compare with
the same view from 10^4 away, where rounding is harmless).  What differs is rounding error.

``python -m tracer.extremes [WIDTH HEIGHT] [--case NAME]`` prints the table (percent of pixels that differ by more than
1/255 from the reference, per backend, and the pixels in which the backends' extreme images differ).
"""
from __future__ import annotations

import argparse
import math
import sys
from dataclasses import replace
from pathlib import Path
from typing import Callable

import numpy as np

from .compile import compile_scene
from .geometry import builtin_mesh
from .model import CSG, Camera, Light, Material, Scene, SceneObject, Settings, Shape
from .render import render
from .sdl.parser import load
from .transforms import rotation, scaling, translation

SCENES = Path(__file__).resolve().parent.parent / "scenes"
#: How far back the telephoto reference stands: far enough that the remaining perspective is < 0.1 pixel.
TELEPHOTO_REFERENCE = 1e4


def _point(matrix: np.ndarray, p) -> tuple:
    return tuple((matrix[:3, :3] @ np.asarray(p, dtype=float) + matrix[:3, 3]).tolist())


def _mapped_object(obj: SceneObject, matrix: np.ndarray) -> SceneObject:
    if isinstance(obj, CSG):
        return replace(obj, left=_mapped_object(obj.left, matrix), right=_mapped_object(obj.right, matrix))
    return replace(obj, matrix=matrix @ obj.matrix)


def mapped(scene: Scene, matrix: np.ndarray) -> Scene:
    """The scene with every shape, light and the camera moved by the similarity ``matrix``."""
    camera = scene.camera
    if camera is not None:
        up = tuple((matrix[:3, :3] @ np.asarray(camera.up, dtype=float)).tolist())
        camera = replace(camera, eye=_point(matrix, camera.eye), look=_point(matrix, camera.look), up=up)
    lights = [replace(light, position=_point(matrix, light.position)) for light in scene.lights]
    return replace(scene, objects=[_mapped_object(o, matrix) for o in scene.objects], lights=lights,
                   camera=camera)


def moved(scene: Scene, offset) -> Scene:
    m = np.eye(4)
    m[:3, 3] = offset
    return mapped(scene, m)


def scaled(scene: Scene, factor: float) -> Scene:
    return mapped(scene, np.diag([factor, factor, factor, 1.0]))


def telephoto(scene: Scene, farther: float) -> Scene:
    """The eye ``farther`` units further back along its line of sight, the view angle narrowed to keep
    the framing at the point looked at."""
    cam = scene.camera
    eye, look = np.asarray(cam.eye, dtype=float), np.asarray(cam.look, dtype=float)
    distance = float(np.linalg.norm(eye - look))
    new_eye = look + (eye - look) * (distance + farther) / distance
    half = math.radians(cam.view_angle) / 2.0
    angle = 2.0 * math.degrees(math.atan(math.tan(half) * distance / (distance + farther)))
    return replace(scene, camera=replace(cam, eye=tuple(new_eye.tolist()), view_angle=angle))


def glass_pane(thickness: float = 1e-5) -> Scene:
    """A thin glass pane at the origin in front of three coloured blocks on a floor, lit from above."""
    glass = Material(ambient=(0, 0, 0), diffuse=(0.05, 0.05, 0.05), specular=(0.9, 0.9, 0.9),
                     specular_exponent=120, transparency=0.9, speed_of_light=0.67, reflectivity=0.1)
    floor = Shape("plane", translation(0, -1, 0) @ np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0],
                                                               [0, 0, 0, 1]], dtype=float),
                  Material(diffuse=(0.6, 0.6, 0.6), specular=(0, 0, 0)))
    blocks = [Shape("cube", translation(x, -0.5, -3) @ scaling(0.5, 0.5, 0.5), Material(diffuse=color))
              for x, color in ((-1.5, (0.9, 0.2, 0.2)), (0, (0.2, 0.8, 0.2)), (1.5, (0.2, 0.3, 0.9)))]
    # The pane faces the camera, tilted so that refraction shifts what is seen through it.
    tilt = np.array([[1, 0, 0, 0], [0, math.cos(0.4), -math.sin(0.4), 0], [0, math.sin(0.4), math.cos(0.4), 0],
                     [0, 0, 0, 1]], dtype=float)
    pane = Shape("cube", tilt @ scaling(1.8, 1.2, thickness / 2.0), glass)
    return Scene(objects=[floor, *blocks, pane], lights=[Light((3, 6, 5), (1, 1, 1)), Light((-4, 3, 4), (0.4, 0.4, 0.4))],
                 camera=Camera((0.3, 0.8, 4.0), (0, -0.2, -1), (0, 1, 0), 50),
                 settings=Settings(global_ambient=(0.15, 0.15, 0.15), background=(0.1, 0.1, 0.15),
                                   max_recursion_depth=4, min_transparency=0.05, min_reflectivity=0.05))


#: The floor of the scenes below: the generic plane turned so that it is exactly y = 0 (its matrix is exact).
_FLOOR = np.array([[1, 0, 0, 0], [0, 0, 1, 0], [0, -1, 0, 0], [0, 0, 0, 1]], dtype=float)
#: Matt materials (no specular highlight): with a light in a surface's plane the highlight of Blinn's model
#: is there or not by the sign of a rounding residue, in the plain twin (the light 1e-7 off) as well.
_MATT = {"specular": (0.0, 0.0, 0.0)}


def _room_shapes() -> list[Shape]:
    """A floor, a cube turned 30 degrees and a sphere: the hosts of the lights on surfaces."""
    floor = Shape("plane", _FLOOR, Material(diffuse=(0.6, 0.6, 0.6), **_MATT))
    cube = Shape("cube", translation(-1.2, 0.55, -0.6) @ rotation(30, 0, 1, 0) @ scaling(0.5, 0.5, 0.5),
                 Material(diffuse=(0.9, 0.25, 0.2), **_MATT))
    sphere = Shape("sphere", translation(1.1, 0.75, -0.4) @ scaling(0.7, 0.7, 0.7), Material(diffuse=(0.2, 0.4, 0.9), **_MATT))
    return [floor, cube, sphere]


def light_on_surface(host: str, off: float = 0.0) -> Scene:
    """The room lit by a dim light from above and a bright one exactly on a surface (``host``: "cube" on a
    face, "sphere" on a point, "floor" in the plane, "mesh" on a face of an octahedron that is a triangle
    mesh, in the cube's place), or ``off`` units outside it along the normal there (the plain twin: in exact
    arithmetic the same picture)."""
    floor, cube, sphere = _room_shapes()
    if host == "mesh":
        matrix = translation(-1.2, 0.75, -0.6) @ rotation(30, 0, 1, 0) @ scaling(0.7, 0.7, 0.7)
        cube = Shape("mesh", matrix, cube.material)
        cube.mesh = builtin_mesh("octahedron")
        # the middle of the face x + y + z = 1
        on, normal = _point(matrix, (1 / 3, 1 / 3, 1 / 3)), np.linalg.inv(matrix[:3, :3]).T @ (1.0, 1.0, 1.0)
    elif host == "cube":  # a point of the face turned toward the camera, generic z = 1
        on, normal = _point(cube.matrix, (0.3, -0.2, 1.0)), cube.matrix[:3, :3] @ (0.0, 0.0, 1.0)
    elif host == "sphere":
        direction = np.array([0.45, 0.35, 0.82]) / np.linalg.norm([0.45, 0.35, 0.82])
        on, normal = _point(sphere.matrix, direction), direction
    else:
        on, normal = (-2.5, 0.0, 1.5), np.array([0.0, 1.0, 0.0])
    normal = np.asarray(normal, dtype=float) / np.linalg.norm(normal)
    position = tuple((np.asarray(on) + off * normal).tolist())
    return Scene(objects=[floor, cube, sphere], lights=[Light((3, 6, 5), (0.3, 0.3, 0.3)), Light(position, (0.8, 0.8, 0.8))],
                 camera=Camera((0.4, 2.4, 5.5), (0, 0.4, -0.4), (0, 1, 0), 45),
                 settings=Settings(global_ambient=(0.1, 0.1, 0.1), background=(0.1, 0.1, 0.15)))


#: The light of a plain twin is this far off the surface its extreme case's light sits on.
LIGHT_OFF = 1e-7


def far_light(distance: float) -> Scene:
    """The room lit from one direction by a light ``distance`` away (beyond 1.3e154 |L - P|^2 overflows)."""
    floor, cube, sphere = _room_shapes()
    toward = np.array([0.5, 0.8, 0.4]) / np.linalg.norm([0.5, 0.8, 0.4])
    return Scene(objects=[floor, cube, sphere], lights=[Light(tuple((distance * toward).tolist()), (0.9, 0.9, 0.9))],
                 camera=Camera((0.4, 2.4, 5.5), (0, 0.4, -0.4), (0, 1, 0), 45),
                 settings=Settings(global_ambient=(0.1, 0.1, 0.1), background=(0.1, 0.1, 0.15)))


def coplanar_faces() -> Scene:
    """Squares lying exactly on the faces of a turned cube and, overlapping, on the floor (decals): each square
    comes before its cube and floor in the scene, so where their hits tie (their error intervals overlap,
    docs/tracer.md) it is the square that is seen."""
    cube_matrix = translation(0.2, 0.7, -0.5) @ rotation(35, 0, 1, 0) @ rotation(20, 1, 0, 0) @ scaling(0.7, 0.7, 0.7)
    decals = []
    for face, color in (((0.0, 0.0, 1.0), (0.95, 0.9, 0.2)), ((1.0, 0.0, 0.0), (0.2, 0.8, 0.9)),
                        ((0.0, 1.0, 0.0), (0.9, 0.3, 0.8))):
        # the generic square (z = 0) turned onto the face of the cube whose normal is `face`
        turn = {(0.0, 0.0, 1.0): np.eye(4), (1.0, 0.0, 0.0): rotation(90, 0, 1, 0),
                (0.0, 1.0, 0.0): rotation(-90, 1, 0, 0)}[face]
        on_face = cube_matrix @ translation(*face) @ turn @ scaling(0.6, 0.6, 1.0)
        decals.append(Shape("square", on_face, Material(diffuse=color, **_MATT)))
    floor_decal = Shape("square", _FLOOR @ translation(-1.6, 0.4, 0.0) @ scaling(0.9, 0.6, 1.0),
                        Material(diffuse=(0.9, 0.5, 0.1), **_MATT))
    cube = Shape("cube", cube_matrix, Material(diffuse=(0.8, 0.2, 0.2), **_MATT))
    floor = Shape("plane", _FLOOR, Material(diffuse=(0.6, 0.6, 0.6), **_MATT))
    return Scene(objects=[*decals, floor_decal, cube, floor], lights=[Light((3, 6, 5), (0.9, 0.9, 0.9))],
                 camera=Camera((2.6, 2.4, 2.8), (-0.4, 0.4, -0.5), (0, 1, 0), 45),
                 settings=Settings(global_ambient=(0.15, 0.15, 0.15), background=(0.1, 0.1, 0.15)))


def grazing_mirror() -> Scene:
    """A mirror floor (a square 40 wide) seen from 10^-6 above it, 10 away: the camera's rays meet it within
    10^-7 ... 10^-5 rad, and the reflected rays leave it as flat (a cube and a sphere stand on it, lit)."""
    floor = Shape("square", _FLOOR @ scaling(20.0, 20.0, 1.0),
                  Material(diffuse=(0.1, 0.1, 0.1), specular=(0.0, 0.0, 0.0), reflectivity=0.8))
    cube = Shape("cube", translation(-0.8, 0.5, -1.0) @ rotation(25, 0, 1, 0) @ scaling(0.5, 0.5, 0.5),
                 Material(diffuse=(0.9, 0.3, 0.2), **_MATT))
    sphere = Shape("sphere", translation(0.9, 0.6, -0.5) @ scaling(0.6, 0.6, 0.6), Material(diffuse=(0.2, 0.5, 0.9), **_MATT))
    return Scene(objects=[floor, cube, sphere], lights=[Light((3, 6, 5), (0.9, 0.9, 0.9))],
                 camera=Camera((0.0, 1e-6, 9.0), (0.0, 1e-6, -1.0), (0, 1, 0), 30),
                 settings=Settings(global_ambient=(0.15, 0.15, 0.15), background=(0.25, 0.3, 0.4),
                                   max_recursion_depth=2, min_reflectivity=0.05))


def tangent_tubes() -> Scene:
    """A torus and a thin one (flattened to 0.3) seen edge on, from their own plane, with a cone on
    its apex between them: the silhouettes are rays tangent to the tubes, and the rays near the middle pass
    by the apex, along its generators."""
    torus = Shape("torus", translation(-1.3, 0.6, 0.0) @ rotation(-90, 1, 0, 0) @ scaling(0.8, 0.8, 0.8),
                  Material(diffuse=(0.9, 0.6, 0.2), **_MATT))
    thin = Shape("torus", translation(1.3, 0.6, 0.0) @ rotation(-90, 1, 0, 0) @ scaling(0.8, 0.8, 0.3),
                 Material(diffuse=(0.3, 0.8, 0.4), **_MATT))
    cone = Shape("cone", translation(0.0, 1.4, 0.0) @ rotation(90, 1, 0, 0) @ scaling(0.4, 0.4, 1.0),
                 Material(diffuse=(0.6, 0.4, 0.9), **_MATT))
    return Scene(objects=[torus, thin, cone], lights=[Light((2, 5, 6), (0.9, 0.9, 0.9))],
                 camera=Camera((0.0, 0.6, 6.0), (0.0, 0.6, 0.0), (0, 1, 0), 40),
                 settings=Settings(global_ambient=(0.15, 0.15, 0.15), background=(0.1, 0.1, 0.15)))


def torus_silhouette(span: float, flattened: float = 1.0) -> Scene:
    """The top of a torus's tube (flattened to ``flattened`` of its height) seen along the line that touches
    it at x = -1 and x = 1, through a window ``span`` high: the lower rows cross the tube twice in chords as
    short as sqrt(2 r span), the upper rows miss it, and the middle ones are tangent within the span."""
    top = 0.2 * flattened
    torus = Shape("torus", scaling(1.0, 1.0, flattened), Material(diffuse=(0.9, 0.6, 0.2), **_MATT))
    angle = 2.0 * math.degrees(math.atan(span / 2.0 / 4.0))
    return Scene(objects=[torus], lights=[Light((-6.0, 2.0, 4.0), (0.9, 0.9, 0.9))],
                 camera=Camera((-5.0, 0.0, top), (-1.0, 0.0, top), (0, 0, 1), angle),
                 settings=Settings(global_ambient=(0.15, 0.15, 0.15), background=(0.1, 0.1, 0.15)))


def cone_apex(span: float, view=(0.3, 0.5, 1.0), light=None) -> Scene:
    """A cone standing on its base, its apex seen from 3 units away along ``view`` (from the apex, on the
    side the cone's tip points to) through a window ``span`` wide, lit from the eye or from ``light`` (also
    relative to the apex).  Any light outside the cone will do: every point seen either faces it or gets no
    light and casts no feeler, and a convex solid cannot shadow itself, so any shadow on it is a feeler
    finding again the surface it left."""
    cone = Shape("cone", rotation(-90, 1, 0, 0), Material(diffuse=(0.85, 0.6, 0.2), **_MATT))
    apex = np.asarray(_point(cone.matrix, (0.0, 0.0, 1.0)))
    view = np.asarray(view, dtype=float) / np.linalg.norm(view)
    eye = tuple((apex + 3.0 * view).tolist())
    lamp = eye if light is None else tuple((apex + np.asarray(light, dtype=float)).tolist())
    up = (0, 1, 0) if abs(view[1]) < 0.9 else (1, 0, 0)
    angle = 2.0 * math.degrees(math.atan(span / 2.0 / 3.0))
    return Scene(objects=[cone], lights=[Light(lamp, (0.9, 0.9, 0.9))],
                 camera=Camera(eye, tuple(apex.tolist()), up, angle),
                 settings=Settings(global_ambient=(0.1, 0.1, 0.1), background=(0.1, 0.1, 0.15)))


def without_shadows(scene: Scene):
    """The scene compiled with its shadow feelers turned off (a twin for scenes that should have no shadow)."""
    compiled = compile_scene(scene)
    return replace(compiled, effects=compiled.effects - {"shadows"})


def bundled(name: str) -> Scene:
    return load(SCENES / f"{name}.sdl")


#: name -> (reference scene, extreme scene), each made on demand.
CASES: dict[str, Callable[[], tuple[Scene, Scene]]] = {
    "csg: seen from 1e6 farther": lambda: (telephoto(bundled("csg"), TELEPHOTO_REFERENCE), telephoto(bundled("csg"), 1e6)),
    "csg: seen from 1e8 farther": lambda: (telephoto(bundled("csg"), TELEPHOTO_REFERENCE), telephoto(bundled("csg"), 1e8)),
    "csg: scaled by 1e-8": lambda: (bundled("csg"), scaled(bundled("csg"), 1e-8)),
    "csg: scaled by 1e8": lambda: (bundled("csg"), scaled(bundled("csg"), 1e8)),
    "csg: moved by +1e7": lambda: (bundled("csg"), moved(bundled("csg"), (1e7, 1e7, 1e7))),
    "csg: moved by -1e7": lambda: (bundled("csg"), moved(bundled("csg"), (-1e7, -1e7, -1e7))),
    "csg: 1 mm, moved by 1e5": lambda: (bundled("csg"), moved(scaled(bundled("csg"), 1e-3), (1e5, 1e5, 1e5))),
    "glass: seen from 1e8 farther": lambda: (telephoto(bundled("glass"), TELEPHOTO_REFERENCE),
                                             telephoto(bundled("glass"), 1e8)),
    "glass: scaled by 1e-8": lambda: (bundled("glass"), scaled(bundled("glass"), 1e-8)),
    "glass: moved by +1e7": lambda: (bundled("glass"), moved(bundled("glass"), (1e7, 1e7, 1e7))),
    "1e-5 glass pane: moved by 1e5": lambda: (glass_pane(), moved(glass_pane(), (1e5, 1e5, 1e5))),
    "light on a cube face": lambda: (light_on_surface("cube", LIGHT_OFF), light_on_surface("cube")),
    "light on a cube face: moved by +1e5": lambda: (light_on_surface("cube", LIGHT_OFF),
                                                    moved(light_on_surface("cube"), (1e5, 1e5, 1e5))),
    "light on a sphere": lambda: (light_on_surface("sphere", LIGHT_OFF), light_on_surface("sphere")),
    "light on a sphere: moved by +1e5": lambda: (light_on_surface("sphere", LIGHT_OFF),
                                                 moved(light_on_surface("sphere"), (1e5, 1e5, 1e5))),
    "light on a mesh face": lambda: (light_on_surface("mesh", LIGHT_OFF), light_on_surface("mesh")),
    "light on a mesh face: moved by +1e5": lambda: (light_on_surface("mesh", LIGHT_OFF),
                                                    moved(light_on_surface("mesh"), (1e5, 1e5, 1e5))),
    "light in the floor plane": lambda: (light_on_surface("floor", LIGHT_OFF), light_on_surface("floor")),
    "light in the floor plane: moved by +1e5": lambda: (light_on_surface("floor", LIGHT_OFF),
                                                        moved(light_on_surface("floor"), (1e5, 1e5, 1e5))),
    "light at 1e300": lambda: (far_light(1e12), far_light(1e300)),
    "coplanar faces: moved by +1e5": lambda: (coplanar_faces(), moved(coplanar_faces(), (1e5, 1e5, 1e5))),
    "coplanar faces: scaled by 1e-6": lambda: (coplanar_faces(), scaled(coplanar_faces(), 1e-6)),
    "grazing mirror floor: moved by +1e5": lambda: (grazing_mirror(), moved(grazing_mirror(), (1e5, 1e5, 1e5))),
    "grazing mirror floor: scaled by 1e-6": lambda: (grazing_mirror(), scaled(grazing_mirror(), 1e-6)),
    "tangent tubes, apex lines: moved by +1e5": lambda: (tangent_tubes(), moved(tangent_tubes(), (1e5, 1e5, 1e5))),
    "tangent tubes, apex lines: scaled by 1e-6": lambda: (tangent_tubes(), scaled(tangent_tubes(), 1e-6)),
    "torus silhouette: span 1e-7, moved by +1e5": lambda: (torus_silhouette(1e-7),
                                                           moved(torus_silhouette(1e-7), (1e5, 1e5, 1e5))),
    "thin torus silhouette: span 1e-7, scaled by 1e-6": lambda: (torus_silhouette(1e-7, 0.05),
                                                                 scaled(torus_silhouette(1e-7, 0.05), 1e-6)),
    "cone apex: span 1e-4": lambda: (without_shadows(cone_apex(1e-4)), cone_apex(1e-4)),
    "cone apex: span 1e-5": lambda: (without_shadows(cone_apex(1e-5)), cone_apex(1e-5)),
    "cone apex: span 1e-6": lambda: (without_shadows(cone_apex(1e-6)), cone_apex(1e-6)),
    "cone apex: span 1e-8": lambda: (without_shadows(cone_apex(1e-8)), cone_apex(1e-8)),
}


def differing_fraction(a: np.ndarray, b: np.ndarray) -> float:
    """Fraction of pixels whose colour differs by more than 1/255 in some channel."""
    return float((np.abs(np.clip(a, 0, 1) - np.clip(b, 0, 1)).max(axis=2) > 1.0 / 255.0).mean())


def measure(name: str, width: int = 80, height: int = 60, backend: str = "numpy") -> float:
    reference, extreme = CASES[name]()
    return differing_fraction(render(reference, width, height, backend=backend).image,
                              render(extreme, width, height, backend=backend).image)


def compare(name: str, width: int, height: int) -> tuple[float, float, int]:
    """The fraction of pixels off the twin on the C core and on the NumPy path, and the number of pixels in
    which the two backends' extreme images differ by more than 1/255."""
    reference, extreme = CASES[name]()
    images = {backend: render(extreme, width, height, backend=backend).image for backend in ("c", "numpy")}
    off = [differing_fraction(render(reference, width, height, backend=backend).image, images[backend])
           for backend in ("c", "numpy")]
    apart = round(differing_fraction(images["c"], images["numpy"]) * width * height)
    return off[0], off[1], apart


def main(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="python -m tracer.extremes", description=(
        "Render each extreme case and its plain twin on both backends and print the table of docs/tracer.md "
        "(\"Rounding error\"): the percentage of pixels off the twin by more than 1/255, per backend, and the "
        "pixels in which the C core's and the NumPy path's extreme images differ."))
    parser.add_argument("width", type=int, nargs="?", default=160, help="image width in pixels (default 160)")
    parser.add_argument("height", type=int, nargs="?", default=120, help="image height in pixels (default 120)")
    parser.add_argument("--case", action="append", choices=list(CASES), metavar="NAME",
                        help="only this case (may be given more than once; default: every case)")
    args = parser.parse_args(argv)
    width, height = args.width, args.height
    print(f"| case ({width}x{height}) | C: pixels differing | NumPy: pixels differing | pixels C != NumPy |")
    print("|---|---|---|---|")
    for name in args.case or CASES:
        c, numpy, apart = compare(name, width, height)
        print(f"| {name} | {100.0 * c:.2f} % | {100.0 * numpy:.2f} % | {apart} |", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
