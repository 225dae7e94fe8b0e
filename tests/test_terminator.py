"""The smooth shadow terminator (docs/tracer.md): a 32-segment UV sphere with per-vertex normals, lit from the
side, against the analytic sphere: without the setting its own facets cast stair-stepped shadows along the
terminator; with it the terminator follows the analytic one, on both backends, C = NumPy."""
from __future__ import annotations

import numpy as np
import pytest

import tracer
from helpers import scaled
from tracer.compile import compile_scene
from tracer.model import Camera, Light, Material, MeshData, Scene, Settings, Shape
from tracer.sdl.parser import parse_sdl

#: Surfaces glow a little (emissive) so that the image tells surface from background everywhere.
GLOW = 0.02
MATERIAL = Material(ambient=(0.0, 0.0, 0.0), diffuse=(1.0, 1.0, 1.0), emissive=(GLOW, GLOW, GLOW))


def uv_sphere(segments: int = 32, rings: int = 16) -> MeshData:
    """Blender's default UV sphere: the unit sphere in ``rings`` bands of ``segments`` quads (triangles at the
    poles), each vertex's normal its position (smooth shading)."""
    theta = np.pi * np.arange(1, rings) / rings
    phi = 2 * np.pi * np.arange(segments) / segments
    ring = np.stack([np.outer(np.sin(theta), np.cos(phi)), np.outer(np.sin(theta), np.sin(phi)),
                     np.repeat(np.cos(theta)[:, None], segments, axis=1)], axis=2).reshape(-1, 3)
    vertices = np.concatenate([[[0.0, 0.0, 1.0]], ring, [[0.0, 0.0, -1.0]]])

    def at(i, j):  # vertex of ring i (1 .. rings - 1), segment j
        return 1 + (i - 1) * segments + j % segments

    faces = [(0, at(1, j), at(1, j + 1)) for j in range(segments)]
    faces += [(at(i, j), at(i + 1, j), at(i + 1, j + 1), at(i, j + 1)) for i in range(1, rings - 1)
              for j in range(segments)]
    faces += [(at(rings - 1, j), len(vertices) - 1, at(rings - 1, j + 1)) for j in range(segments)]
    return MeshData(vertices, vertices.copy(), [(f, f) for f in faces], "uv-sphere")


def side_lit(obj: Shape, smooth: bool) -> Scene:
    return Scene(objects=[obj], lights=[Light((-40.0, 0.0, -12.0), (1.0, 1.0, 1.0))],
                 camera=Camera((0.0, -4.0, 0.5), (0.0, 0.0, 0.0), (0.0, 0.0, 1.0), 40.0),
                 settings=Settings(background=(0.0, 0.0, 0.0), global_ambient=(0.0, 0.0, 0.0),
                                   smooth_terminator=smooth))


def terminator_error(backend, smooth: bool) -> tuple[float, float, object]:
    """(largest, mean) pixel error of the mesh against the analytic sphere in the band about the terminator
    (inside both silhouettes), and the mesh's render."""
    w, h = scaled(backend, 160, 160)
    mesh = tracer.render(side_lit(Shape("mesh", np.eye(4), MATERIAL, mesh=uv_sphere(), mesh_file="uv.3vn"), smooth),
                         w, h, backend=backend)
    exact = tracer.render(side_lit(Shape("sphere", np.eye(4), MATERIAL), smooth), w, h, backend=backend)
    a, b = mesh.image[..., 0], exact.image[..., 0]
    surface = (a >= GLOW) & (b >= GLOW)
    inner = surface.copy()  # away from the silhouettes (a polygon's outline is not the circle's)
    for axis in (0, 1):
        for shift in (-2, -1, 1, 2):
            inner &= np.roll(surface, shift, axis=axis)
    band = inner & (b < GLOW + 0.3)  # the analytic Lambert term below 0.3: the terminator and its shadow side
    error = np.abs(a - b)[band]
    return float(error.max()), float(error.mean()), mesh


def test_low_poly_sphere_has_no_stair_stepped_terminator(backend):
    stepped, stepped_mean, _ = terminator_error(backend, smooth=False)
    smooth, smooth_mean, result = terminator_error(backend, smooth=True)
    # (measured at 160 x 160: 0.099 and 0.0049 at most, 0.0012 and 0.00057 on average)
    assert stepped > 0.05  # the facets' own shadows: steps of the lit colour (small there: Lambert is)
    assert smooth < 0.015  # the interpolated normals' own difference only (under 4/255)
    assert smooth < stepped / 5 and smooth_mean < stepped_mean / 1.5
    assert "smooth-terminator" in result.stats()["effects"]


def test_c_and_numpy_agree_on_the_lifted_feelers():
    from tracer import native
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    scene = side_lit(Shape("mesh", np.eye(4), MATERIAL, mesh=uv_sphere(12, 6), mesh_file="uv.3vn"), True)
    scene.objects[0].matrix = np.array([[1.5, 0.3, 0, 0.2], [0, 0.8, 0.1, 0], [0, 0, 1.1, 0.1], [0, 0, 0, 1]])
    c = tracer.render(scene, 64, 64, backend="c")
    n = tracer.render(scene, 64, 64, backend="numpy")
    assert np.array_equal(c.image, n.image)
    assert c.rays.as_dict() == n.rays.as_dict()


def test_the_setting_is_sdl_and_costs_nothing_without_meshes():
    scene = parse_sdl("smoothTerminator 1\nlight 0 5 5 1 1 1\nsphere\nteapot\n")
    assert scene.settings.smooth_terminator
    assert "smooth-terminator" in compile_scene(scene).effects
    assert "smooth-terminator" not in compile_scene(parse_sdl("smoothTerminator 1\nlight 0 5 5 1 1 1\nsphere")).effects
    assert "smooth-terminator" not in compile_scene(parse_sdl("light 0 5 5 1 1 1\nteapot")).effects


def test_usd_keeps_the_setting(tmp_path):
    from tracer.usd import load_usd, save_usd
    scene = parse_sdl("smoothTerminator 1\nlight 0 5 5 1 1 1\nteapot\n")
    save_usd(scene, tmp_path / "t.usda")
    assert load_usd(tmp_path / "t.usda").settings.smooth_terminator
    save_usd(parse_sdl("teapot"), tmp_path / "plain.usda")
    assert not load_usd(tmp_path / "plain.usda").settings.smooth_terminator
