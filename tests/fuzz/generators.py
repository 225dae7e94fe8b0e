"""Inputs made from nothing, one generator per class of failure a second, independent fuzz run found (issue 28),
beside the mutations of the bundled files in mutate.py:

* ``tree``: ray trees the depth limit does not bound (mirrors and glass reflecting and transmitting most of
  the light, at any maxRecursionDepth): an image within the time its size implies, a ``warning:`` at most;
* ``mesh_numbers``: .3vn files whose numbers are extreme (1e308, 1e151, -1e308, 0 0 0): sums that overflow;
* ``usd_numbers``: USD meshes, transforms and lights with inf, -inf, nan and overflowing points;
* ``image_format``: pictures in every format Pillow writes, whole, mutated, or with headers declaring sizes
  their bytes cannot hold;
* ``usd_hostile``: bytes that are not UTF-8, non-finite numbers where integers belong, composition cycles,
  booleans nested thousands deep, references fanning out;
* ``interrupt`` and ``kill``: a render (of SDL or USD) or a convert to USD that a signal (SIGINT, SIGTERM;
  SIGKILL) reaches at a random moment;
* ``name``: output file names of every length up to the file system's limit, and past it;
* ``edge``: polyhedra seen exactly along their edges, planes moved far along themselves: both backends;
* ``readers``: grammar-aware SDL texts long enough for the C reader, read by both SDL readers and compared.

Each case is made from ``random.Random(seed)`` alone.  fuzz.py runs and judges them (see Case's fields).
"""
from __future__ import annotations

import io
import random
import signal
import struct
from dataclasses import dataclass, field
from typing import Callable, Optional

GENERATED = ("tree", "mesh_numbers", "usd_numbers", "image_format", "usd_hostile", "interrupt", "kill", "name",
             "edge", "readers")
#: Classes that need usd-core (left out under make sanitize).
NEEDS_USD = ("usd_numbers", "usd_hostile")
#: Classes that read or write USD in some of their cases: without usd-core those cases are SDL ones.
USD_SOMETIMES = ("interrupt", "kill")

CAMERA = "camera 0 0 6  0 0 0  0 1 0  40\nlight 2 3 4  1 1 1\n"
EXTREME = ("1e308", "-1e308", "1.7976931348623157e308", "1e151", "-1e151", "1e150", "1e-308", "5e-324", "0",
           "-0", "1", "1e30", "-1e30", "9e15")
OLD_OUTPUT = b"the output of an earlier run"


@dataclass
class Generated:
    """A generated input: the files (name -> bytes; the first is the one run), the command and its options,
    and what the run must be judged by besides the usual promise."""

    kind: str
    files: dict[str, bytes]
    options: list[str] = field(default_factory=list)
    command: str = "render"
    output: str = "out.png"  # the image a render writes (relative to its folder)
    signal: Optional[tuple[int, float]] = None  # (signal, seconds after the start) the run is sent
    old_output: Optional[bytes] = None  # written at ``output`` first: a failed or cancelled run keeps it
    compare: bool = False  # render again with the other backend: C = NumPy within 1/255
    names: tuple[str, ...] = ()  # more strings one of which an error line must contain

    @property
    def main(self) -> str:
        return next(iter(self.files))


SMALL = ["--width", "32", "--height", "24", "-q"]


def _number(rng: random.Random) -> str:
    return rng.choice([f"{rng.uniform(-10, 10):.6g}", rng.choice(EXTREME)])


# -- work the depth limit does not bound --------------------------------------------------------------------

def tree(rng: random.Random, name: str) -> Generated:
    kr, kt = rng.choice([(0.95, 0.95), (1.0, 1.0), (0.9, 0.6), (0.5, 0.5), (0.99, 0.01), (2.0, 0.0),
                         (rng.random(), rng.random()), (rng.uniform(0.5, 1.5), rng.uniform(0.5, 1.5))])
    depth = rng.choice([3, 12, 64, 65, 1000, 10**9])
    speed = rng.choice(["0.5", "0.7", "1", "1.5", "1e-3"])
    text = CAMERA + f"maxRecursionDepth {depth}\nminReflectivity 0 minTransparency 0\n"
    text += f"reflectivity {kr:.3g} transparency {kt:.3g} speedOfLight {speed}\n"
    layout = rng.randrange(4)
    if layout == 0:  # nested spheres
        text += "".join(f"push scale {s:.3g} {s:.3g} {s:.3g} sphere pop\n" for s in (1.0, 0.7, 0.45, 0.2)[:rng.randint(1, 4)])
    elif layout == 1:  # two mirrors facing each other, the camera between them
        text = text.replace("camera 0 0 6", "camera 0 0 0.5") + \
            "push translate 0 0 -1.2 scale 100 100 0.1 cube pop\npush translate 0 0 1.2 scale 100 100 0.1 cube pop\n"
    elif layout == 2:  # inside a box of mirrors
        text = text.replace("camera 0 0 6", "camera 0.1 0.2 0.3") + "push scale 3 3 3 cube pop\nsphere\n"
    else:  # glass over glass, booleans
        text += "difference sphere push scale 0.6 0.6 0.6 sphere pop\npush translate 0 0 -1 cube pop\n"
    options = SMALL + (["--cutoff", rng.choice(["0", "1e-9"])] if rng.random() < 0.3 else []) + \
        (["--all-rays"] if rng.random() < 0.1 else [])
    if rng.random() < 0.2:  # the slow reference, at a smaller size
        options = ["--width", "12", "--height", "9", "-q", "--backend", "numpy"]
    return Generated("tree", {f"{name}.sdl": text.encode()}, options)


# -- numbers that overflow the sums they feed -----------------------------------------------------------------

def mesh_numbers(rng: random.Random, name: str) -> Generated:
    if rng.random() < 0.1:
        body = rng.choice(["0 0 0\n", "0 0 0", "3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "0 1 0\n0 0 1\n"])
    else:
        v = rng.randint(3, 12)
        vertices = [[rng.choice(EXTREME) if rng.random() < 0.15 else f"{rng.uniform(-1, 1):.5g}" for _ in range(3)]
                    for _ in range(v)]
        normals = [[rng.choice(EXTREME) if rng.random() < 0.2 else f"{rng.uniform(-1, 1):.5g}" for _ in range(3)]
                   for _ in range(rng.randint(1, 3))]
        faces = []
        for _ in range(rng.randint(1, 12)):
            corners = rng.sample(range(v), 3) if rng.random() < 0.9 else [0, 0, 0]
            faces.append(" ".join(map(str, [3, *corners, *(rng.randrange(len(normals)) for _ in range(3))])))
        body = "\n".join([f"{v} {len(normals)} {len(faces)}"] + [" ".join(p) for p in vertices + normals] + faces) + "\n"
    scene = "camera 3 2 4  0 0.3 0  0 1 0  40\nlight 2 3 4  1 1 1\n" + \
        rng.choice(["", "scale 1e200 1e200 1e200 ", "translate 1e308 0 0 ", "rotate 45 1e200 0 0 "]) + f"mesh {name}.3vn\n"
    return Generated("mesh_numbers", {f"{name}.sdl": scene.encode(), f"{name}.3vn": body.encode()}, SMALL[:],
                     names=(f"{name}.3vn",))


_USD_NUMBER = ("inf", "-inf", "nan", "1e308", "-1e308", "1e39", "3.5e38", "0", "1")


def _usd_number(rng: random.Random) -> str:
    return rng.choice(_USD_NUMBER) if rng.random() < 0.3 else f"{rng.uniform(-2, 2):.4g}"


def usd_numbers(rng: random.Random, name: str) -> Generated:
    points = ", ".join(f"({_usd_number(rng)}, {_usd_number(rng)}, {_usd_number(rng)})" for _ in range(4))
    matrix = ", ".join("(" + ", ".join(_usd_number(rng) if rng.random() < 0.2 else ("1" if i == j else "0")
                                       for j in range(4)) + ")" for i in range(4))
    prims = [f'def Mesh "m"\n{{\n    point3f[] points = [{points}]\n    int[] faceVertexCounts = [3, 3]\n'
             f'    int[] faceVertexIndices = [0, 1, 2, 0, 2, 3]\n}}\n',
             f'def Sphere "s" (\n)\n{{\n    double radius = {_usd_number(rng)}\n'
             f'    matrix4d xformOp:transform = ({matrix})\n    uniform token[] xformOpOrder = ["xformOp:transform"]\n}}\n',
             f'def SphereLight "l"\n{{\n    float inputs:intensity = {_usd_number(rng)}\n'
             f'    float inputs:exposure = {_usd_number(rng)}\n    double3 xformOp:translate = ({_usd_number(rng)}, 0, 0)\n'
             f'    uniform token[] xformOpOrder = ["xformOp:translate"]\n}}\n',
             f'def Camera "c"\n{{\n    float focalLength = {_usd_number(rng)}\n}}\n']
    text = "#usda 1.0\n" + "".join(rng.sample(prims, rng.randint(1, len(prims))))
    return Generated("usd_numbers", {f"{name}.usda": text.encode()}, SMALL + ["--lenient"] * (rng.random() < 0.3))


# -- pictures of every format ---------------------------------------------------------------------------------

#: Pillow formats it writes, and the extension a file of each gets.
_PICTURE_FORMATS = {"PNG": "png", "JPEG": "jpg", "BMP": "bmp", "PPM": "ppm", "TIFF": "tif", "GIF": "gif",
                    "TGA": "tga", "ICO": "ico", "PCX": "pcx", "SGI": "sgi", "DDS": "dds", "WEBP": "webp",
                    "IM": "im", "MSP": "msp", "QOI": "qoi", "BLP": "blp", "XBM": "xbm", "JPEG2000": "jp2"}
#: Where some headers keep their size: (offset, struct format of width then height).
_SIZE_FIELDS = {"GIF": (6, "<HH"), "TGA": (12, "<HH"), "PCX": (8, "<HH"), "SGI": (6, ">HH"), "DDS": (12, "<II"),
                "BMP": (18, "<ii"), "QOI": (4, ">II")}


def _picture(rng: random.Random, fmt: str) -> bytes:
    from PIL import Image

    mode = {"MSP": "1", "XBM": "1", "BLP": "RGB"}.get(fmt, rng.choice(["RGB", "L", "P", "RGBA", "1"]))
    size = (rng.randint(1, 40), rng.randint(1, 40))
    picture = Image.new("RGB", size, tuple(rng.randrange(256) for _ in range(3))).convert(mode)
    options = {}
    if fmt == "TIFF":
        options["compression"] = rng.choice(["raw", "tiff_lzw", "tiff_deflate", "packbits", "jpeg"])
        if options["compression"] == "jpeg":
            picture = picture.convert("RGB")
    buffer = io.BytesIO()
    try:
        picture.save(buffer, format=fmt, **options)
    except Exception:  # noqa: BLE001 — a mode this format cannot hold: its RGB
        buffer = io.BytesIO()
        picture.convert("RGB").save(buffer, format=fmt)
    return buffer.getvalue()


def image_format(rng: random.Random, name: str) -> Generated:
    from mutate import mutate_bytes  # (the blind byte edits)

    fmt = rng.choice(sorted(_PICTURE_FORMATS))
    try:
        data = _picture(rng, fmt)
    except Exception:  # noqa: BLE001 — a format this Pillow cannot write after all
        fmt, data = "PNG", _picture(rng, "PNG")
    roll = rng.random()
    if roll < 0.35 and fmt in _SIZE_FIELDS:
        at, layout = _SIZE_FIELDS[fmt]
        width, height = rng.choice([(65535, 65535), (4096, 16384), (8192, 8192), (1, 65535), (0, 7)])
        if layout[1] == "I" or layout[1] == "i":
            width, height = rng.choice([(67108864, 1), (4096, 16384), (2**31 - 1, 2), (8193, 8192), (width, height)])
        data = data[:at] + struct.pack(layout, width, height) + data[at + struct.calcsize(layout):]
    elif roll < 0.7:
        data = mutate_bytes(rng, data)
    ext = _PICTURE_FORMATS[fmt] if rng.random() < 0.8 else rng.choice(list(_PICTURE_FORMATS.values()))
    picture = f"{name}.{ext}"
    scene = f"{CAMERA}makePixmap 1 {picture}\npush ambient 1 1 1 diffuse 1 1 1 texture 1 sphere pop\n"
    options = SMALL + ["--lenient"] * (rng.random() < 0.2)
    return Generated("image_format", {f"{name}.sdl": scene.encode(), picture: data}, options, names=(picture,))


# -- stages USD cannot read, or should not -------------------------------------------------------------------

def usd_hostile(rng: random.Random, name: str) -> Generated:
    file = f"{name}.usda"
    choice = rng.randrange(6)
    files: dict[str, bytes] = {}
    if choice == 0:  # a byte that is not UTF-8, anywhere
        text = f'#usda 1.0\ndef Xform "a"\n{{\n    custom int sdl:texture = 0\n}}\ndef Sphere "s"\n{{\n}}\n'.encode()
        at = rng.randrange(len(text))
        files[file] = text[:at] + bytes([rng.choice([0x80, 0xC3, 0xE9, 0xFF, 0xFE])]) + text[at:]
    elif choice == 1:  # non-finite numbers where whole numbers belong
        value = rng.choice(["inf", "-inf", "nan", "1e300", "1.5", "-2"])
        attr = rng.choice(["sdl:texture", "sdl:maxRecursionDepth", "sdl:version"])
        files[file] = ('#usda 1.0\ndef Xform "SDLScene"\n{\n    custom int sdl:version = 1\n'
                       f'    custom double {attr} = {value}\n    custom double[] sdl:pixmapNumbers = [{value}]\n'
                       '    custom asset[] sdl:pixmapFiles = [@x.png@]\n'
                       '    def Sphere "s"\n    {\n        custom token sdl:shape = "sphere"\n'
                       f'        custom color3d sdl:diffuse = (1, 1, 1)\n        custom double sdl:texture = {value}\n'
                       '    }\n}\n').encode()
    elif choice == 2:  # composition cycles
        arc = rng.choice(["inherits", "specializes", "references"])
        target = "</B>" if arc != "references" else f"@./{file}@</B>"
        back = "</A>" if arc != "references" else f"@./{file}@</A>"
        files[file] = (f'#usda 1.0\n(\n    defaultPrim = "A"\n)\ndef Xform "A" (\n    {arc} = {target}\n)\n{{\n'
                       f'    def Sphere "s"\n    {{\n    }}\n}}\ndef Xform "B" (\n    {arc} = {back}\n)\n{{\n}}\n').encode()
    elif choice == 3:  # booleans nested thousands deep, as nested prims (written by another writer)
        depth = rng.choice([50, 1999, 2001, 3000])
        inner = 'def Sphere "s" {\n custom token sdl:operand = "right"\n}\n'
        text = inner
        for level in range(depth):
            op = rng.choice(["union", "intersection", "difference"])
            text = (f'def Xform "b{level}" {{\n custom token sdl:csg = "{op}"\n def Cube "c" {{\n}}\n' + text + "}\n")
        files[file] = ("#usda 1.0\n" + text).encode()
    elif choice == 4:  # references fanning out: levels of ten
        levels = rng.randint(2, 6)
        files[file] = b""
        for level in range(levels):
            ref = f"{name}_{level + 1}.usda" if level + 1 < levels else None
            body = "".join(f'    def Xform "r{k}" (\n        references = @./{ref}@\n    )\n    {{\n    }}\n'
                           for k in range(10)) if ref else '    def Sphere "s"\n    {\n    }\n'
            files[f"{name}_{level}.usda" if level else file] = \
                f'#usda 1.0\n(\n    defaultPrim = "P"\n)\ndef Xform "P"\n{{\n{body}}}\n'.encode()
    else:  # a stage of many plain prims: what composition adds is bounded, not what a file holds
        count = rng.choice([100, 3000, 60000 // 10])
        files[file] = ("#usda 1.0\n" + "".join(f'def Sphere "s{k}"\n{{\n    double radius = 0.1\n}}\n'
                                               for k in range(count))).encode()
    command = rng.choice(["render", "render", "info", "convert"])
    options = SMALL[:] if command == "render" else []
    return Generated("usd_hostile", files, options, command=command)


# -- signals, kills and names ---------------------------------------------------------------------------------

def _busy_scene(rng: random.Random) -> str:
    """A scene whose render at 64 x 48 takes about a second: glass trees cut by the ray budget."""
    k = rng.choice([0.9, 0.95])
    return (CAMERA.replace("camera 0 0 6", "camera 0 0 3") + "maxRecursionDepth 64 minReflectivity 0 minTransparency 0\n"
            + f"reflectivity {k} transparency {k} speedOfLight 0.7\nsphere\npush scale 0.5 0.5 0.5 sphere pop\n")


_BUSY_STAGES: dict[str, bytes] = {}


def _busy_stage(text: str) -> bytes:
    """The busy scene as a .usda stage (written once per text with tracer.usd, in the fuzz run's process)."""
    if text not in _BUSY_STAGES:
        import tempfile
        from pathlib import Path

        from tracer.sdl.parser import parse_sdl
        from tracer.usd import save_usd

        with tempfile.TemporaryDirectory() as folder:
            path = Path(folder) / "busy.usda"
            save_usd(parse_sdl(text), path)
            _BUSY_STAGES[text] = path.read_bytes()
    return _BUSY_STAGES[text]


def _many_spheres(count: int) -> str:
    return CAMERA + "".join(f"push translate {k % 50 - 25} {k // 50 % 50 - 25} {-(k // 2500)} scale 0.3 0.3 0.3 "
                            f"sphere pop\n" for k in range(count))


def interrupt(rng: random.Random, name: str, usd: bool = True) -> Generated:
    """A run a signal reaches at a random moment: a render of glass (from SDL or, reading it through usd-core,
    from USD), or a convert of many spheres to USD (usd-core writing); ``usd`` False: always the SDL render
    (under the sanitizers usd-core cannot be loaded)."""
    signum = rng.choice([signal.SIGINT, signal.SIGTERM])
    moment = (signum, rng.uniform(0.0, 1.5))
    options = ["--width", "64", "--height", "48", "-q", "--threads", "1"]
    what = rng.choice(["sdl", "sdl", "usd", "convert"]) if usd else "sdl"
    if what == "convert":
        files = {f"{name}.sdl": _many_spheres(rng.choice([2000, 5000])).encode()}
        return Generated("interrupt", files, [], command="convert", output="out.usda", signal=moment,
                         old_output=OLD_OUTPUT)
    text = _busy_scene(rng)
    files = {f"{name}.usda": _busy_stage(text)} if what == "usd" else {f"{name}.sdl": text.encode()}
    output = rng.choice(["out.png", "out.png", "out.bmp", "out.tif"])
    return Generated("interrupt", files, options, output=output, signal=moment, old_output=OLD_OUTPUT)


def kill(rng: random.Random, name: str, usd: bool = True) -> Generated:
    case = interrupt(rng, name, usd)
    case.kind, case.signal = "kill", (signal.SIGKILL, case.signal[1])
    return case


def output_name(rng: random.Random, name: str) -> Generated:
    ext = rng.choice(["png", "bmp", "ppm", "jpg", "tif"])
    alphabet = rng.choice(["a", "abc XYZ_-", "é☃", "a.b"])
    length = rng.choice([1, 100, 200, 240, 250, 255 - len(ext) - 1, 254, 256, 300])
    stem = "".join(rng.choice(alphabet) for _ in range(length))
    while len((stem + "." + ext).encode()) > 255 and length <= 255 - len(ext) - 1:
        stem = stem[:-1]  # (a name that fits in characters but not in bytes: cut to fit, unless meant to be long)
    output = f"{stem}.{ext}"
    scene = CAMERA + "sphere\n"
    return Generated("name", {f"{name}.sdl": scene.encode()}, SMALL[:], output=output,
                     old_output=OLD_OUTPUT if rng.random() < 0.5 else None, names=(output[:50],))


# -- last bits: edges and far planes, both backends ------------------------------------------------------------

def edge(rng: random.Random, name: str) -> Generated:
    shape = rng.choice(["tetrahedron", "octahedron", "cube", "icosahedron", "dodecahedron", "buckyball", "diamond"])
    turn = rng.choice(["", "rotate 90 0 0 1 ", "rotate 45 0 0 1 ", "rotate 90 1 0 0 ", "rotate 180 0 1 0 "])
    angle = rng.choice([30, 40, 53.13])
    text = f"camera 0 0 5  0 0 0  0 1 0  {angle}\nlight 2 3 4 1 1 1\n{turn}{shape}\n"
    if rng.random() < 0.4:
        move = rng.choice(["9e15 0 0", "0 0 9e15", "1e12 0 1e12", "9e15 0 9e15"])
        text = f"camera 3 2 4  0 0 0  0 1 0  40\nlight 2 3 4 1 1 1\npush translate {move} rotate -90 1 0 0 " \
               f"{rng.choice(['texture -1 ', ''])}plane pop\nreflectivity 0.5 sphere\n"
    size = str(rng.choice([24, 32, 50]))
    return Generated("edge", {f"{name}.sdl": text.encode()}, ["--width", size, "--height", size, "-q"], compare=True)


# -- the two SDL readers -------------------------------------------------------------------------------------

def _statement(rng: random.Random, depth: list[int]) -> str:
    """One statement the C reader reads (its keyword has an action), with values it takes (numbers of every
    written form); ``depth`` counts the pushes not yet popped.  (Transforms are kept from piling up: a
    product of thousands of scales would be refused as not clearly invertible.)"""
    from tracer.sdl import statements

    entry = rng.choice([s for s in statements.STATEMENTS if s.action])
    keyword = entry.keyword
    if keyword == "pop" and not depth[0]:
        keyword = "push"
    if keyword in ("scale", "rotate", "translate") and rng.random() < 0.5:
        keyword = "identityAffine"
    depth[0] += {"push": 1, "pop": -1}.get(keyword, 0)
    if keyword != entry.keyword:
        return keyword
    words = [keyword]
    for part in entry.usage.split():
        if part in ("...", "pn", "p1"):
            continue
        if part == "n" and "p1" in entry.usage:
            count = rng.randint(0, 10)
            words += [str(count)] + [_plain(rng) for _ in range(count)]
        elif part in ("t", "i", "n"):
            words.append(str(rng.randint(0, 64) if keyword == "maxRecursionDepth" else rng.randint(-3, 0)))
        elif keyword == "scale":
            words.append(rng.choice(["1", "2", "0.5", "-1", "1.5", "0.75"]))
        elif keyword == "rotate" and part != "angle":
            words.append(rng.choice(["1", "0.5", "-2", "3e-3"]))
        elif keyword == "camera" and part == "viewAngle":
            words.append(f"{rng.uniform(5, 170):.5g}")
        else:
            words.append(_plain(rng))
    return " ".join(words)


def _plain(rng: random.Random) -> str:
    """A number in one of the forms SDL allows, of a size nothing refuses."""
    return rng.choice([f"{rng.uniform(-10, 10):.{rng.randint(1, 17)}g}", str(rng.randint(-5, 5)), "-0", "0.0",
                       ".125", "7.", "1e-5", "2.5E+2", repr(rng.uniform(0, 1))])


#: What the C reader stops at (then the Python reader reads the whole text): words outside its subset,
#: characters beyond ASCII where it does not take them, numbers that are not numbers.
_HOSTILE = ("! name: shape café\n", "! ☃ comment\n", "! name: x\n", "\u00a0", "é", "junk", "1e999", "--5",
            "0x10", ".", "def d { sphere }", "use d", "union sphere cube", "fresnel metal", "mesh x.3vn",
            "maxRecursionDepth 100000", "pop")


def readers(rng: random.Random, name: str) -> Generated:
    from tracer.sdl.parser import FAST_MIN_CHARS

    parts, depth, size = [], [0], 0
    while size < FAST_MIN_CHARS + rng.randrange(2000):
        parts.append(_statement(rng, depth) if rng.random() > 0.02 else rng.choice(["! a comment\n", "\r\n"]))
        size += len(parts[-1]) + 1
    if rng.random() < 0.3:  # one thing the C reader stops at, somewhere
        parts.insert(rng.randrange(len(parts) + 1), rng.choice(_HOSTILE))
    separators = [" ", "\n", "\r\n", "  ", "\t"]
    text = "".join(p + rng.choice(separators) for p in parts)
    return Generated("readers", {f"{name}.sdl": text.encode("utf-8")}, ["--lenient"] * (rng.random() < 0.5),
                     command="differential-sdl")


GENERATORS: dict[str, Callable[[random.Random, str], Generated]] = {
    "tree": tree, "mesh_numbers": mesh_numbers, "usd_numbers": usd_numbers, "image_format": image_format,
    "usd_hostile": usd_hostile, "interrupt": interrupt, "kill": kill, "name": output_name, "edge": edge,
    "readers": readers}


def generated_case(seed: int, usd: bool = True) -> Generated:
    """The generated case for one seed; ``usd`` False: no class that needs usd-core."""
    rng = random.Random(seed)
    kinds = GENERATED if usd else tuple(k for k in GENERATED if k not in NEEDS_USD)
    kind = rng.choice(kinds)
    if kind in USD_SOMETIMES:
        return GENERATORS[kind](rng, f"in{seed}", usd)
    return GENERATORS[kind](rng, f"in{seed}")


# -- the differential run of the SDL readers (in the child process) --------------------------------------------

def _scene_facts(scene) -> list:
    """Everything a scene holds, as comparable values (floats as their bits)."""
    from tracer.model import CSG

    def bits(values):
        values = values if isinstance(values, (tuple, list)) else (values,)
        return tuple(struct.pack("<d", float(v)) if isinstance(v, float) else repr(v) for v in values)

    facts = []
    todo = list(reversed(scene.objects))
    while todo:
        node = todo.pop()
        if isinstance(node, CSG):
            facts.append((node.op, node.groups, str(node.source)))
            todo += (node.right, node.left)
            continue
        material = node.material
        facts.append((node.kind, node.matrix.tobytes(), tuple(bits(getattr(material, f)) for f in
                                                               material.__dataclass_fields__),
                      bits(tuple(node.parameters)), node.groups, str(node.source), node.name, node.mesh_file))
    facts.append([(bits(tuple(l.position)), bits(tuple(l.color))) for l in scene.lights])
    camera = scene.camera
    facts.append(None if camera is None else [bits(tuple(getattr(camera, f)) if f != "view_angle"
                                                   else camera.view_angle) for f in ("eye", "look", "up", "view_angle")])
    facts.append([bits(getattr(scene.settings, f)) for f in scene.settings.__dataclass_fields__])
    facts.append(sorted(scene.pixmaps.items()))
    facts.append(list(scene.warnings))
    return facts


def differential_sdl(path: str, lenient: bool) -> tuple[int, str]:
    """Read ``path`` with the C reader first (when it takes the text) and with the Python reader alone: the
    same scene, or the same error.  (0, "") when they agree, else (3, what differs)."""
    from tracer.errors import SDLError
    from tracer.sdl.parser import load

    def outcome(fast: bool):
        try:
            return _scene_facts(load(path, strict=not lenient, fast=fast))
        except SDLError as error:
            return f"error: {error}"

    fast, slow = outcome(True), outcome(False)
    if fast == slow:
        return 0, ""
    if isinstance(fast, str) or isinstance(slow, str):
        return 3, f"readers differ: C reader {str(fast)[:150]!r}, Python reader {str(slow)[:150]!r}"
    for k, (a, b) in enumerate(zip(fast, slow)):
        if a != b:
            return 3, f"readers differ at item {k}: {str(a)[:150]} / {str(b)[:150]}"
    return 3, f"readers differ in length: {len(fast)} / {len(slow)}"


def signal_name(signum: int) -> str:
    return signal.Signals(signum).name
