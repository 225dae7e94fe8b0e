"""The C core: the per-ray work of tracer.trace.Tracer in C, on all cores, loaded with ctypes.

This package's own module is the library: loaded (and checked against tracer/native/contract.py) on
import, with the C readers and builders the lower layers use (:func:`scan_numbers` and :func:`scan_3vn` for
the readers, :func:`build_mesh_bvh` for tracer.compile).  ``load_error`` is None when the library is built
and loaded, else a short reason (no compiler, a compile error...); then the C core's tracer cannot be made
and tracer.backend uses the NumPy path.  An installed package loads the library CMake built for it; a
checkout compiles it on first import when missing or out of date (see :mod:`tracer.native.build`).

The C core as a backend, tracing compiled scenes, is :class:`tracer.native.tracer.NativeTracer` (with
:mod:`tracer.native.flatten`, which lays a compiled scene out for it): a layer above tracer.compile and
tracer.trace, which this module is below.
"""
from __future__ import annotations

import ctypes
import os
from typing import BinaryIO, Optional

import numpy as np

from .. import signals
from ..errors import TracerError
from ..intersect.mesh import NODE
from ..threads import default_threads
from . import build as _builder
from . import contract
from .build import BuildError

_lib: Optional[ctypes.CDLL] = None
load_error: Optional[str] = None



#: A library file to load instead of looking for one ($SDL_TRACER_LIBRARY; make sanitize uses it).
LIBRARY_OVERRIDE = "SDL_TRACER_LIBRARY"


def _load() -> ctypes.CDLL:
    """$SDL_TRACER_LIBRARY if set; else the prebuilt library of an installed package if it loads, else the
    development build."""
    override = os.environ.get(LIBRARY_OVERRIDE)
    if override:
        return _configure(ctypes.CDLL(override))
    prebuilt = _builder.prebuilt_library()
    if prebuilt is None:
        return _configure(ctypes.CDLL(str(_builder.build())))
    try:
        return _configure(ctypes.CDLL(str(prebuilt)))
    except (OSError, BuildError) as err:
        problem = f"the prebuilt C core {prebuilt} did not load ({err})"
    try:
        return _configure(ctypes.CDLL(str(_builder.build())))
    except (OSError, BuildError) as err:
        raise BuildError(f"{problem}, and building it failed: {err}") from None


def _configure(lib: ctypes.CDLL) -> ctypes.CDLL:
    """Declares the functions' types (contract.FUNCTIONS) and checks that the library speaks this contract."""
    contract.declare(lib)
    mismatch = layout_mismatch(lib)
    if mismatch:
        raise BuildError(mismatch)
    return lib


def c_layout(lib: ctypes.CDLL, which: int = 0) -> list[tuple[int, int]]:
    """(offset, size) of every field of struct ``which`` of contract.STRUCTS (SceneDesc by default) as the C
    compiler laid it out, in the table's order."""
    capacity = len(contract.STRUCTS[which].fields)
    offsets, sizes = np.zeros(capacity, np.int64), np.zeros(capacity, np.int64)
    count = lib.rt_struct_layout(which, _ptr(offsets, ctypes.c_int64), _ptr(sizes, ctypes.c_int64), capacity)
    if count != capacity:
        return [(-1, -1)] * max(0, int(count))
    return list(zip(offsets.tolist(), sizes.tolist()))


def ctypes_layout(which: int = 0) -> list[tuple[int, int]]:
    """(offset, size) of every field of the ctypes mirror of struct ``which`` (contract.CTYPES)."""
    struct = contract.STRUCTS[which]
    mirror = contract.CTYPES[struct.name]
    return [(getattr(mirror, f.name).offset, getattr(mirror, f.name).size) for f in struct.fields]


def layout_mismatch(lib: ctypes.CDLL) -> Optional[str]:
    """None if the library was built from this contract and lays every struct out as ctypes does, else why
    not."""
    built_from = lib.rt_contract_digest().decode()
    if built_from != contract.digest():
        return (f"the C core was built from another contract ({built_from}, not {contract.digest()}): "
                "regenerate contract.h (python -m tracer.native.contract) and rebuild")
    for which, struct in enumerate(contract.STRUCTS):
        c, py = c_layout(lib, which), ctypes_layout(which)
        if len(c) != len(py):
            return f"the C core's {struct.name} has {len(c)} fields, contract.py {len(py)}"
        for f, (c_off, c_size), (py_off, py_size) in zip(struct.fields, c, py):
            if (c_off, c_size) != (py_off, py_size):
                return (f"{struct.name}.{f.name} is at offset {c_off} ({c_size} bytes) in C but {py_off} "
                        f"({py_size} bytes) in ctypes")
        if lib.rt_struct_size(which) != ctypes.sizeof(contract.CTYPES[struct.name]):
            return f"the C core's {struct.name} size differs from its ctypes mirror's"
    return None


def _rays(origins, directions) -> tuple[np.ndarray, np.ndarray]:
    o = np.ascontiguousarray(np.asarray(origins, dtype=np.float64).reshape(-1, 3))
    d = np.ascontiguousarray(np.asarray(directions, dtype=np.float64).reshape(-1, 3))
    if o.shape != d.shape:
        raise ValueError("origins and directions must both be (N, 3)")
    return o, d


def _ptr(array: np.ndarray, ctype):
    return array.ctypes.data_as(ctypes.POINTER(ctype))


def scan_numbers(data: bytes) -> Optional[np.ndarray]:
    """The values of the white-space separated decimal numbers in ``data`` (see scan.h), or None when it
    holds anything else: a word that is not such a number, a byte outside ASCII.  Needs the C core."""
    if _lib is None:
        raise TracerError(f"the C core is not available: {load_error}")
    bad = ctypes.c_int64(-1)
    count = _lib.rt_scan_numbers(data, len(data), None, 0, ctypes.byref(bad))
    if count < 0:
        return None
    values = np.empty(count, dtype=np.float64)
    if _lib.rt_scan_numbers(data, len(data), _ptr(values, ctypes.c_double), count, ctypes.byref(bad)) != count:
        return None
    return values


#: The .3vn reader reads a file this many bytes at a time: its peak is the mesh's arrays, not the file.
SCAN_PIECE = 1 << 22
_SPACE = b" \t\n\r\x0b\x0c\x1c\x1d\x1e\x1f"  # scan.h's scan_is_space


def scan_3vn(handle: BinaryIO) -> Optional[tuple[np.ndarray, ...]]:
    """A ``.3vn`` file's (vertices (V, 3), normals (N, 3), face sizes (F,) int64, vertex indices and normal
    indices (sum of sizes,) int32), read from ``handle`` (at its start; it is read twice) a piece at a time
    straight into those arrays (see scan.h), or None when the file is not exactly a well-formed ``.3vn`` of
    decimal numbers.  Needs the C core."""
    if _lib is None:
        raise TracerError(f"the C core is not available: {load_error}")
    state = np.zeros(_lib.rt_scan3_state_size(), np.int64)
    state_ptr = _ptr(state, ctypes.c_int64)
    start = handle.tell()
    for piece in _whole_word_pieces(handle):  # first pass: the counts, and the words after them
        if _lib.rt_scan_3vn(state_ptr, piece, len(piece), None, None, None, None, None) != 0:
            return None
    corners = _lib.rt_scan_3vn_end(state_ptr, 0)
    if corners < 0:
        return None
    counts = state[1:5].copy()  # SCAN3_V, SCAN3_N, SCAN3_F, SCAN3_CORNERS
    n_vertices, n_normals, n_faces, _ = counts.tolist()
    out = (np.empty((n_vertices, 3)), np.empty((n_normals, 3)), np.empty(n_faces, np.int64),
           np.empty(corners, np.int32), np.empty(corners, np.int32))
    pointers = [_ptr(a, t) for a, t in zip(out, (ctypes.c_double, ctypes.c_double, ctypes.c_int64, ctypes.c_int32,
                                                  ctypes.c_int32))]
    state[:] = 0
    state[1:5] = counts
    handle.seek(start)
    for piece in _whole_word_pieces(handle):
        if _lib.rt_scan_3vn(state_ptr, piece, len(piece), *pointers) != 0:
            return None
    return out if _lib.rt_scan_3vn_end(state_ptr, 1) == 0 else None


def _whole_word_pieces(handle: BinaryIO):
    """The file's bytes in pieces of about SCAN_PIECE, each ending at white space (or the file's end)."""
    carry = b""
    while True:
        block = handle.read(SCAN_PIECE)
        if not block:
            if carry:
                yield carry
            return
        block = carry + block
        cut = _last_space(block)
        if cut < 0:
            carry = block
            continue
        yield block[:cut + 1]
        carry = block[cut + 1:]


def _last_space(block: bytes) -> int:
    return max(block.rfind(bytes([space])) for space in _SPACE)


def build_mesh_bvh(vertices: np.ndarray, tri_vertex: np.ndarray, leaf_size: int, bins: int, pad: float,
                   threads: Optional[int] = None) -> tuple[np.ndarray, np.ndarray]:
    """(nodes, tri_order) of TriangleMesh's builder (the same tree, see bvh_build.h), built in C over the
    triangles ``tri_vertex`` ((T, 3) indices, in range) of ``vertices`` ((V, 3)): NODE records with boxes
    grown by ``pad`` and rounded outward, and the leaf order (int32).  On ``threads`` threads (default:
    default_threads()); the tree does not depend on how many.  Needs the C core."""
    if _lib is None:
        raise TracerError(f"the C core is not available: {load_error}")
    vertices = np.ascontiguousarray(vertices, dtype=np.float64).reshape(-1, 3)
    tri_vertex = np.ascontiguousarray(tri_vertex, dtype=np.int32).reshape(-1, 3)
    n = len(tri_vertex)
    order = np.empty(n, np.int32)
    buffer = ctypes.c_void_p()
    count = _lib.rt_build_mesh_bvh(n, _ptr(vertices, ctypes.c_double), _ptr(tri_vertex, ctypes.c_int32),
                                   int(leaf_size), int(bins), float(pad),
                                   int(default_threads() if threads is None else threads),
                                   _ptr(order, ctypes.c_int32), ctypes.byref(buffer))
    if count < 0:
        raise MemoryError("the C core ran out of memory building a mesh BVH")
    try:
        nodes = np.empty(count, dtype=NODE)
        if count:
            ctypes.memmove(nodes.ctypes.data, buffer.value, count * NODE.itemsize)
    finally:
        _lib.rt_free(buffer)
    return nodes, order


try:
    _lib = _load()
except (BuildError, OSError) as err:
    load_error = str(err) or type(err).__name__
else:
    signals.attach_library(_lib)  # (its signal handler and watchdog, while a command works: interrupt.h)
