"""Solid textures, noise, image lookups and mappings, Cook–Torrance (textured renders on both backends; the C
core's texture colours point by point: tests/test_native.py)."""
from __future__ import annotations


import numpy as np
import pytest
from PIL import Image

import tracer
from helpers import Light, scene_of, shape, translation
from tracer.compile import compile_scene
from tracer.errors import TracerError
from tracer.sdl.parser import load as load_sdl
from tracer.textures.images import load_image, sample_bilinear
from tracer.textures.mapping import surface_uv
from tracer.textures.noise import noise, turbulence
from tracer.textures.solid import checkerboard, marble, wood
from tracer.backend import make_tracer
from tracer.trace import cook_torrance

rng = np.random.default_rng(7)


@pytest.mark.parametrize("offset", [0.0, -37.0, 1e6])
def test_noise_vanishes_on_lattice_points(offset):
    points = np.floor(rng.uniform(-20, 20, (50, 3))) + offset
    assert np.all(noise(points) == 0.0)


@pytest.mark.parametrize("axis", [0, 1, 2])
@pytest.mark.parametrize("offset", [0.0, -513.0, 1e6])
def test_noise_is_continuous_across_lattice_planes(axis, offset):
    p = rng.uniform(-5, 5, (200, 3)) + offset
    p[:, axis] = np.round(p[:, axis])
    eps = np.zeros(3)
    eps[axis] = 1e-7
    # The gradient is bounded (|grad| < 3), so a jump of more than that times the step would be a seam.
    assert np.abs(noise(p - eps) - noise(p + eps)).max() < 3 * 2e-7 + 1e-9


def test_noise_is_the_same_function_at_negative_and_huge_coordinates():
    p = rng.uniform(0, 1, (100, 3)) * 50
    period = 256.0 * 3907  # the lattice hash repeats every 256 cells; this shift is about 10^6
    assert noise(p - period) == pytest.approx(noise(p), abs=1e-8)
    assert noise(p + period) == pytest.approx(noise(p), abs=1e-8)
    assert np.abs(noise(p + 1.0) - noise(p)).max() > 0.1  # but not trivially periodic
    values = noise(rng.uniform(-1e3, 1e3, (20000, 3)))
    assert np.abs(values).max() <= 1.0 and values.std() > 0.1
    assert np.all(turbulence(p) >= 0)


def test_checkerboard_alternates_and_its_cells_have_the_given_size():
    size = 0.5
    params = (size, 1, 0, 0, 0, 0, 1)
    a = checkerboard(np.array([[0.1, 0.1, 0.1]]), params)[0]
    b = checkerboard(np.array([[0.1 + size, 0.1, 0.1]]), params)[0]
    c = checkerboard(np.array([[0.1 + size, 0.1 + size, 0.1]]), params)[0]
    assert list(a) == [1, 0, 0] and list(b) == [0, 0, 1] and list(c) == [1, 0, 0]
    # Cells are centred on the lattice, so the generic faces at +-1 are not on a boundary.
    face = checkerboard(np.array([[1.0, 0.1, 0.1], [1.0 - 1e-12, 0.1, 0.1]]), params)
    assert np.array_equal(face[0], face[1])


def test_wood_rings_depend_on_distance_from_the_axis():
    spacing = 0.2
    angles = np.linspace(0, 2 * np.pi, 12, endpoint=False)
    ring = np.stack([0.33 * np.cos(angles), 0.33 * np.sin(angles), np.full(12, 0.4)], axis=1)
    colors = wood(ring, (spacing, 0.0))  # no wobble: a perfect ring
    assert np.ptp(colors, axis=0).max() < 1e-12
    line = np.stack([np.linspace(0, 1, 400), np.zeros(400), np.zeros(400)], axis=1)
    shade = wood(line, (spacing, 0.0))[:, 0]
    # The pattern repeats with the ring spacing.
    assert shade[:320] == pytest.approx(wood(line[:320] + [spacing, 0, 0], (spacing, 0.0))[:, 0], abs=1e-9)
    assert np.ptp(shade) > 0.2


def test_marble_mixes_its_two_colours():
    colors = marble(rng.uniform(-2, 2, (5000, 3)), (4.0, 4.0, 5.0, 1, 1, 1, 0, 0, 0))
    assert colors.min() >= 0 and colors.max() <= 1
    assert (colors[:, 0] > 0.9).mean() > 0.3 and (colors[:, 0] < 0.5).mean() > 0.02  # base and veins


def test_texture_moves_with_its_object(backend):
    def color_at_top(dx):
        scene = scene_of(shape("sphere", translation(dx, 0, 0), texture=-3, ambient=(1, 1, 1), diffuse=(0, 0, 0)),
                         global_ambient=(1, 1, 1))
        tr = make_tracer(compile_scene(scene), backend)
        return tr.camera_rays(np.array([[dx + 0.3, 5.0, 0.2]]), np.array([[0.0, -1.0, 0.0]]))[0]

    assert color_at_top(0.0) == pytest.approx(color_at_top(12.75), abs=1e-9)


def test_image_lookup_seam_and_orientation():
    image = np.zeros((4, 8, 3), dtype=np.uint8)  # 8-bit, as load_image keeps pictures
    image[0] = (0, 0, 255)  # bottom row (row 0 is the bottom here)
    image[-1] = (255, 0, 0)
    image[:, 0, 1] = 255  # first column green
    u = np.array([1e-9, 1 - 1e-9])
    both = sample_bilinear(image, u, np.array([0.5, 0.5]), wrap_u=True, wrap_v=False)
    assert both[0] == pytest.approx(both[1], abs=1e-6)  # no seam at u = 0 / 1
    bottom = sample_bilinear(image, np.array([0.5]), np.array([0.0]), False, False)[0]
    top = sample_bilinear(image, np.array([0.5]), np.array([1.0]), False, False)[0]
    assert bottom == pytest.approx((0, 0, 1)) and top == pytest.approx((1, 0, 0))


def test_sphere_mapping_at_the_poles_and_seam():
    poles = np.array([[0, 0, 1.0], [0, 0, -1.0], [1e-300, 0, 1.0]])
    u, v, wrap_u, wrap_v = surface_uv("sphere", poles, np.zeros(3, int))
    assert np.all(np.isfinite(u)) and list(v) == [1.0, 0.0, 1.0] and wrap_u and not wrap_v
    seam = np.array([[1.0, -1e-12, 0.0], [1.0, 1e-12, 0.0]])
    u, _, _, _ = surface_uv("sphere", seam, np.zeros(2, int))
    assert u[0] == pytest.approx(1.0) and u[1] == pytest.approx(0.0)


def test_cube_faces_map_unmirrored_from_outside():
    for face, (point, right) in {1: ((1, 0, 0), (0, 0, -1)), 5: ((0, 0, 1), (1, 0, 0)),
                                 0: ((-1, 0, 0), (0, 0, 1)), 3: ((0, 1, 0), (1, 0, 0))}.items():
        p = np.array([point, np.add(point, np.multiply(right, 0.1))], dtype=float)
        u, v, _, _ = surface_uv("cube", p, np.array([face, face]))
        assert u[1] > u[0] and v[1] == pytest.approx(v[0])


def test_image_texture_renders_on_a_square(tmp_path, backend):
    picture = np.zeros((2, 2, 3), dtype=np.uint8)
    picture[:, 0] = (255, 0, 0)  # left column red, right column blue
    picture[:, 1] = (0, 0, 255)
    Image.fromarray(picture).save(tmp_path / "lr.png")
    scene = tracer.parse_sdl("""camera 0 0 5 0 0 0 0 1 0 30
        globalAmbient 1 1 1 background 0 0 0 makePixmap 3 lr.png
        ambient 1 1 1 diffuse 0 0 0 texture 3 square""", base_dir=tmp_path)
    result = tracer.render(scene, 40, 40, backend=backend)
    assert result.backend == backend
    image = result.image
    # The square spans about columns 5..35; beyond the outer texel centres (u < 1/4, u > 3/4) the
    # bilinear lookup clamps to pure colours, between them it blends.
    assert image[20, 8] == pytest.approx((1, 0, 0), abs=1e-6)
    assert image[20, 32] == pytest.approx((0, 0, 1), abs=1e-6)
    middle = image[20, 20]
    assert 0.3 < middle[0] < 0.7 and middle[0] + middle[2] == pytest.approx(1.0)


def test_missing_pixmap_is_a_clear_error():
    scene = scene_of(shape("sphere", texture=4))
    with pytest.raises(TracerError, match="makePixmap 4"):
        compile_scene(scene)


def test_a_file_that_is_no_picture_is_named_at_its_makepixmap(tmp_path):
    (tmp_path / "binary.sdl").write_bytes(bytes(range(256)) * 2)
    scene_file = tmp_path / "badpix.sdl"
    scene_file.write_text("light 2 3 4 1 1 1\n\nmakePixmap 1 binary.sdl\ntexture 1\nsphere\n")
    scene = load_sdl(scene_file)
    with pytest.raises(TracerError) as raised:
        compile_scene(scene)
    message = str(raised.value)
    assert message.startswith(f"{scene_file}:3:1: makePixmap 1: ")  # the makePixmap, not the sphere on line 5
    assert message.endswith("binary.sdl: not a picture textures may use (PNG, JPEG, BMP, PPM, TIFF)")
    assert " object at 0x" not in message


def test_cook_torrance_at_normal_incidence():
    # Light and eye along the normal: h = n, D = 1 / (pi m^2), G = 1, F = F0, so CT = F0 D / 4.
    n = np.array([[0.0, 0.0, 1.0]])
    f0, m = 0.3, 0.4
    value = cook_torrance(n, n, n, np.array([[f0, f0, f0]]), np.array([m]))
    assert value[0] == pytest.approx([f0 / (np.pi * m * m) / 4] * 3)
    # Rougher surfaces spread the highlight: lower peak.
    assert cook_torrance(n, n, n, np.array([[f0] * 3]), np.array([0.8]))[0, 0] < value[0, 0]


def test_textured_scene_is_live_only_when_used():
    plain = compile_scene(scene_of(shape("sphere"), lights=[Light((1, 2, 3), (1, 1, 1))]))
    assert "textures" not in plain.effects and plain.textures is None
    textured = compile_scene(scene_of(shape("sphere", texture=-1), lights=[Light((1, 2, 3), (1, 1, 1))]))
    assert "textures" in textured.effects


def test_fallback_decoder_floats_become_the_files_bytes(monkeypatch, tmp_path):
    # Where Pillow cannot be imported (Blender's Python) a fallback decoder gives floats in [0, 1]; they are
    # kept as the same 8 bits Pillow would have given.
    import sys

    from tracer.textures import images

    texels = np.random.default_rng(5).integers(0, 256, (7, 9, 3), dtype=np.uint8)
    monkeypatch.setitem(sys.modules, "PIL", None)  # import PIL now fails
    monkeypatch.setattr(images, "_fallback_decoder", lambda path: (texels / 255.0).astype(np.float32))
    loaded = images.load_image(tmp_path / "any.png")
    assert loaded.dtype == np.uint8 and np.array_equal(loaded, texels)


def test_only_the_five_picture_formats_are_read(tmp_path):
    """A picture Pillow reads in a format textures do not use (GIF, here) is refused before it is decoded."""
    Image.new("RGB", (4, 4), (10, 20, 30)).save(tmp_path / "swatch.gif")
    with pytest.raises(TracerError, match=r"swatch\.gif: not a picture textures may use \(PNG, JPEG, BMP, PPM, TIFF\)"):
        load_image(tmp_path / "swatch.gif")
    for fmt in ("png", "jpg", "bmp", "ppm", "tif"):
        Image.new("RGB", (4, 4), (10, 20, 30)).save(tmp_path / f"swatch.{fmt}")
        assert load_image(tmp_path / f"swatch.{fmt}").shape == (4, 4, 3)


def test_stored_pixels_the_file_cannot_hold_are_refused_before_decoding(tmp_path):
    import struct

    path = tmp_path / "wide.bmp"
    Image.new("RGB", (4, 1)).save(path)
    data = bytearray(path.read_bytes())
    struct.pack_into("<i", data, 18, 1 << 24)  # 16,777,216 x 1 pixels in a 66-byte file
    path.write_bytes(bytes(data))
    with pytest.raises(TracerError, match=r"wide\.bmp: the picture declares 16777216 x 1 pixels, which need .* bytes; the file holds 66"):
        load_image(path)
