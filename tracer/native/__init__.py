"""The C core: the per-ray work of tracer.trace.Tracer in C, on all cores, loaded with ctypes.

``load_error`` is None when the library is built and loaded, else a short reason (no compiler, a
compile error...); then :class:`NativeTracer` cannot be made and tracer.backend uses the NumPy path.
An installed package loads the library CMake built for it; a checkout compiles it on first import when
missing or out of date (see :mod:`tracer.native.build`).

:class:`NativeTracer` is a backend (see tracer.backend): ``name``, ``counts``, ``camera_rays``.  It also
answers the queries the tests compare with the NumPy path: :meth:`NativeTracer.object_hits` (whole-line
hits of one top-level object, as ``obj.intersect``), :meth:`NativeTracer.first_hits`,
:meth:`NativeTracer.occluded` and :meth:`NativeTracer.texture_colors`.
"""
from __future__ import annotations

import ctypes
import os
import weakref
from dataclasses import fields
from typing import BinaryIO, Optional

import numpy as np

from ..compile import CompiledScene
from ..errors import RenderCancelled, TracerError
from ..intersect.hits import HitArrays
from ..savings import RaySavings, sealed_table
from ..threads import default_threads
from ..trace import RayCounts
from . import contract, flatten
from . import build as _builder
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
    from ..intersect.mesh import NODE

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


def interrupt_library() -> Optional[ctypes.CDLL]:
    """The loaded library, for tracer.signals (its rt_interrupt_* functions, interrupt.h), or None."""
    return _lib


def _flat_scene(compiled: CompiledScene) -> flatten.FlatScene:
    """The FlatScene of a compiled scene, made once per compiled scene and kept on it (a second render of
    it flattens nothing), again only when the mesh constants it reads have changed.  (The tolerances it
    passes on are the compiled scene's own: compile_scene compiles again when they change.)"""
    from ..intersect import mesh as mesh_module

    key = tuple(getattr(mesh_module, name, None) for name in flatten.MESH_CONSTANTS)
    cached = getattr(compiled, "_flat_cache", None)
    if cached is not None and cached[0] == key:
        return cached[1]
    flat = flatten.FlatScene(compiled)
    compiled._flat_cache = (key, flat)
    return flat


class CoreScene:
    """The C core's scene made from a FlatScene: its checked description, mesh views, object hierarchy and
    sealed-lights table.  Made once per flat scene (when first traced) and kept on it (``flat.core``),
    shared by every NativeTracer of it, edited in place (:meth:`edit`), released with the flat scene."""

    def __init__(self, flat: flatten.FlatScene, threads: int):
        message = ctypes.create_string_buffer(256)
        # (the object hierarchy is built on the tracer's threads; it is the same tree on any number)
        handle = _lib.rt_create_threaded(ctypes.byref(flat.desc), threads, message, len(message))
        if not handle:
            reason = message.value.decode(errors="replace") or "no reason given"
            raise TracerError(f"the C core refused the scene description: {reason}")
        self.handle = handle
        self._release = weakref.finalize(self, _lib.rt_destroy, handle)
        self._sealed_sent: Optional[np.ndarray] = None

    @classmethod
    def of(cls, compiled: CompiledScene, threads: int) -> "CoreScene":
        flat = _flat_scene(compiled)
        core = getattr(flat, "core", None)
        if core is None:
            core = flat.core = cls(flat, threads)
        return core

    def send_sealed(self, sealed: Optional[np.ndarray]) -> None:
        """Give the C core this sealed-lights table (objects x lights; None: none), unless it has it already."""
        if sealed is self._sealed_sent:
            return
        if sealed is None:
            done = _lib.rt_set_sealed(self.handle, None, 0)
        else:
            flat = np.ascontiguousarray(sealed, dtype=np.uint8).reshape(-1)
            done = _lib.rt_set_sealed(self.handle, _ptr(flat if flat.size else np.zeros(1, np.uint8), ctypes.c_uint8),
                                      flat.size)
        if done != 0:
            raise MemoryError("the C core ran out of memory (or the sealed table has the wrong size)")
        self._sealed_sent = sealed

    def edit(self, flat: flatten.FlatScene, objects: Optional[np.ndarray], meshes: bool, rebuild: bool,
             threads: int, removed: Optional[np.ndarray] = None) -> None:
        """The C core takes ``flat``'s description as it is now (see rt_edit): the hierarchy refitted to the
        boxes of ``objects`` (None: every object), or built anew with ``rebuild`` (or where an object in it
        became unbounded); with ``removed`` (ascending indices before), those objects were removed and the
        objects after the survivors added; ``meshes``: the mesh tables may have changed."""
        bits = contract.EDIT_BITS
        flags = (bits["meshes"] if meshes else 0) | (bits["rebuild"] if rebuild else 0) | \
            (bits["objects"] if removed is not None else 0)
        if removed is not None:
            objects = removed
        listed = np.ascontiguousarray(np.zeros(1, np.int64) if objects is None or not len(objects) else objects,
                                      dtype=np.int64)
        message = ctypes.create_string_buffer(256)
        if _lib.rt_edit(self.handle, ctypes.byref(flat.desc), _ptr(listed, ctypes.c_int64),
                        -1 if objects is None else len(objects), flags, threads, message, len(message)) != 0:
            self._release()  # (a scene refused half way is never traced)
            flat.core = None
            reason = message.value.decode(errors="replace") or "no reason given"
            raise TracerError(f"the C core refused the edited scene: {reason}")
        if self._sealed_sent is not None and self._sealed_sent.shape != (flat.desc.n_objects, flat.desc.n_lights):
            self._sealed_sent = None  # (rt_edit dropped it)


try:
    _lib = _load()
except (BuildError, OSError) as err:
    load_error = str(err) or type(err).__name__


class NativeTracer:
    """Shades batches of camera rays in C for one compiled scene, counting every ray it casts."""

    name = "c"

    @staticmethod
    def unsupported(compiled: CompiledScene) -> Optional[str]:
        """None if the C core can trace this scene, else the reason it cannot."""
        if _lib is None:
            return f"the C core is not available: {load_error}"
        return flatten.unsupported_reason(compiled)

    def __init__(self, compiled: CompiledScene, threads: Optional[int] = None,
                 savings: Optional[RaySavings] = None):
        if _lib is None:
            raise TracerError(f"the C core is not available: {load_error}")
        reason = flatten.unsupported_reason(compiled)
        if reason is not None:
            raise TracerError(f"the C core cannot trace this scene: {reason}")
        self.scene = compiled
        self.counts = RayCounts()
        self.threads = threads or default_threads()
        self._flat = _flat_scene(compiled)  # owns the arrays the C side points into
        self._core = CoreScene.of(compiled, self.threads)
        self._handle = self._core.handle
        self.savings = RaySavings() if savings is None else savings
        if self.savings.inside_shadows and "shadows" in compiled.effects:
            self._core.send_sealed(sealed_table(compiled))
        #: ``cancel() -> bool``, asked every 50 ms while a batch is traced: True stops it (RenderCancelled).
        self.cancel = None
        self._stop = np.zeros(1, dtype=np.int32)  # the flag the C core polls at every ray

    def object_tree(self) -> tuple[bytes, np.ndarray, tuple[int, ...]]:
        """The C core's object hierarchy as built (for tests): its PairNode records as bytes, the bounded
        objects in leaf order, and (root leaf's first item, its count, depth, items)."""
        root = np.zeros(5, dtype=np.int64)
        count = _lib.rt_object_tree(self._handle, None, None, _ptr(root, ctypes.c_int64))
        pairs = ctypes.create_string_buffer(max(1, int(count * root[4])))
        items = np.zeros(max(1, int(root[3])), dtype=np.int64)
        _lib.rt_object_tree(self._handle, pairs, _ptr(items, ctypes.c_int64), _ptr(root, ctypes.c_int64))
        return pairs.raw[:int(count * root[4])], items[:int(root[3])], tuple(root[:4].tolist())

    def close(self) -> None:
        """Let go of the scene (the C core's scene itself lives as long as the compiled scene's FlatScene)."""
        self._handle = self._core = None

    def camera_rays(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        o, d = _rays(origins, directions)
        colors = np.empty_like(o)
        counts = np.zeros(len(fields(RayCounts)), dtype=np.int64)
        status = self._polling_cancel(lambda: _lib.rt_trace(
            self._handle, len(o), _ptr(o, ctypes.c_double), _ptr(d, ctypes.c_double),
            _ptr(colors, ctypes.c_double), _ptr(counts, ctypes.c_int64), self.threads, float(self.savings.cutoff),
            self.savings.flags(), int(self.savings.ray_budget), _ptr(self._stop, ctypes.c_int32)))
        if status == -2:  # stopped: by a signal (whose Python handler runs now) or by self.cancel
            raise RenderCancelled("render cancelled")
        if status != 0:
            raise MemoryError("the C core ran out of memory")
        self.counts.add(RayCounts(*(int(c) for c in counts)))
        return colors

    def _polling_cancel(self, call):
        """``call()`` (a C function that polls self._stop), asking ``self.cancel`` every 50 ms meanwhile:
        the call runs on a thread of its own (ctypes lets go of the interpreter while C runs) and this one
        sets the flag when cancel() says so, or when it is interrupted itself."""
        self._stop[0] = 0
        if self.cancel is None:
            return call()
        import threading  # (here: a command-line render, which has no cancel callback, never loads it)

        outcome = []
        worker = threading.Thread(target=lambda: outcome.append(call()), name="sdl-tracer-batch", daemon=True)
        worker.start()
        try:
            while worker.is_alive():
                worker.join(0.05)
                if worker.is_alive() and self.cancel():
                    self._stop[0] = 1
        finally:
            self._stop[0] = 1  # (a no-op when the batch is done; else it ends it before this frame unwinds)
            worker.join()
            self._stop[0] = 0
        return outcome[0]

    def first_hits(self, origins, directions) -> dict[str, np.ndarray]:
        """The nearest hit with t > 0 per ray: t (inf on a miss), unit world normal, shape, object, entering."""
        o, d = _rays(origins, directions)
        n = len(o)
        out = dict(t=np.empty(n), normal=np.empty((n, 3)), shape=np.empty(n, np.int32),
                   obj=np.empty(n, np.int32), entering=np.empty(n, np.int8))
        if _lib.rt_first_hits(self._handle, n, _ptr(o, ctypes.c_double), _ptr(d, ctypes.c_double),
                              _ptr(out["t"], ctypes.c_double), _ptr(out["normal"], ctypes.c_double),
                              _ptr(out["shape"], ctypes.c_int32), _ptr(out["obj"], ctypes.c_int32),
                              _ptr(out["entering"], ctypes.c_int8), self.threads) == -1:
            raise MemoryError("the C core ran out of memory")
        out["entering"] = out["entering"].astype(bool)
        return out

    def occluded(self, origins, directions, t_max: float = 1.0) -> np.ndarray:
        """Shadow feelers: is anything on origin + t direction, 0 < t < t_max?"""
        o, d = _rays(origins, directions)
        blocked = np.empty(len(o), np.int8)
        if _lib.rt_occluded(self._handle, len(o), _ptr(o, ctypes.c_double), _ptr(d, ctypes.c_double),
                            float(t_max), _ptr(blocked, ctypes.c_int8), self.threads) == -1:
            raise MemoryError("the C core ran out of memory")
        return blocked.astype(bool)

    def texture_colors(self, shape, points, parts, uv=None) -> np.ndarray:
        """Texture colours (N, 3) at world ``points`` on primitives ``shape`` hit on ``parts`` (at barycentrics
        ``uv`` (N, 2) on meshes, or None), as ``compiled.textures.colors`` (1 where untextured)."""
        p = np.ascontiguousarray(np.asarray(points, dtype=np.float64).reshape(-1, 3))
        s = np.ascontiguousarray(np.asarray(shape, dtype=np.int32).reshape(-1))
        q = np.ascontiguousarray(np.asarray(parts, dtype=np.int32).reshape(-1))
        b = None if uv is None else np.ascontiguousarray(np.asarray(uv, dtype=np.float64).reshape(-1, 2))
        if not len(p) == len(s) == len(q) or (b is not None and len(b) != len(p)):
            raise ValueError("shape, points, parts and uv must have the same length")
        out = np.empty_like(p)
        bary = None if b is None else _ptr(b, ctypes.c_double)
        if _lib.rt_texture_colors(self._handle, len(p), _ptr(s, ctypes.c_int32), _ptr(p, ctypes.c_double),
                                  _ptr(q, ctypes.c_int32), bary, _ptr(out, ctypes.c_double)) != 0:
            raise IndexError("primitive index out of range")
        return out

    def object_hits(self, index: int, origin, direction) -> HitArrays:
        """Whole-line hits of top-level object ``index`` for one ray, as ``compiled.objects[index].intersect``
        (world normals, not unit; only finite hits, so K is the number of hits)."""
        o, d = _rays(origin, direction)
        capacity = 64
        while True:
            t = np.empty(capacity)
            entering = np.empty(capacity, np.int8)
            normal = np.empty((capacity, 3))
            shape = np.empty(capacity, np.int32)
            part = np.empty(capacity, np.int32)
            uv = np.empty((capacity, 2))
            inside = np.zeros(1, np.int8)
            n = _lib.rt_object_hits(self._handle, int(index), _ptr(o, ctypes.c_double), _ptr(d, ctypes.c_double),
                                    capacity, _ptr(t, ctypes.c_double), _ptr(entering, ctypes.c_int8),
                                    _ptr(normal, ctypes.c_double), _ptr(shape, ctypes.c_int32),
                                    _ptr(part, ctypes.c_int32), _ptr(uv, ctypes.c_double),
                                    _ptr(inside, ctypes.c_int8))
            if n < 0:
                raise MemoryError("the C core ran out of memory (or the object index is out of range)")
            if n <= capacity:
                break
            capacity = int(n)
        return HitArrays(t=t[None, :n].copy(), entering=entering[None, :n].astype(bool), normal=normal[None, :n].copy(),
                         part=part[None, :n].copy(), uv=uv[None, :n].copy(), inside_at_start=inside.astype(bool),
                         shape=shape[None, :n].copy())
