"""Hostile inputs: the bundled scenes, meshes, images and USD stage, mutated.

Each case is one file to feed the command line plus the options to feed it with: an SDL scene, a ``.3vn``
mesh (through a one-line scene that uses it), a BMP/PNG/JPEG/PPM picture (through a scene that textures a
sphere with it) or a USD stage.  Mutations mix blind byte edits (flips, truncation, splices) with ones that
know the format: numbers swapped for extreme values, lines repeated or dropped, statements and macros
inserted, booleans nested, PNG chunks edited with their checksums fixed, image headers declaring huge sizes.
Everything is drawn from ``random.Random(seed)``, so a case is reproduced from its seed alone.
"""
from __future__ import annotations

import io
import random
import re
import struct
import zlib
from dataclasses import dataclass, field
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"
KINDS = ("sdl", "3vn", "png", "bmp", "jpeg", "ppm", "usd")

EXTREMES = ("0", "-0", "1", "-1", "2", "0.5", "1e-308", "-1e-308", "1e308", "-1e308", "1.7976931348623157e308",
            "5e-324", "1e9", "-1e9", "1000000", "9223372036854775808", "18446744073709551616", "4294967296",
            "65536", "3", "64", "65", "100000", "1e30", "-1e30", "0.999999999999", "1.0000000001", "1e15")
WORDS = ("sphere", "cube", "plane", "square", "cone", "cylinder", "torus", "teapot", "diamond", "buckyball",
         "taperedCylinder 0.5", "union", "intersection", "difference", "push", "pop", "identityAffine",
         "translate 1 2 3", "scale 0 1 1", "scale 1e300 1e300 1e300", "rotate 90 0 0 0", "reflectivity 1",
         "transparency 1", "speedOfLight 0", "speedOfLight 1e-300", "texture -3 parameters 3 4 4 1e9",
         "texture -1", "texture 1", "texture 7", "maxRecursionDepth 100000", "minReflectivity 0",
         "minTransparency 0", "makePixmap 1 images/uvgrid.bmp", "makePixmap 2 nothere.png", "mesh meshes/pawn.3vn",
         "mesh /dev/zero", "mesh .", "light 1e308 0 0 1 1 1", "camera 0 0 0 0 0 0 0 1 0 45",
         "camera 1e308 1e308 1e308 0 0 0 0 1 0 179.9999", "{", "}", "def", "use", "!", "parameters 10",
         "globalAmbient 1e308 1e308 1e308", "background -1 -1 -1", "specularExponent 1e308",
         "surfaceRoughness 0 specularFraction 1",
         # the extensions for Blender scenes (docs/sdl.md)
         "sphereLight 1e308 0 0 1 1 1 1e308 4", "areaLight 0 3 0 0 -1 0 1 0 0 1 1 1 2 1 16",
         "ellipseLight 0 1e300 0 0 -1 0 0 0 1 1 1 1 1e-300 1e-300 4", "sunLight 1e-300 -1 0 1 1 1 179 8",
         "spotLight 0 3 0 0 -1 0 1 1 1 180 1 0.5 4", "fresnel dielectric", "fresnel metal fresnelTint 1 0.5 0",
         "smoothTerminator 1")


@dataclass
class Case:
    """One input: the files to write (name -> bytes; the first is the one run), the command's options."""

    kind: str
    files: dict[str, bytes]
    options: list[str] = field(default_factory=list)
    command: str = "render"

    @property
    def main(self) -> str:
        return next(iter(self.files))


def _seed_texts() -> dict[str, list[str]]:
    return {"sdl": [p.read_text() for p in sorted(SCENES.glob("*.sdl"))],
            "3vn": [(SCENES / "meshes" / "pawn.3vn").read_text()],
            "usd": [p.read_text() for p in sorted((SCENES / "usd").glob("*.usda"))]}


_SEEDS = None


def seeds() -> dict[str, list]:
    global _SEEDS
    if _SEEDS is None:
        from PIL import Image
        import numpy as np

        texts = _seed_texts()
        pixels = (np.indices((12, 16)).sum(axis=0)[..., None] * np.array([9, 17, 29])).astype(np.uint8)
        picture = Image.fromarray(pixels)  # (H, W, 3) uint8: RGB
        images = {"png": [(SCENES / "images" / "bricks.png").read_bytes()],
                  "bmp": [(SCENES / "images" / "uvgrid.bmp").read_bytes()]}
        for kind, fmt in (("png", "PNG"), ("bmp", "BMP"), ("jpeg", "JPEG"), ("ppm", "PPM")):
            buffer = io.BytesIO()
            picture.save(buffer, format=fmt)
            images.setdefault(kind, []).append(buffer.getvalue())
        _SEEDS = {**texts, **images}
    return _SEEDS


# -- blind byte mutations ---------------------------------------------------------------------------------

def mutate_bytes(rng: random.Random, data: bytes, rounds: int = 0) -> bytes:
    data = bytearray(data)
    for _ in range(rounds or rng.randint(1, 4)):
        if not data:
            data += bytes([rng.randrange(256)])
        choice = rng.random()
        at = rng.randrange(len(data))
        if choice < 0.35:
            data[at] ^= 1 << rng.randrange(8)
        elif choice < 0.5:
            data[at] = rng.choice((0, 0xFF, 0x7F, 0x80, ord("\n"), ord("{"), ord("!")))
        elif choice < 0.6:
            del data[at:at + rng.randint(1, 64)]
        elif choice < 0.7:
            data[at:at] = bytes(rng.randrange(256) for _ in range(rng.randint(1, 16)))
        elif choice < 0.8:
            end = min(len(data), at + rng.randint(1, 256))
            data[at:at] = data[at:end] * rng.randint(1, 8)
        elif choice < 0.9:
            del data[rng.randrange(len(data)):]
        else:
            data[at:at + 4] = struct.pack(rng.choice(("<I", ">I")), rng.choice(
                (0, 1, 0x7FFFFFFF, 0xFFFFFFFF, 0x80000000, 30000, 65535, 100000)) & 0xFFFFFFFF)
    return bytes(data)


# -- text mutations (SDL, .3vn, usda) -------------------------------------------------------------------------

_NUMBER = re.compile(r"(?<![\w.])[-+]?(?:\d+\.?\d*|\.\d+)(?:[eE][-+]?\d+)?")


def mutate_text(rng: random.Random, text: str, kind: str, deep: int = 1500) -> str:
    """``deep``: the deepest boolean nesting to insert (the NumPy path takes minutes over 1,500 levels: it is
    the slow reference, so its runs get shallower trees)."""
    lines = text.split("\n")
    for _ in range(rng.randint(1, 5)):
        choice = rng.random()
        at = rng.randrange(len(lines)) if lines else 0
        if choice < 0.35 and lines:  # a number becomes an extreme one
            numbers = list(_NUMBER.finditer(lines[at]))
            if numbers:
                m = rng.choice(numbers)
                lines[at] = lines[at][:m.start()] + rng.choice(EXTREMES) + lines[at][m.end():]
        elif choice < 0.45 and lines:
            del lines[at]
        elif choice < 0.55 and lines:
            lines[at:at] = [lines[at]] * rng.choice((2, 3, 10, 100))
        elif choice < 0.7 and kind == "sdl":
            lines.insert(at, " ".join(rng.choice(WORDS) for _ in range(rng.randint(1, 4))))
        elif choice < 0.75 and kind == "sdl":
            depth = min(deep, rng.choice((10, 200, 1500)))
            lines.insert(at, " ".join(rng.choice(("union", "difference", "intersection")) for _ in range(depth)) +
                         " sphere" * (depth + 1))
        elif choice < 0.8 and kind == "sdl":
            levels = rng.choice((3, 12, 40))
            macros = ["def fz0 { sphere }"] + [f"def fz{i} {{ use fz{i - 1} use fz{i - 1} }}" for i in range(1, levels)]
            lines[at:at] = macros + [f"use fz{levels - 1}"]
        elif choice < 0.85 and lines:
            words = lines[at].split()
            if len(words) > 1:
                i, j = rng.randrange(len(words)), rng.randrange(len(words))
                words[i], words[j] = words[j], words[i]
                lines[at] = " ".join(words)
        elif choice < 0.9 and lines:
            lines[at] = lines[at] + rng.choice(("x" * rng.choice((50, 5000)), "\0", "\ufeff", "é", "\r", "\t"))
        else:
            return mutate_bytes(rng, "\n".join(lines).encode(), 1).decode("utf-8", "replace")
    return "\n".join(lines)


# -- image mutations that keep a PNG's chunks valid, and headers with huge sizes ------------------------------

def _png_chunks(data: bytes):
    pos, chunks = 8, []
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        chunks.append([kind, data[pos + 8:pos + 8 + length]])
        pos += 12 + length
    return chunks


def _png_from(chunks) -> bytes:
    out = b"\x89PNG\r\n\x1a\n"
    for kind, body in chunks:
        out += struct.pack(">I", len(body)) + kind + body + struct.pack(">I", zlib.crc32(kind + body) & 0xFFFFFFFF)
    return out


def mutate_png(rng: random.Random, data: bytes) -> bytes:
    chunks = _png_chunks(data)
    if not chunks or rng.random() < 0.3:
        return mutate_bytes(rng, data)
    kind, body = rng.choice(chunks)
    index = next(i for i, c in enumerate(chunks) if c[0] == kind)
    if kind == b"IHDR" and len(body) >= 13 and rng.random() < 0.6:
        width, height = rng.choice(((30000, 30000), (1, 100000), (0, 5), (8192, 8192), (2**31 - 1, 1), (100, 0)))
        chunks[index][1] = struct.pack(">II", width, height) + body[8:]
    elif kind == b"IHDR" and len(body) >= 13:
        fields = bytearray(body)
        fields[rng.choice((8, 9, 10, 11, 12))] = rng.choice((0, 1, 2, 3, 4, 6, 8, 16, 255))
        chunks[index][1] = bytes(fields)
    else:
        chunks[index][1] = mutate_bytes(rng, body, 2)
    if rng.random() < 0.2:
        chunks.insert(rng.randrange(1, len(chunks) + 1), [rng.choice((b"tEXt", b"iCCP", b"PLTE", b"tRNS", b"zzZz")),
                                                         bytes(rng.randrange(256) for _ in range(rng.randint(0, 40)))])
    return _png_from(chunks)


def mutate_header_size(rng: random.Random, kind: str, data: bytes) -> bytes:
    width, height = rng.choice(((30000, 30000), (100000, 1), (0, 4), (8193, 8192), (2**31 - 1, 2**31 - 1)))
    if kind == "bmp" and len(data) >= 26:
        return data[:18] + struct.pack("<ii", width, rng.choice((height, -height))) + data[26:]
    if kind == "ppm":
        return b"P6\n%d %d\n255\n" % (width, height) + data[-48:]
    if kind == "jpeg":
        marker = data.find(b"\xff\xc0")
        if marker >= 0:
            at = marker + 5
            return data[:at] + struct.pack(">HH", min(height, 65535), min(width, 65535)) + data[at + 4:]
    return mutate_bytes(rng, data)


# -- whole cases -------------------------------------------------------------------------------------------

TEXTURED = ("camera 0 0 4  0 0 0  0 1 0  40\nlight 2 3 4  1 1 1\nmakePixmap 1 {name}\n"
            "push ambient 1 1 1 diffuse 1 1 1 texture 1 sphere pop\n")
MESHED = "camera 3 2 4  0 0.3 0  0 1 0  40\nlight 2 3 4  1 1 1\nmesh {name}\n"


def render_options(rng: random.Random) -> list[str]:
    options = ["--width", "32", "--height", "24", "-q"]
    if rng.random() < 0.15:
        options += ["--backend", "numpy"]
    if rng.random() < 0.15:
        options += ["--lenient"]
    if rng.random() < 0.1:
        options += ["--block-size", rng.choice(("2", "7", "33", "100000")), *(["--progressive"] * rng.randint(0, 1))]
    if rng.random() < 0.05:
        options += ["--samples", "2", "--sampling", rng.choice(("regular", "jittered", "adaptive"))]
    if rng.random() < 0.05:
        options += ["--max-depth", rng.choice(("0", "5", "1000000"))]
    return options


#: Lines put before a text to make it as long as the command line's reader offers to the C reader first
#: (tracer.sdl.parser.FAST_MIN_CHARS): comments, or shapes, which the C reader reads before it meets the
#: mutations (and declines, or reads them too).
PADDING = ("! a comment line, for length\n", "push translate 0.5 -0.25 1e-3 scale 0.01 0.01 0.01 sphere pop\n",
           "diffuse 0.3 0.6 0.9 rotate 33 1 2 3 cube identityAffine\n")


def padded_for_the_c_reader(rng: random.Random, text: str) -> str:
    from tracer.sdl.parser import FAST_MIN_CHARS
    line = rng.choice(PADDING)
    return line * (FAST_MIN_CHARS // len(line) + 1) + text


def make_case(seed: int, usd: bool = True) -> Case:
    """The case for one seed; ``usd`` False: nothing that needs usd-core (no USD input, no convert)."""
    rng = random.Random(seed)
    kind = rng.choice(KINDS if usd else tuple(k for k in KINDS if k != "usd"))
    pool = seeds()[kind]
    original = rng.choice(pool)
    name = f"in{seed}"
    roll = rng.random()
    command = "info" if roll < 0.08 else "convert" if roll < 0.14 and kind in ("sdl", "usd") else "render"
    if command == "convert" and not usd:
        command = "info"
    options = render_options(rng) if command == "render" else ["--json"] * rng.randint(0, 1) if command == "info" else []
    deep = 1500 if "numpy" not in options else 100
    if kind == "sdl":
        text = mutate_text(rng, original, kind, deep)
        # (not for the NumPy path, the slow reference: a thousand padding shapes take it past the hang limit)
        if rng.random() < 0.3 and "numpy" not in options:
            text = padded_for_the_c_reader(rng, text)
        case = Case(kind, {f"{name}.sdl": text.encode()})
    elif kind == "usd":
        text = original if rng.random() < 0.1 else mutate_text(rng, original, kind)
        case = Case(kind, {f"{name}.usda": text.encode()})
    elif kind == "3vn":
        body = mutate_text(rng, original, kind).encode() if rng.random() < 0.7 else mutate_bytes(rng, original.encode())
        case = Case(kind, {f"{name}.sdl": MESHED.format(name=f"{name}.3vn").encode(), f"{name}.3vn": body})
    else:
        ext = {"jpeg": "jpg"}.get(kind, kind)
        roll = rng.random()
        if roll < 0.25:
            body = mutate_header_size(rng, kind, original)
        elif kind == "png":
            body = mutate_png(rng, original)
        else:
            body = mutate_bytes(rng, original)
        case = Case(kind, {f"{name}.sdl": TEXTURED.format(name=f"{name}.{ext}").encode(), f"{name}.{ext}": body})
    case.command, case.options = command, options
    return case
