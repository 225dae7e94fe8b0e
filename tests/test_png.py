"""The PNG writer gives Pillow's bytes: same filters, same deflate stream, same IDAT chunks."""
import io
import zlib

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from PIL import Image, features

from tracer.png import idat_bytes, write_png

#: Pillow's file bytes are to be expected where Pillow deflates with the zlib Python's zlib module uses
#: (its Linux wheels); a Pillow on another deflate (zlib-ng) gives other bytes for the same rows.
SAME_ZLIB = features.version("zlib") == zlib.ZLIB_RUNTIME_VERSION


def assert_pillows_file(ours: bytes, pillows: bytes, *context) -> None:
    if SAME_ZLIB:
        assert ours == pillows, context
    else:
        with Image.open(io.BytesIO(ours)) as a, Image.open(io.BytesIO(pillows)) as b:
            assert a.mode == b.mode and a.size == b.size and a.tobytes() == b.tobytes(), context


def pillow_png(pixels: np.ndarray, level: int) -> bytes:
    out = io.BytesIO()
    Image.fromarray(pixels).save(out, format="PNG", compress_level=level)
    return out.getvalue()


def our_png(pixels: np.ndarray, level: int, rows_per_band: int) -> bytes:
    out = io.BytesIO()
    bands = [pixels[top:top + rows_per_band] for top in range(0, len(pixels), rows_per_band)]
    write_png(out, pixels.shape[1], pixels.shape[0], bands, level)
    return out.getvalue()


def chunk_sizes(png: bytes) -> list[tuple[bytes, int]]:
    sizes, at = [], 8
    while at < len(png):
        size = int.from_bytes(png[at:at + 4], "big")
        sizes.append((png[at + 4:at + 8], size))
        at += 12 + size
    return sizes


def images():
    rng = np.random.default_rng(7)
    ramp = np.add.outer(np.arange(120), np.arange(90))
    yield "noise", rng.integers(0, 256, (150, 170, 3), dtype=np.uint8)  # several IDAT chunks
    yield "flat", np.full((30, 40, 3), 200, np.uint8)
    yield "black", np.zeros((3, 5, 3), np.uint8)
    yield "pixel", np.array([[[1, 2, 3]]], np.uint8)
    yield "ramps", (ramp[..., None] * np.array([1, 2, 3]) % 256).astype(np.uint8)
    yield "smooth", np.clip(ramp[..., None] + rng.normal(0, 2, (120, 90, 3)), 0, 255).astype(np.uint8)
    # Bytes where every filter ties, and the byte 128 (whose cost, as a signed byte, is 128).
    yield "ties", np.tile(np.array([[[128, 0, 128]]], np.uint8), (6, 7, 1))


@pytest.mark.parametrize("name,pixels", list(images()))
@pytest.mark.parametrize("level", [1, 3, 6, 9])
def test_the_file_is_pillows_byte_for_byte(name, pixels, level):
    expected = pillow_png(pixels, level)
    for rows_per_band in (1, 7, len(pixels)):
        assert_pillows_file(our_png(pixels, level, rows_per_band), expected, name, level, rows_per_band)


def test_idat_chunks_are_pillows_buffer_size_also_for_images_wider_than_16384():
    pixels = np.random.default_rng(3).integers(0, 256, (2, 17000, 3), dtype=np.uint8)
    png = our_png(pixels, 3, 1)
    assert_pillows_file(png, pillow_png(pixels, 3))
    idats = [size for kind, size in chunk_sizes(png) if kind == b"IDAT"]
    assert idat_bytes(17000) == 68000 and idats[:-1] == [68000] * (len(idats) - 1) and len(idats) > 1


@settings(max_examples=40, deadline=None)
@given(st.integers(1, 9), st.integers(1, 40), st.integers(1, 12), st.integers(0, 2**32 - 1),
       st.sampled_from([2, 16, 256]))
def test_any_small_image_matches(height, width, rows_per_band, seed, levels):
    """Random images with few distinct values (where the filters' costs often tie) or many."""
    pixels = np.random.default_rng(seed).integers(0, levels, (height, width, 3), dtype=np.uint8)
    assert_pillows_file(our_png(pixels, 3, rows_per_band), pillow_png(pixels, 3))


def test_bad_calls_are_refused():
    pixels = np.zeros((4, 4, 3), np.uint8)
    with pytest.raises(ValueError, match="1 to 9"):
        write_png(io.BytesIO(), 4, 4, [pixels], level=0)
    with pytest.raises(ValueError, match="given 2"):
        write_png(io.BytesIO(), 4, 4, [pixels[:2]])
