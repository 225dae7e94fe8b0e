"""Big SDL files read by the C core (tracer/native/sdl_read.h), with the Python reader as its reference.

The C scanner reads the statements generated scenes are made of (settings, lights, camera, materials,
transforms and every shape but ``mesh``) in one pass into columns, or declines the text: at the first
thing outside that subset (a ``def``, a brace, a boolean, an unknown word, a word where a number belongs, a
statement cut short, a value the Python reader would refuse, clamp or warn about, a transform that is not
clearly invertible) it stops and :func:`read` answers None, and :func:`tracer.sdl.parser.parse_sdl` reads
the text with the Python reader as before.  So every message stays the Python reader's, strict or lenient.

What it reads equals what the Python reader makes of the same text, bit for bit: the same shapes (kind,
matrix, material by value, parameters, place, name), lights, camera and settings (tests/test_sdl_fastread.py
compares the two).  The shapes come as columns, which the scene holds without making a Shape per row.

Which keywords it reads, and how (its action, with an argument such as a material field's slot or a
shape's kind and parameter count), is tracer/sdl/statements.py's table, the one the Python reader's handlers
come from too: a statement without an action there is declined, and so read by the Python reader.
"""
from __future__ import annotations

import ctypes
import functools
import re
import sys
from dataclasses import dataclass
from typing import Optional, Union

import numpy as np

from .. import shapes as shape_registry
from ..camera import camera_problem
from ..model import Camera, Light, Material, MaterialRows, Scene, ShapeTable
from . import statements

#: Whether this process's math.cos and math.sin are the C core's cos and sin (one C library on Linux and macOS;
#: on Windows Python's and the core's may differ in the last bit): otherwise the C reader declines rotations
#: whose sine and cosine are not plain 0 or +-1.
SHARED_LIBM = sys.platform != "win32"

_SURROGATE = re.compile(r"[\ud800-\udfff]")

#: Keywords the C reader leaves to the Python reader: it declines the text at the first of them.
DECLINED = statements.DECLINED


@dataclass(frozen=True)
class Declined:
    """Why the C reader left a text to the Python reader (sdl_read.h's reason) and where (a character
    offset)."""

    reason: str
    offset: int


# sdl_read.h's SDL_SET_* bits: which settings the text set.
_SET_GLOBAL_AMBIENT, _SET_BACKGROUND, _SET_MIN_REFLECTIVITY, _SET_MIN_TRANSPARENCY, _SET_MAX_DEPTH = 1, 2, 4, 8, 16


def _check_material_rows(width: int, max_parameters: int) -> None:
    """The C side's material row must be tracer.model.MaterialRows' (the material columns the scene keeps)."""
    if width != MaterialRows.WIDTH or max_parameters != MaterialRows.MAX_PARAMETERS:
        raise RuntimeError("sdl_read.h's material row does not match tracer.model.MaterialRows")


@dataclass(frozen=True)
class _Setup:
    """What every read hands the C side: the library, the vocabulary and the default material."""

    lib: ctypes.CDLL
    words: bytes
    codes: np.ndarray  # (action, argument, count) per word, int32
    defaults: np.ndarray  # the default material's row
    reasons: tuple[str, ...]


@functools.lru_cache(maxsize=1)
def _setup() -> Optional[_Setup]:
    """None when the C core is not loaded (then the Python reader reads everything)."""
    from .. import native  # deferred: the parser must not load the C core for small texts
    if native.load_error is not None or native._lib is None:
        return None
    lib = native._lib  # (its functions declared from tracer/native/contract.py's FUNCTIONS)
    _check_material_rows(lib.rt_sdl_material_width(), statements.MAX_PARAMETERS)
    vocabulary = statements.vocabulary()  # (the library speaks its actions' codes: the contract's digest)
    words = b"".join(word.encode("ascii") + b"\0" for word in vocabulary)
    codes = np.array(list(vocabulary.values()), dtype=np.int32).reshape(-1, 3)
    defaults = MaterialRows.row_of(Material())
    return _Setup(lib, words, codes, defaults, tuple(lib.rt_sdl_decline_names().decode().split()))


def available() -> bool:
    """Whether the C reader can be used (the C core is built and loaded)."""
    return _setup() is not None


@dataclass
class Columns:
    """What the C reader read: the shapes as columns (see tracer.model.ShapeTable) and the rest."""

    kinds: np.ndarray  # (N,) int16, index into tracer.shapes.REGISTRY
    affines: np.ndarray  # (N, 12) float64
    material_ids: np.ndarray  # (N,) int32
    materials: MaterialRows
    parameters: np.ndarray  # (N, tracer.shapes.MAX_PARAMETERS) float64
    lines: np.ndarray  # (N,) int32
    columns: np.ndarray  # (N,) int32
    names: Optional[dict[int, str]]
    lights: list[Light]
    cameras: list[tuple[float, ...]]  # every camera statement's ten numbers, in order
    settings: dict[str, object]  # the settings the text set


def scan(text: str) -> Union[Columns, Declined, None]:
    """The C reader's reading of ``text``; a :class:`Declined` when it leaves the text to the Python reader;
    None when the C core is not loaded."""
    setup = _setup()
    if setup is None:
        return None
    utf8 = _Utf8.of(text)
    if utf8 is None:  # a lone surrogate (in a str made in Python: read_text replaces bad bytes with U+FFFD)
        return Declined("ascii", _SURROGATE.search(text).start())
    lib = setup.lib
    pointer = lib.rt_sdl_read(utf8.data, utf8.size, setup.words, len(setup.words),
                              setup.codes.ctypes.data_as(ctypes.POINTER(ctypes.c_int32)), len(setup.codes),
                              setup.defaults.ctypes.data_as(ctypes.POINTER(ctypes.c_double)), SHARED_LIBM)
    if not pointer:
        return Declined("memory", 0)
    try:
        res = pointer.contents
        if res.status != 0:
            return Declined(setup.reasons[res.status], utf8.characters_before(int(res.decline_offset)))
        return _columns(res, utf8)
    finally:
        lib.rt_sdl_free(pointer)


@dataclass(frozen=True)
class _Utf8:
    """A text's UTF-8 as the C reader gets it, and the way back from its byte offsets to the text's."""

    text: str
    #: In CPython, the address of the str's own UTF-8 (an ASCII str's own bytes; for any other str, a copy
    #: CPython makes once and keeps with the str), valid while ``text`` lives; else an encoded copy (encoding
    #: 100 MB takes a few tenths of a second and as much memory again).
    data: Union[int, bytes]
    size: int  # in bytes

    @staticmethod
    def of(text: str) -> Optional["_Utf8"]:
        """None when ``text`` has no UTF-8 form (it holds a lone surrogate)."""
        if _utf8_and_size is not None:
            size = ctypes.c_ssize_t()
            try:
                address = _utf8_and_size(text, ctypes.byref(size))
            except UnicodeEncodeError:
                return None
            if address:
                return _Utf8(text, address, size.value)
        try:
            data = text.encode("utf-8")
        except UnicodeEncodeError:
            return None
        return _Utf8(text, data, len(data))

    def characters_before(self, offset: int) -> int:
        """The character offset in the text of byte ``offset``: the bytes before it that start a character
        (all but UTF-8's continuation bytes, 10xxxxxx)."""
        if self.size == len(self.text):  # ASCII: bytes are characters
            return offset
        before = np.frombuffer(self.bytes_at(0, offset), dtype=np.uint8)
        return offset - int(np.count_nonzero((before & 0xC0) == 0x80))

    def bytes_at(self, start: int, length: int) -> bytes:
        if isinstance(self.data, bytes):
            return self.data[start:start + length]
        return ctypes.string_at(self.data + start, length)

    def cut(self, start: int, length: int) -> str:
        """The characters of bytes [start, start + length), which start and end characters."""
        if self.size == len(self.text):
            return self.text[start:start + length]
        return self.bytes_at(start, length).decode("utf-8")


def _cpython_utf8_and_size():
    if sys.implementation.name != "cpython":
        return None
    prototype = ctypes.PYFUNCTYPE(ctypes.c_void_p, ctypes.py_object, ctypes.POINTER(ctypes.c_ssize_t))
    return prototype(("PyUnicode_AsUTF8AndSize", ctypes.pythonapi))


_utf8_and_size = _cpython_utf8_and_size()


def _array(pointer, shape: tuple[int, ...], dtype) -> np.ndarray:
    """A copy of the C buffer behind ``pointer``, which is freed after the read."""
    return _view(pointer, shape, dtype).copy()


def _view(pointer, shape: tuple[int, ...], dtype) -> np.ndarray:
    """The C buffer behind ``pointer`` as an array, valid until the read's result is freed."""
    if shape[0] == 0:
        return np.zeros(shape, dtype=dtype)
    return np.ctypeslib.as_array(pointer, shape=shape)  # (of the pointer's type, which is dtype)


def _columns(res, utf8: _Utf8) -> Columns:
    """The columns of a read's result (contract.SdlResult)."""
    n = res.shapes
    # (what becomes Python objects is read in place; what the scene keeps as arrays is copied)
    name_rows = _view(res.name_rows, (res.names, 3), np.int64).tolist()
    # (C strips a name of white space in ASCII; str.strip is the name pattern's \s* beyond ASCII too)
    names = {row: utf8.cut(start, length).strip() for row, start, length in name_rows} or None
    materials = MaterialRows(_view(res.material_rows, (res.materials, MaterialRows.WIDTH), np.float64))  # (a copy)
    lights = [Light(tuple(row[:3]), tuple(row[3:])) for row in _view(res.light_rows, (res.lights, 6),
                                                                       np.float64).tolist()]
    cameras = [tuple(row) for row in _view(res.camera_rows, (res.cameras, 10), np.float64).tolist()]
    settings: dict[str, object] = {}
    if res.settings_set & _SET_GLOBAL_AMBIENT:
        settings["global_ambient"] = tuple(res.global_ambient)
    if res.settings_set & _SET_BACKGROUND:
        settings["background"] = tuple(res.background)
    if res.settings_set & _SET_MIN_REFLECTIVITY:
        settings["min_reflectivity"] = res.min_reflectivity
    if res.settings_set & _SET_MIN_TRANSPARENCY:
        settings["min_transparency"] = res.min_transparency
    if res.settings_set & _SET_MAX_DEPTH:
        settings["max_recursion_depth"] = int(res.max_recursion_depth)
    return Columns(_array(res.kinds, (n,), np.int16), _array(res.affines, (n, 12), np.float64),
                   _array(res.material_ids, (n,), np.int32), materials,
                   _array(res.parameters, (n, shape_registry.MAX_PARAMETERS), np.float64),
                   _array(res.lines, (n,), np.int32), _array(res.columns, (n,), np.int32), names, lights, cameras,
                   settings)


def read(text: str, file: Optional[str] = None) -> Optional[Scene]:
    """The scene in ``text`` as the Python reader would make it, or None when the C reader declines it (or
    the C core is not loaded)."""
    columns = scan(text)
    if not isinstance(columns, Columns):
        return None
    with np.errstate(over="ignore", invalid="ignore"):  # (huge numbers: the checks' answer is what counts)
        for numbers in columns.cameras:  # one the Python reader would refuse: its message is the parser's
            if camera_problem(numbers[0:3], numbers[3:6], numbers[6:9], numbers[9]) is not None:
                return None
    shapes = ShapeTable(columns.kinds, columns.affines, columns.material_ids, columns.materials, columns.parameters,
                        columns.lines, columns.columns, file, columns.names)
    scene = Scene(objects=shapes, lights=columns.lights)
    if columns.cameras:
        numbers = columns.cameras[-1]
        scene.camera = Camera(eye=numbers[0:3], look=numbers[3:6], up=numbers[6:9], view_angle=numbers[9])
    for name, value in columns.settings.items():
        setattr(scene.settings, name, value)
    return scene
