"""Writing rendered images: 8-bit files through Pillow, written atomically."""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import numpy as np

from .errors import TracerError


def to_8bit(image: np.ndarray) -> np.ndarray:
    """Linear colour in [0, 1] (clipped) to uint8, rounding to nearest; NaN becomes 0."""
    return np.round(np.clip(np.nan_to_num(image, nan=0.0), 0.0, 1.0) * 255.0).astype(np.uint8)


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
    if not path.parent.is_dir():
        raise TracerError(f"{path}: folder {str(path.parent)!r} does not exist")
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as handle:
            Image.fromarray(to_8bit(image), "RGB").save(handle, format=known[ext])
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise
    return path
