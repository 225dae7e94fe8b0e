"""Texture images read by Blender's own image loading, for the tracer inside Blender.

Blender's Python ships without Pillow, which the tracer uses to read ``makePixmap`` files outside Blender;
inside Blender the engine registers :func:`decode` as the tracer's fallback decoder
(``tracer.textures.images.set_fallback_decoder``), so every format Blender reads works there.

Values are the file's own, as Pillow gives them: 8-bit samples over 255, no colour-space conversion (a
float file, such as a 16-bit PNG, is read as Non-Color so that Blender does not linearise it).
"""
from __future__ import annotations

import os
from pathlib import Path

import bpy
import numpy as np

from .tracer import errors
from .tracer.textures import images as limits


def _existing(path: Path):
    """An image datablock already showing this file (the importer puts each material's image in one)."""
    wanted = os.path.normcase(os.path.abspath(path))
    for image in bpy.data.images:
        if image.source == "FILE" and not image.packed_file and image.filepath and \
                os.path.normcase(os.path.abspath(bpy.path.abspath(image.filepath, library=image.library))) == wanted:
            return image
    return None


def decode(path: Path) -> np.ndarray:
    """(height, width, 3) float32 in [0, 1], row 0 at the bottom (Blender's order too)."""
    path = Path(path)
    if not path.is_file():
        raise errors.TracerError(f"{path}: texture image not found")
    image = _existing(path)
    if image is not None and image.is_float and image.colorspace_settings.name != "Non-Color":
        image = None  # its pixels are linearised: read the file again rather than change the user's image
    loaded = image is None
    if loaded:
        try:
            image = bpy.data.images.load(str(path), check_existing=False)
        except RuntimeError as err:
            raise errors.TracerError(f"{path}: cannot read texture image "
                                     f"({str(err).strip().splitlines()[-1]})") from None
    try:
        if loaded and image.is_float:
            image.colorspace_settings.name = "Non-Color"  # the stored values, not linearised ones
        width, height = image.size
        channels = image.channels
        if width * height == 0 or channels == 0:
            raise errors.TracerError(f"{path}: cannot read texture image (Blender could not decode it)")
        if width * height > limits.MAX_TEXELS:
            raise errors.TracerError(f"{path}: image of {width}x{height} pixels is too large for a texture")
        pixels = np.empty(width * height * channels, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        if loaded:
            bpy.data.images.remove(image)
    pixels = pixels.reshape(height, width, channels)
    rgb = pixels[..., :3] if channels >= 3 else np.repeat(pixels[..., :1], 3, axis=2)
    return np.ascontiguousarray(rgb)


def register() -> None:
    limits.set_fallback_decoder(decode)


def unregister() -> None:
    limits.set_fallback_decoder(None)
