"""Texture images read by Blender's own image loading, for the tracer inside Blender.

Blender's Python ships without Pillow, which the tracer uses to read ``makePixmap`` files outside Blender;
inside Blender the engine registers :func:`decode` as the tracer's fallback decoder
(``tracer.textures.images.set_fallback_decoder``), so every format Blender reads works there.

Values are the file's own, as Pillow gives them: 8-bit samples over 255, no colour-space conversion (a
float file, such as a 16-bit PNG, is read as Non-Color so that Blender does not linearise it).

Each picture is decoded once per content (:data:`_decoded`): loading and removing a Blender image is a change
to the file's data, which Blender reports to a Rendered viewport as a scene change, so decoding on every
rebuild made the viewport start again for ever (Blender 3.4, scenes/textures.sdl).
"""
from __future__ import annotations

import hashlib
import os
from pathlib import Path

import bpy
import numpy as np

from .tracer import errors
from .tracer.imageio import save_image
from .tracer.textures import images as limits


def _existing(path: Path):
    """An image datablock already showing this file (the importer puts each material's image in one)."""
    wanted = os.path.normcase(os.path.abspath(path))
    for image in bpy.data.images:
        if image.source == "FILE" and not image.packed_file and image.filepath and \
                os.path.normcase(os.path.abspath(bpy.path.abspath(image.filepath, library=image.library))) == wanted:
            return image
    return None


#: Pictures decoded so far: file content digest -> (height, width, 3) float32, read-only.
_decoded: dict[bytes, np.ndarray] = {}
#: path -> ((size, modification time), content digest): a file is read again only after it changed.
_digests: dict[str, tuple[tuple[int, int], bytes]] = {}


def _digest(path: Path) -> bytes:
    status = path.stat()
    stamp = (status.st_size, status.st_mtime_ns)
    key = os.path.normcase(os.path.abspath(path))
    known = _digests.get(key)
    if known is None or known[0] != stamp:
        with open(path, "rb") as handle:
            known = _digests[key] = (stamp, hashlib.file_digest(handle, "sha256").digest()
                                     if hasattr(hashlib, "file_digest") else hashlib.sha256(handle.read()).digest())
    return known[1]


@bpy.app.handlers.persistent
def forget(*_args) -> None:
    """load_post: drop every decoded picture (the images a new file uses are other ones)."""
    _decoded.clear()
    _digests.clear()


def decode(path: Path) -> np.ndarray:
    """(height, width, 3) float32 in [0, 1], row 0 at the bottom (Blender's order too); read-only, and the
    same array for every file of the same content."""
    path = Path(path)
    if not path.is_file():
        raise errors.TracerError(f"{path}: texture image not found")
    try:
        digest = _digest(path)
    except OSError as err:
        raise errors.TracerError(f"{path}: cannot read texture image ({err.strerror or err})") from None
    rgb = _decoded.get(digest)
    if rgb is None:
        rgb = _decoded[digest] = _decode_with_blender(path)
        rgb.setflags(write=False)
    return rgb


def _decode_with_blender(path: Path) -> np.ndarray:
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
        return _rgb(image, f"{path}: cannot read texture image (Blender could not decode it)", f"{path}: image")
    finally:
        if loaded:
            bpy.data.images.remove(image)


def _rgb(image, empty: str, named: str) -> np.ndarray:
    """A Blender image's pixels as (height, width, 3) float32, row 0 at the bottom; ``empty``: the message
    when it has none, ``named``: how the message of one too large to be a texture names it."""
    width, height = image.size
    channels = image.channels
    if width * height == 0 or channels == 0:
        raise errors.TracerError(empty)
    if width * height > limits.MAX_TEXELS:
        raise errors.TracerError(f"{named} of {width}x{height} pixels is too large for a texture")
    pixels = np.empty(width * height * channels, dtype=np.float32)
    image.pixels.foreach_get(pixels)
    pixels = pixels.reshape(height, width, channels)
    rgb = pixels[..., :3] if channels >= 3 else np.repeat(pixels[..., :1], 3, axis=2)
    return np.ascontiguousarray(rgb)


#: The picture files made so far (linear_copy: content digest of the file; pixels_copy: of the texels) -> file.
_made: dict[bytes, str] = {}
_made_folder = None  # a tempfile.TemporaryDirectory, made on first use, removed at exit


def _linear_from_srgb(stored: np.ndarray) -> np.ndarray:
    """Stored sRGB values in [0, 1] made linear (the sRGB transfer curve undone), as Cycles reads them."""
    return np.where(stored <= 0.04045, stored / 12.92, ((stored + 0.055) / 1.055) ** 2.4)


def _texels(rgb: np.ndarray, linear: bool) -> np.ndarray:
    """8-bit texels of (height, width, 3) values (row 0 at the bottom), rows top first as a file has them;
    made linear first where ``linear``."""
    stored = np.clip(rgb, 0.0, 1.0)
    values = _linear_from_srgb(stored) if linear else stored
    return np.rint(values[::-1] * 255.0).astype(np.uint8)


def _picture_file(digest: bytes, suffix: str, texels) -> str:
    """The picture file of the content ``digest``: the one made before, or ``texels()`` written now."""
    made = _made.get(digest)
    if made is not None and os.path.isfile(made):
        return made
    made = os.path.join(_temporary_folder(), digest.hex()[:24] + suffix)
    save_image(texels(), made)
    _made[digest] = made
    return made


def linear_copy(path: str) -> str:
    """An 8-bit picture file holding ``path``'s colours made linear (the sRGB curve undone), as Cycles reads
    an sRGB Image Texture; the tracer, which uses a picture's values as they are stored (as SDL does), is
    given this copy for a Blender material's texture.  One copy per content, in a temporary folder.  (8 bits
    of linear values are coarse in the darkest tenth: a stored 10 of 255 becomes 1.)"""
    return _picture_file(_digest(Path(path)), "-linear.png", lambda: _texels(decode(Path(path)), linear=True))


def pixels_copy(image, linear: bool) -> str:
    """An 8-bit picture file of a Blender image's own pixels (one packed into the .blend, or generated), for
    the tracer, which reads pictures from files: its colours made linear first where ``linear`` (an sRGB
    picture, as Cycles reads it).  One file per content, in the same temporary folder as linear_copy's;
    the pixels are read again each time (a painted image changes without a new file)."""
    texels = _texels(_rgb(image, f"picture {image.name} has no pixels", f"picture {image.name}"), linear)
    digest = hashlib.sha256(texels.tobytes() + bytes("x".join(map(str, texels.shape)), "ascii")).digest()
    return _picture_file(digest, "-pixels.png", lambda: texels)


def _temporary_folder() -> str:
    """The folder of the picture files made here (removed at exit)."""
    global _made_folder
    if _made_folder is None:
        import tempfile

        _made_folder = tempfile.TemporaryDirectory(prefix="sdl-raytracer-")
    return _made_folder.name


def register() -> None:
    limits.set_fallback_decoder(decode)
    bpy.app.handlers.load_post.append(forget)


def unregister() -> None:
    limits.set_fallback_decoder(None)
    while forget in bpy.app.handlers.load_post:
        bpy.app.handlers.load_post.remove(forget)
    forget()
