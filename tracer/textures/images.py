"""Image textures: loading with Pillow (BMP as in the book, PNG, JPEG, ...) and bilinear lookup.

Texel centres sit at ((i + 1/2) / width, (j + 1/2) / height); v = 0 is the bottom row of the picture.  Along a
wrapping direction the last texel blends into the first, so a sphere or cylinder shows no seam at u = 0 / 1;
along a clamped direction lookups stop at the edge texels, so the poles of a sphere stay finite.
"""
from __future__ import annotations

from pathlib import Path
from typing import Callable, Optional

import numpy as np

from ..errors import TracerError

#: Largest picture accepted, in pixels (a 16k x 16k RGB float image is 3 GiB).
MAX_TEXELS = 64 * 1024 * 1024


#: ``decode(path) -> (height, width, 3) floats in [0, 1], row 0 at the bottom`` (a TracerError for an unreadable
#: file), used where Pillow cannot be imported: the Blender add-on sets Blender's own image loading, since
#: Blender's Python ships without Pillow.
_fallback_decoder: Optional[Callable[[Path], np.ndarray]] = None


def set_fallback_decoder(decode: Optional[Callable[[Path], np.ndarray]]) -> None:
    """Read textures with ``decode`` when Pillow is not importable (None: no fallback)."""
    global _fallback_decoder
    _fallback_decoder = decode


def load_image(path: str | Path) -> np.ndarray:
    """(height, width, 3) float64 in [0, 1], row 0 at the *bottom*."""
    path = Path(path)
    try:
        from PIL import Image, UnidentifiedImageError
    except ImportError:
        if _fallback_decoder is None:
            raise TracerError(f"{path}: reading texture images needs Pillow (pip install Pillow)") from None
        return np.asarray(_fallback_decoder(path), dtype=np.float64)

    try:
        with Image.open(path) as picture:
            if picture.width * picture.height > MAX_TEXELS:
                raise TracerError(f"{path}: image of {picture.width}x{picture.height} pixels is too large for a texture")
            rgb = np.asarray(picture.convert("RGB"), dtype=np.float64) / 255.0
    except FileNotFoundError:
        raise TracerError(f"{path}: texture image not found") from None
    except (UnidentifiedImageError, OSError) as err:
        raise TracerError(f"{path}: cannot read texture image ({err})") from None
    return rgb[::-1].copy()


def sample_bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray, wrap_u: bool, wrap_v: bool) -> np.ndarray:
    """Colours (N, 3) at texture coordinates u, v."""
    height, width = image.shape[:2]

    def axis(coord, size, wrap):
        x = coord * size - 0.5  # in texel-centre units
        x0 = np.floor(x)
        frac = x - x0
        i0 = x0.astype(np.int64)
        i1 = i0 + 1
        if wrap:
            i0, i1 = np.mod(i0, size), np.mod(i1, size)
        else:
            i0, i1 = np.clip(i0, 0, size - 1), np.clip(i1, 0, size - 1)
        return i0, i1, frac

    u = np.where(np.isfinite(u), u, 0.0)
    v = np.where(np.isfinite(v), v, 0.0)
    x0, x1, fx = axis(u, width, wrap_u)
    y0, y1, fy = axis(v, height, wrap_v)
    top = image[y1, x0] * (1 - fx)[:, None] + image[y1, x1] * fx[:, None]
    bottom = image[y0, x0] * (1 - fx)[:, None] + image[y0, x1] * fx[:, None]
    return bottom * (1 - fy)[:, None] + top * fy[:, None]
