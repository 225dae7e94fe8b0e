"""Every bundled scene reads cleanly, renders (on both backends), and shows its objects where they are."""
from __future__ import annotations

import re
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

import tracer
from tracer.camera import CameraFrame, scene_camera
from tracer.compile import compile_scene
from tracer.model import Shape
from helpers import scaled

SCENES = sorted((Path(__file__).parent.parent / "scenes").glob("*.sdl"))
WIDTH, HEIGHT = 160, 120  # (the NumPy variants render half of that)


def test_there_are_scenes_for_every_feature():
    kinds, effects = set(), set()
    for path in SCENES:
        scene = tracer.load(path)
        kinds |= {s.kind for s in scene.shapes()}
        effects |= compile_scene(scene).effects
        if any(s.groups for s in scene.shapes()):
            effects.add("def/use")
    assert {"sphere", "cube", "square", "plane", "taperedCylinder", "cylinder", "cone", "torus", "teapot",
            "mesh", "tetrahedron", "octahedron", "dodecahedron", "icosahedron", "buckyball", "diamond"} <= kinds
    assert {"shadows", "reflection", "refraction", "csg", "def/use"} <= effects


def test_scenes_use_every_sdl_keyword():
    from tracer.sdl.parser import EXTENSION_KEYWORDS, KEYWORDS
    from tracer.shapes import REGISTRY

    # (the SDL extensions' keywords are not the book's: their own tests render them)
    words = {e.keyword for e in REGISTRY if e.extension} | EXTENSION_KEYWORDS
    for path in SCENES:
        text = "\n".join(line.split("!")[0] for line in path.read_text().splitlines())  # without comments
        words |= set(re.findall(r"[A-Za-z][A-Za-z0-9]*", text))
    assert sorted(KEYWORDS - words) == []


def _project(frame: CameraFrame, point, width: int, height: int):
    rel = np.asarray(point) - frame.eye
    depth = -np.dot(rel, frame.n)
    x = np.dot(rel, frame.u) / depth / frame.half_width
    y = np.dot(rel, frame.v) / depth / frame.half_height
    col = int((x + 1) / 2 * width)
    row_from_bottom = int((y + 1) / 2 * height)
    return depth, row_from_bottom, col


def _dominant(color) -> int | None:
    """The clearly strongest channel of a colour, if it has one."""
    c = np.asarray(color)
    order = np.argsort(c)
    return int(order[-1]) if c[order[-1]] > 1.2 * c[order[-2]] + 0.02 else None


@pytest.mark.parametrize("path", SCENES, ids=lambda p: p.stem)
def test_scene_renders_objects_in_their_colours(path, backend):
    scene = tracer.load(path)
    assert scene.warnings == []
    width, height = scaled(backend, WIDTH, HEIGHT)
    result = tracer.render(scene, width, height, backend=backend)
    image = result.image
    assert result.backend == backend
    assert image.shape == (height, width, 3) and np.all(np.isfinite(image))
    compiled = compile_scene(scene)
    frame = CameraFrame.from_camera(scene_camera(scene, compiled, width / height), width / height)
    checked = 0
    for obj in compiled.objects:
        if not obj.bounded:
            continue
        leaves = {id(p.shape) for p in (obj.leaves() if hasattr(obj, "leaves") else [obj])}
        # Look at the centre, or near it where the centre is hollow (a drilled CSG object).
        for offset in [(0, 0)] + [(a * 0.3, b * 0.3) for a in (-1, 1) for b in (-1, 1)]:
            aim = obj.center + obj.radius * (offset[0] * frame.u + offset[1] * frame.v)
            depth, row, col = _project(frame, aim, width, height)
            if depth <= 0 or not (0 <= row < height and 0 <= col < width):
                continue
            # The pixel's ray must meet this very object first.
            direction = frame.directions(np.array([row]), np.array([col]), height, width)[0]
            first = tracer.hits(compiled, frame.eye, direction)
            if first and id(first[0].shape) in leaves:
                break
        else:
            continue
        mat = first[0].shape.material
        hue = _dominant(mat.diffuse)
        if hue is None or mat.reflectivity > 0 or mat.transparency > 0 or mat.texture:
            continue
        pixel = image[height - 1 - row, col]
        assert _dominant(pixel) == hue, f"{first[0].shape.kind} at pixel {(row, col)} is {pixel}, diffuse {mat.diffuse}"
        checked += 1
    # In the glass scene the coloured blocks stand behind the glass: only the floor is in plain view.
    # Every object of the textures scene is textured: test_textures_scene_shows_its_textures checks it.
    expected = {"glass": 1, "textures": 0}.get(path.stem, 3)
    assert checked >= expected, "too few objects could be checked"


def test_lecture_scene_has_its_cylinders_spheres_three_cones_and_two_lights():
    scene = tracer.load(Path(__file__).parent.parent / "scenes" / "lecture.sdl")
    kinds = [s.kind for s in scene.shapes()]
    assert kinds.count("cone") == 3 and kinds.count("cylinder") >= 2 and kinds.count("sphere") >= 2
    assert len(scene.lights) == 2


def test_jack_is_built_with_macros():
    scene = tracer.load(Path(__file__).parent.parent / "scenes" / "jack.sdl")
    grouped = [s for s in scene.shapes() if "jack" in s.groups]
    assert len(grouped) == 2 * 10  # two jacks, each three arms of three parts and a hub
    assert all(isinstance(s, Shape) for s in grouped)


def test_glass_scene_refracts(backend):
    scene = tracer.load(Path(__file__).parent.parent / "scenes" / "glass.sdl")
    with_glass = tracer.render(scene, *scaled(backend, 80, 60), backend=backend)
    assert with_glass.rays.refraction > 0 and with_glass.rays.reflection > 0
    for shape in scene.shapes():
        if shape.material.transparency > 0:
            shape.material = replace(shape.material, transparency=0.0)
    opaque = tracer.render(scene, *scaled(backend, 80, 60), backend=backend)
    assert opaque.rays.refraction == 0
    changed = np.abs(with_glass.image - opaque.image).max(axis=2) > 0.05
    assert changed.mean() > 0.05  # the glass objects look different from opaque ones


def test_textures_scene_shows_its_textures(backend):
    scene = tracer.load(Path(__file__).parent.parent / "scenes" / "textures.sdl")
    size = scaled(backend, 160, 120)
    textured = tracer.render(scene, *size, backend=backend).image
    for shape in scene.shapes():
        shape.material = replace(shape.material, texture=0)
    plain = tracer.render(scene, *size, backend=backend).image
    changed = np.abs(textured - plain).max(axis=2) > 0.05
    assert changed.mean() > 0.3
    # The checkerboard floor alternates light and dark along the bottom row.
    row = textured[-1, :, 0]
    assert (row > 0.6).mean() > 0.2 and (row < 0.3).mean() > 0.2
    # The brick wall is red with light mortar.
    h, w = textured.shape[:2]
    wall = textured[h * 5 // 120:h * 25 // 120, w // 4:w * 3 // 4]  # (rows 5-25, columns 40-120 at 160 x 120)
    red = (wall[..., 0] > 1.5 * wall[..., 1]).mean()
    assert 0.5 < red < 0.95
