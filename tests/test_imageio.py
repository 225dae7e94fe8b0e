"""Writing images: the 8-bit conversion (NaN, clipping, rounding, banding) and atomic saves."""
import io

import numpy as np
import pytest
from PIL import Image

from tracer import imageio
from tracer.errors import TracerError
from tracer.imageio import band_rows, save_image, to_8bit


def test_to_8bit_clips_rounds_and_zeroes_nan():
    image = np.array([[[np.nan, -0.5, 2.0], [0.3 / 255, 0.7 / 255, 0.25]]], dtype=np.float32)
    out = to_8bit(image)
    assert out.dtype == np.uint8
    assert out.tolist() == [[[0, 0, 255], [0, 1, 64]]]  # to nearest: 0.3 -> 0, 0.7 -> 1, 63.75 -> 64


def test_to_8bit_bands_cover_every_row_and_leave_the_film_alone():
    rng = np.random.default_rng(0)
    image = rng.uniform(-0.2, 1.2, size=(2 * band_rows(np.zeros((1, 5, 3))) + 7, 5, 3)).astype(np.float32)
    before = image.copy()
    out = to_8bit(image)
    expected = np.round(np.clip(image, 0, 1) * 255).astype(np.uint8)
    assert np.array_equal(out, expected)
    assert np.array_equal(image, before)


def test_save_round_trips_and_leaves_no_temporary(tmp_path):
    image = np.zeros((4, 6, 3), dtype=np.float32)
    image[1, 2] = (1.0, 0.5, 0.0)
    path = save_image(image, tmp_path / "out.png")
    with Image.open(path) as saved:
        pixels = np.asarray(saved)
    assert pixels.shape == (4, 6, 3) and pixels[1, 2].tolist() == [255, 128, 0]
    assert [p.name for p in tmp_path.iterdir()] == ["out.png"]


def test_unknown_type_and_missing_folder_are_clear_errors(tmp_path):
    image = np.zeros((2, 2, 3), dtype=np.float32)
    with pytest.raises(TracerError, match="unknown image type"):
        save_image(image, tmp_path / "out.xyz")
    with pytest.raises(TracerError, match="does not exist"):
        save_image(image, tmp_path / "nowhere" / "out.png")
    assert list(tmp_path.iterdir()) == []


def test_float64_colours_get_the_bytes_of_their_float32_film():
    """A tile converted as it is traced (float64 colours) gets what the float32 film converted later got,
    also where the two precisions round to different bytes."""
    rng = np.random.default_rng(1)
    steps = (np.arange(256) + 0.5) / 255  # halfway between two bytes: where float32 rounding decides
    colours = np.concatenate([steps + rng.uniform(-1e-8, 1e-8, steps.size) for _ in range(30)])
    colours = np.concatenate([colours, [np.nan, np.inf, -np.inf, 1e39, -1e39]]).reshape(-1, 1, 1).repeat(3, 2)
    with np.errstate(over="ignore"):
        film = colours.astype(np.float32)
    assert np.array_equal(to_8bit(colours), to_8bit(film))
    assert not np.array_equal(to_8bit(colours), np.rint(np.clip(np.nan_to_num(colours), 0, 1) * 255))


@pytest.mark.parametrize("suffix,options", [(".png", {"compress_level": 3}), (".bmp", {}), (".tif", {}),
                                            (".ppm", {}), (".jpg", {})])
@pytest.mark.parametrize("height,width", [(37, 23), (5, 41), (1, 1)])
def test_banded_writing_gives_the_whole_frame_file_byte_for_byte(tmp_path, monkeypatch, suffix, options, height,
                                                                 width):
    """The file made a band of rows at a time (bands that do not divide the height), from floats or from
    bytes, is the file Pillow writes from the whole 8-bit frame at once."""
    rng = np.random.default_rng(height * width)
    image = rng.uniform(-0.1, 1.1, size=(height, width, 3)).astype(np.float32)
    image[0, 0] = np.nan
    whole = io.BytesIO()
    Image.fromarray(to_8bit(image)).save(whole, format=Image.registered_extensions()[suffix], **options)
    monkeypatch.setattr(imageio, "BAND_VALUES", 4 * width * 3)  # four rows a band
    assert band_rows(image) == 4
    from_floats = save_image(image, tmp_path / f"floats{suffix}").read_bytes()
    from_bytes = save_image(to_8bit(image), tmp_path / f"bytes{suffix}").read_bytes()
    upside_down = to_8bit(image)[::-1]  # a film counted from the bottom, seen through a flipped view
    from_view = save_image(upside_down[::-1], tmp_path / f"view{suffix}").read_bytes()
    assert from_floats == from_bytes == from_view
    if suffix == ".png":  # (written by tracer.png: Pillow's bytes where both deflate with one zlib)
        from test_png import assert_pillows_file
        assert_pillows_file(from_floats, whole.getvalue())
    else:
        assert from_floats == whole.getvalue()


def test_images_of_another_shape_are_refused(tmp_path):
    with pytest.raises(ValueError, match="height, width, 3"):
        save_image(np.zeros((4, 4)), tmp_path / "out.png")
    assert list(tmp_path.iterdir()) == []


@pytest.mark.parametrize("height,width", [(1, 1), (37, 23), (700, 13)])  # (700 x 13 x 3: several pages)
def test_releasing_rows_while_writing_gives_the_same_file(tmp_path, monkeypatch, height, width):
    """An image of new_8bit_image gives its rows back as Pillow takes them (it reads as 0 afterwards); the file
    is the one written from the whole image.  Other arrays, and views of such an image, are left alone."""
    monkeypatch.setattr(imageio, "BAND_VALUES", 5 * width * 3)
    pixels = np.random.default_rng(width).integers(0, 256, size=(height, width, 3), dtype=np.uint8)
    expected = save_image(pixels, tmp_path / "kept.png").read_bytes()
    mapped = imageio.new_8bit_image(height, width)
    mapped[:] = pixels
    assert save_image(mapped, tmp_path / "released.png", release=True).read_bytes() == expected
    if mapped.nbytes >= 2 * 4096:  # whole pages of it were copied: given back, they read as zeros
        assert not mapped[: 4096 // (3 * width)].any()
    plain = pixels.copy()
    save_image(plain, tmp_path / "plain.png", release=True)
    mapped[:] = pixels
    flipped = mapped[::-1]
    assert save_image(flipped, tmp_path / "flipped.png", release=True).read_bytes() == \
        save_image(pixels[::-1], tmp_path / "expected.png").read_bytes()
    assert np.array_equal(plain, pixels) and np.array_equal(mapped, pixels)
