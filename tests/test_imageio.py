"""Writing images: the 8-bit conversion (NaN, clipping, rounding, banding) and atomic saves."""
import numpy as np
import pytest
from PIL import Image

from tracer.errors import TracerError
from tracer.imageio import ROWS_PER_CHUNK, save_image, to_8bit


def test_to_8bit_clips_rounds_and_zeroes_nan():
    image = np.array([[[np.nan, -0.5, 2.0], [0.3 / 255, 0.7 / 255, 0.25]]], dtype=np.float32)
    out = to_8bit(image)
    assert out.dtype == np.uint8
    assert out.tolist() == [[[0, 0, 255], [0, 1, 64]]]  # to nearest: 0.3 -> 0, 0.7 -> 1, 63.75 -> 64


def test_to_8bit_bands_cover_every_row_and_leave_the_film_alone():
    rng = np.random.default_rng(0)
    image = rng.uniform(-0.2, 1.2, size=(2 * ROWS_PER_CHUNK + 7, 5, 3)).astype(np.float32)
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
