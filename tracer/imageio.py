"""Writing rendered images: 8-bit files through Pillow, written atomically."""
from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from .atomic import replacing
from .errors import TracerError


ROWS_PER_CHUNK = 256  # converted a band at a time, so a 4K frame needs no full-size temporaries


def to_8bit(image: np.ndarray) -> np.ndarray:
    """Linear colour in [0, 1] (clipped) to uint8, rounding to nearest; NaN becomes 0."""
    out = np.empty(image.shape, dtype=np.uint8)
    for top in range(0, image.shape[0], ROWS_PER_CHUNK):
        band = np.nan_to_num(image[top:top + ROWS_PER_CHUNK], nan=0.0)  # a copy: the film stays untouched
        np.clip(band, 0.0, 1.0, out=band)
        band *= 255.0
        np.rint(band, out=band)
        out[top:top + ROWS_PER_CHUNK] = band
    return out


def save_image(image: np.ndarray, path: str | os.PathLike) -> Path:
    """Save a (height, width, 3) float image; the format follows the file extension (png, bmp, ppm, jpg, tif).

    The file appears complete or not at all: it is written beside the target and renamed over it.
    """
    from PIL import Image

    path = Path(path)
    ext = path.suffix.lower().lstrip(".")
    known = {"png": "PNG", "bmp": "BMP", "ppm": "PPM", "jpg": "JPEG", "jpeg": "JPEG", "tif": "TIFF", "tiff": "TIFF"}
    if ext not in known:
        raise TracerError(f"{path}: unknown image type {path.suffix!r} (use one of .{', .'.join(sorted(known))})")
    # PNG at zlib level 3, not Pillow's 6: twice as fast for a 5 % larger file (measured on a 1280 x 960
    # render: 0.07 s against 0.15 s), which is what a renderer that writes many frames wants.
    options = {"compress_level": 3} if ext == "png" else {}
    with replacing(path) as temp, open(temp, "wb") as handle:
        Image.fromarray(to_8bit(image)).save(handle, format=known[ext], **options)  # (H, W, 3) uint8: RGB
    return path
