"""Writing rendered images: 8-bit files through Pillow, written atomically.

A render's colours become bytes in one place, :func:`to_8bit`, whether a whole float film is converted when
the file is written or each tile as it is traced (``tracer.render.render(..., eight_bit=True)``): both give
the same bytes.  Nothing here makes a full-size float temporary: colours are converted a band of rows at a
time.  PNG files are written by :mod:`tracer.png` straight from those bands (the bytes Pillow would
write), without Pillow's copy of the pixels or Pillow itself being loaded.  The other formats go through
Pillow, which keeps its own copy of the pixels (4 bytes each: it stores RGB as RGBX); an 8-bit image made
by :func:`new_8bit_image` can give its rows back to the system as they are written
(``save_image(..., release=True)``), so that the two are not held in full at once.
"""
from __future__ import annotations

import contextlib
import importlib.util
import mmap
import os
from pathlib import Path
from typing import Callable, Iterator

import numpy as np

from .atomic import writing
from .errors import TracerError
from .png import PngWriter, write_png

#: Values (rows x columns x channels) converted or judged at a time: a band of 1 MB of float32, whatever the
#: width (a band's temporaries, a few times that, are all a full-size step adds to the peak).
BAND_VALUES = 1 << 18


def band_rows(image: np.ndarray) -> int:
    """How many rows of ``image`` make one band of about BAND_VALUES values."""
    per_row = int(np.prod(image.shape[1:], dtype=np.int64)) or 1
    return max(1, BAND_VALUES // per_row)


def to_8bit(image: np.ndarray, out: np.ndarray | None = None) -> np.ndarray:
    """Linear colour in [0, 1] (clipped) to uint8, rounding to nearest; NaN becomes 0.

    The colours are first rounded to float32, the float film's precision, so that a tile's float64 colours
    converted as they are traced get the bytes the float32 film would have got.  ``out``: where to write
    (for instance a window of an 8-bit film); by default a new array.
    """
    if out is None:
        out = np.empty(image.shape, dtype=np.uint8)
    rows = band_rows(image)
    for top in range(0, image.shape[0], rows):
        with np.errstate(over="ignore"):  # (a float64 colour beyond float32's range is infinite there too)
            band = np.array(image[top:top + rows], dtype=np.float32)  # a copy: the film stays untouched
        np.nan_to_num(band, copy=False, nan=0.0)
        np.clip(band, 0.0, 1.0, out=band)
        band *= 255.0
        np.rint(band, out=band)
        out[top:top + rows] = band
    return out


def new_8bit_image(height: int, width: int) -> np.ndarray:
    """A zeroed (height, width, 3) uint8 image in an anonymous memory mapping of its own (pages are backed
    by memory only once written), whose rows :func:`pillow_image` can release as it copies them."""
    size = height * width * 3
    # Private, not Python's default of shared: released pages of a shared mapping would stay in memory.
    private = {"flags": mmap.MAP_PRIVATE} if hasattr(mmap, "MAP_PRIVATE") else {}
    memory = mmap.mmap(-1, max(size, 1), **private)
    return np.frombuffer(memory, dtype=np.uint8, count=size).reshape(height, width, 3)


def _own_mapping(image: np.ndarray) -> mmap.mmap | None:
    """The mapping that holds exactly ``image``'s pixels, in order (an image of :func:`new_8bit_image`), when
    this system can release its pages; else None."""
    base = image.base
    while isinstance(base, np.ndarray):
        base = base.base
    base = base.obj if isinstance(base, memoryview) else base  # (np.frombuffer keeps a view of the buffer)
    if not (isinstance(base, mmap.mmap) and hasattr(base, "madvise") and image.flags.c_contiguous):
        return None
    return base if np.frombuffer(base, np.uint8, count=1).ctypes.data == image.ctypes.data else None


def bands_8bit(image: np.ndarray, release: bool = False) -> Iterator[np.ndarray]:
    """The rows of a (height, width, 3) image, float colours (converted by :func:`to_8bit`) or uint8, as
    uint8 bands of about BAND_VALUES values, top first.

    ``release``: give the memory of the rows already taken back to the system as the bands go by (an image
    of :func:`new_8bit_image` only; its pixels then read as 0), so that whatever the bands are copied into
    and the image are not held in full at once.
    """
    if image.ndim != 3 or image.shape[2] != 3:  # (checked now, not when the first band is asked for)
        raise ValueError(f"expected a (height, width, 3) image, not an array of shape {image.shape}")
    return _bands(image, _own_mapping(image) if release else None)


def _bands(image: np.ndarray, mapping: mmap.mmap | None) -> Iterator[np.ndarray]:
    height, width = image.shape[:2]
    released = 0  # bytes of the mapping already given back: a whole number of pages
    rows = band_rows(image)
    for top in range(0, height, rows):
        band = image[top:top + rows]
        yield np.ascontiguousarray(band) if band.dtype == np.uint8 else to_8bit(band)
        if mapping is not None:
            taken = min(top + rows, height) * width * 3 // mmap.PAGESIZE * mmap.PAGESIZE
            if taken > released:
                mapping.madvise(mmap.MADV_DONTNEED, released, taken - released)
                released = taken


def pillow_image(image: np.ndarray, release: bool = False):
    """A Pillow RGB image of a (height, width, 3) image, float colours (converted by :func:`to_8bit`) or
    uint8, filled a band of rows at a time: besides Pillow's own pixels (4 bytes each) only a band is made.
    ``release``: as for :func:`bands_8bit` (the peak is then Pillow's pixels, not Pillow's and the image's).
    """
    from PIL import Image

    bands = bands_8bit(image, release)
    height, width = image.shape[:2]
    picture = Image.new("RGB", (width, height), None)  # (not filled: its pages are backed as bands arrive)
    top = 0
    for band in bands:
        picture.paste(Image.fromarray(band), (0, top))
        top += len(band)
    return picture


#: PNG at zlib level 3, not Pillow's 6: twice as fast for a 5 % larger file (measured on a 1280 x 960
#: render: 0.07 s against 0.15 s), which is what a renderer that writes many frames wants.
PNG_LEVEL = 3

#: Pillow's format for each extension an image may be written with.
OUTPUT_FORMATS = {"png": "PNG", "bmp": "BMP", "ppm": "PPM", "jpg": "JPEG", "jpeg": "JPEG", "tif": "TIFF",
                  "tiff": "TIFF"}


def output_format(path: str | os.PathLike) -> str:
    """Pillow's name for the format of an image to write at ``path``, from its extension.  TracerError for
    an extension no writer knows, or for a format that needs Pillow when it is not installed: a renderer
    checks this before tracing, so that neither is found only once the image is done."""
    path = Path(path)
    ext = path.suffix.lower().lstrip(".")
    if ext not in OUTPUT_FORMATS:
        raise TracerError(f"{path}: unknown image type {path.suffix!r} "
                          f"(use one of .{', .'.join(sorted(OUTPUT_FORMATS))})")
    image_format = OUTPUT_FORMATS[ext]
    # (PNG is written without Pillow; the others need it.  Looked for, not imported: loading it is a cost
    # that a render paid before tracing, on top of the scene's memory.)
    if image_format != "PNG" and not _have_pillow():
        raise TracerError(f"{path}: writing {image_format} images needs Pillow (pip install Pillow)")
    return image_format


def _have_pillow() -> bool:
    try:
        return importlib.util.find_spec("PIL") is not None
    except ImportError:  # (a finder that refuses it)
        return False


def save_image(image: np.ndarray, path: str | os.PathLike, release: bool = False) -> Path:
    """Save a (height, width, 3) image, row 0 at the top: float colours (linear, clipped to [0, 1]) or the
    uint8 values of :func:`to_8bit`; the format follows the file extension (png, bmp, ppm, jpg, tif).
    ``release``: as for :func:`bands_8bit` (for an image that is not needed afterwards).

    The file appears complete or not at all (see :mod:`tracer.atomic`).
    """
    path = Path(path)
    image_format = output_format(path)
    with writing(path) as handle:
        if image_format == "PNG":
            bands = bands_8bit(image, release)
            write_png(handle, image.shape[1], image.shape[0], bands, level=PNG_LEVEL)
        else:
            pillow_image(image, release).save(handle, format=image_format)
    return path


@contextlib.contextmanager
def png_rows(path: str | os.PathLike, width: int, height: int) -> Iterator[Callable[[np.ndarray], None]]:
    """Write a PNG file from rows handed over as they are made: the block gets a function taking the next
    uint8 rows (rows, width, 3), top first, all ``height`` of them by the end of the block.  The file is the
    one :func:`save_image` writes from the whole image, and, as there, appears complete or not at all (a
    block that raises leaves no file)."""
    path = Path(path)
    with writing(path) as handle:
        writer = PngWriter(handle, width, height, level=PNG_LEVEL)
        yield writer.add_rows
        writer.finish()
