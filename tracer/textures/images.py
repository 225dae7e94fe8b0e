"""Image textures: loading with Pillow (BMP as in the book, PNG, JPEG, ...) and bilinear lookup.

Texel centres sit at ((i + 1/2) / width, (j + 1/2) / height); v = 0 is the bottom row of the picture.  Along a
wrapping direction the last texel blends into the first, so a sphere or cylinder shows no seam at u = 0 / 1;
along a clamped direction lookups stop at the edge texels, so the poles of a sphere stay finite.

Pictures are kept as 8-bit RGB, as the files hold them: a texel's value is its byte / 255, computed only for
the texels a lookup reads (the C core does the same), so a picture costs 3 bytes per texel and no float
copy of it is ever made.  The size a file declares is checked before anything is decoded.
"""
from __future__ import annotations

import os
import warnings
from pathlib import Path
from typing import Callable, Optional

import numpy as np

from ..diagnostics import held_stderr
from ..errors import TracerError, TracerWarning
from ..userfiles import open_regular, shown_name

#: The picture formats textures may use (Pillow's names): what a user of SDL textures needs.  Pillow reads
#: some forty more, whose decoders were never meant for files from anywhere (a 128-byte DDS that declares
#: 4096 x 16384 pixels took minutes): those are refused before anything is decoded.
FORMATS = ("PNG", "JPEG", "BMP", "PPM", "TIFF")

#: Largest picture accepted, in pixels: 8192 x 8192 (192 MiB as 8-bit RGB).  Below Pillow's own
#: decompression-bomb threshold, so that check never speaks first.
MAX_TEXELS = 8192 * 8192


class ImageWarning(TracerWarning):
    """Something odd in a picture that did not stop reading it; the message names the file."""


#: ``decode(path) -> (height, width, 3) floats in [0, 1], row 0 at the bottom`` (a TracerError for an unreadable
#: file), used where Pillow cannot be imported: the Blender add-on sets Blender's own image loading, since
#: Blender's Python ships without Pillow.
_fallback_decoder: Optional[Callable[[Path], np.ndarray]] = None


def set_fallback_decoder(decode: Optional[Callable[[Path], np.ndarray]]) -> None:
    """Read textures with ``decode`` when Pillow is not importable (None: no fallback)."""
    global _fallback_decoder
    _fallback_decoder = decode


def load_image(path: str | Path) -> np.ndarray:
    """(height, width, 3) uint8, row 0 at the *bottom*.  TracerError naming the file for anything that
    cannot be read; what the decoder warns about becomes an :class:`ImageWarning` naming the file."""
    path = Path(path)
    name = shown_name(str(path))
    try:
        from PIL import Image
    except ImportError:
        if _fallback_decoder is None:
            raise TracerError(f"{name}: reading texture images needs Pillow (pip install Pillow)") from None
        return _from_fallback(name, _fallback_decoder(path))
    printed: list[str] = []
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        try:
            with held_stderr() as printed:  # (libtiff and libjpeg print their complaints)
                texels = _decode(Image, path, name)
        except FileNotFoundError:
            raise TracerError(f"{name}: texture image not found") from None
        except Image.DecompressionBombError:
            raise TracerError(f"{name}: image too large for a texture (more than {MAX_TEXELS} pixels)") from None
        except TracerError:
            raise
        except Image.UnidentifiedImageError:  # (its own message names the file object Pillow was given)
            raise TracerError(f"{name}: not a picture textures may use ({', '.join(FORMATS)})") from None
        except MemoryError:
            raise TracerError(f"{name}: not enough memory to decode the picture") from None
        except OSError as err:
            problem = _decoder_said(printed) or err.strerror or str(err)
            raise TracerError(f"{name}: cannot read texture image ({problem})") from None
        # A hostile file can make a decoder fail in many ways besides OSError (ValueError from a PPM header,
        # SyntaxError from some plugins, struct.error, EOFError, IndexError...): each is this file's fault.
        except Exception as err:  # noqa: BLE001
            raise TracerError(f"{name}: cannot read texture image ({type(err).__name__}: {err})") from None
    for line in dict.fromkeys(printed):  # (a decoder's complaint about a picture it read all the same)
        warnings.warn(ImageWarning(f"{name}: the decoder says: {line}"), stacklevel=2)
    for record in caught:
        if issubclass(record.category, Image.DecompressionBombWarning):
            continue  # the size check above has already refused such a picture
        warnings.warn(ImageWarning(f"{name}: {record.message}"), stacklevel=2)
    return texels


def _decode(Image, path: Path, name: str) -> np.ndarray:
    """The picture's texels (see load_image), its format and size checked before anything is decoded."""
    with open_regular(path, "texture image") as handle, \
            Image.open(_ReadsWithinFile(handle), formats=FORMATS) as picture:
        width, height = picture.size  # from the header: nothing decoded yet
        _check_size(name, width, height)
        _check_stored_size(name, picture, handle)
        rgb = picture.convert("RGB").transpose(Image.Transpose.FLIP_TOP_BOTTOM)
        return np.asarray(rgb, dtype=np.uint8)


class _ReadsWithinFile:
    """A picture file whose ``read(n)`` never asks for more bytes than are left in it.

    Pillow's PNG reader reads a chunk's declared length in one call, and a damaged length (4 GB) would
    allocate that much before finding the file short: a MemoryError under a memory limit, a 4 GB mapping
    without one.  Everything else is the file's own."""

    def __init__(self, handle):
        self._handle = handle
        self._size = os.fstat(handle.fileno()).st_size

    def read(self, size: Optional[int] = -1) -> bytes:
        left = max(0, self._size - self._handle.tell())
        return self._handle.read(left if size is None or size < 0 else min(size, left))

    def __getattr__(self, name):
        return getattr(self._handle, name)


def _from_fallback(name: str, rgb) -> np.ndarray:
    """The fallback decoder's floats in [0, 1] as 8-bit texels (an 8-bit file's bytes come back exactly)."""
    rgb = np.asarray(rgb)
    if rgb.ndim != 3 or rgb.shape[2] != 3:
        raise TracerError(f"{name}: cannot read texture image (decoded to shape {rgb.shape})")
    _check_size(name, rgb.shape[1], rgb.shape[0])
    texels = np.empty(rgb.shape, dtype=np.uint8)
    for top in range(0, rgb.shape[0], 256):  # a band at a time: no float copy of the whole picture
        band = np.nan_to_num(rgb[top:top + 256], nan=0.0).astype(np.float32)
        np.clip(band, 0.0, 1.0, out=band)
        texels[top:top + 256] = np.rint(band * 255.0)
    return texels


def _check_stored_size(name: str, picture, handle) -> None:
    """Refuse a picture whose stored pixels (the parts Pillow reads uncompressed) need more bytes than the file
    holds, before anything is decoded: Pillow makes the whole picture first, and a 70-byte BMP that declares
    67108864 x 1 pixels asked for a quarter of a gigabyte.  (At least one bit a pixel, or the row size the
    header gives.)"""
    size = os.fstat(handle.fileno()).st_size
    for tile in picture.tile:
        x0, y0, x1, y1 = tile[1]
        args = tile[3] if isinstance(tile[3], tuple) else (tile[3],)
        stride = args[1] if tile[0] == "raw" and len(args) > 1 and args[1] else (x1 - x0 + 7) // 8
        needed = tile[2] + (y1 - y0) * abs(stride) if tile[0] == "raw" else tile[2]
        if needed > size:
            raise TracerError(f"{name}: the picture declares {picture.size[0]} x {picture.size[1]} pixels, which "
                              f"need {needed:,} bytes; the file holds {size:,}")


def _decoder_said(printed: list[str]) -> str:
    """What a C decoder (libtiff, libjpeg) printed when it failed, as one clause: its first complaint."""
    return printed[0] if printed else ""


def _check_size(name: str, width: int, height: int) -> None:
    if width < 1 or height < 1:
        raise TracerError(f"{name}: image of {width}x{height} pixels has no pixels")
    if width * height > MAX_TEXELS:
        raise TracerError(f"{name}: image of {width}x{height} pixels is too large for a texture "
                          f"(at most {MAX_TEXELS} pixels)")


def sample_bilinear(image: np.ndarray, u: np.ndarray, v: np.ndarray, wrap_u: bool, wrap_v: bool) -> np.ndarray:
    """Colours (N, 3) at texture coordinates u, v of an 8-bit picture from :func:`load_image`."""
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

    def texels(rows, cols):
        return image[rows, cols] / 255.0

    u = np.where(np.isfinite(u), u, 0.0)
    v = np.where(np.isfinite(v), v, 0.0)
    x0, x1, fx = axis(u, width, wrap_u)
    y0, y1, fy = axis(v, height, wrap_v)
    top = texels(y1, x0) * (1 - fx)[:, None] + texels(y1, x1) * fx[:, None]
    bottom = texels(y0, x0) * (1 - fx)[:, None] + texels(y0, x1) * fx[:, None]
    return bottom * (1 - fy)[:, None] + top * fy[:, None]
