"""The C core as a backend: :class:`NativeTracer` shades camera rays of a compiled scene in C, on all cores.

It is a backend as tracer.trace.Tracer is (see tracer.backend): ``name``, ``counts``, ``camera_rays``.  It
also answers the queries the tests compare with the NumPy path: :meth:`NativeTracer.object_hits` (whole-line
hits of one top-level object, as ``obj.intersect``), :meth:`NativeTracer.first_hits`,
:meth:`NativeTracer.occluded` and :meth:`NativeTracer.texture_colors`.  The scene reaches the C core as a
:class:`tracer.native.flatten.FlatScene`, made once per compiled scene; the library itself (``_lib``, and
``load_error`` when it could not be loaded) is the package's module, :mod:`tracer.native`.
"""
from __future__ import annotations

import ctypes
import weakref
from dataclasses import fields
from typing import Optional

import numpy as np

from .. import native as library
from ..compile import CompiledScene
from ..errors import RenderCancelled, TracerError
from ..intersect import mesh as mesh_module
from ..intersect.hits import HitArrays
from ..savings import RaySavings
from ..skippable import sealed_table
from ..threads import default_threads
from ..trace import RayCounts
from . import _ptr, _rays, contract, flatten


def _flat_scene(compiled: CompiledScene) -> flatten.FlatScene:
    """The FlatScene of a compiled scene, made once per compiled scene and kept on it (a second render of
    it flattens nothing), again only when the mesh constants it reads have changed.  (The tolerances it
    passes on are the compiled scene's own: compile_scene compiles again when they change.)"""
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
        handle = library._lib.rt_create_threaded(ctypes.byref(flat.desc), threads, message, len(message))
        if not handle:
            reason = message.value.decode(errors="replace") or "no reason given"
            raise TracerError(f"the C core refused the scene description: {reason}")
        self.handle = handle
        self._release = weakref.finalize(self, library._lib.rt_destroy, handle)
        self._sealed_sent: Optional[np.ndarray] = None

    @classmethod
    def of(cls, compiled: CompiledScene, threads: int) -> "CoreScene":
        flat = _flat_scene(compiled)
        core = getattr(flat, "core", None)
        if core is None:
            core = flat.core = cls(flat, threads)
        return core

    @property
    def sealed_sent(self) -> bool:
        """Whether the C core holds a sealed-lights table (a tracer that skips feelers from inside sent it)."""
        return self._sealed_sent is not None

    def send_sealed(self, sealed: Optional[np.ndarray]) -> None:
        """Give the C core this sealed-lights table (objects x lights; None: none), unless it has it already."""
        if sealed is self._sealed_sent:
            return
        if sealed is None:
            done = library._lib.rt_set_sealed(self.handle, None, 0)
        else:
            flat = np.ascontiguousarray(sealed, dtype=np.uint8).reshape(-1)
            table = _ptr(flat if flat.size else np.zeros(1, np.uint8), ctypes.c_uint8)
            done = library._lib.rt_set_sealed(self.handle, table, flat.size)
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
        if library._lib.rt_edit(self.handle, ctypes.byref(flat.desc), _ptr(listed, ctypes.c_int64),
                                -1 if objects is None else len(objects), flags, threads, message,
                                len(message)) != 0:
            self._release()  # (a scene refused half way is never traced)
            flat.core = None
            reason = message.value.decode(errors="replace") or "no reason given"
            raise TracerError(f"the C core refused the edited scene: {reason}")
        if self._sealed_sent is not None and self._sealed_sent.shape != (flat.desc.n_objects, flat.desc.n_lights):
            self._sealed_sent = None  # (rt_edit dropped it)


class NativeTracer:
    """Shades batches of camera rays in C for one compiled scene, counting every ray it casts."""

    name = "c"

    @staticmethod
    def unsupported(compiled: CompiledScene) -> Optional[str]:
        """None if the C core can trace this scene, else the reason it cannot."""
        if library._lib is None:
            return f"the C core is not available: {library.load_error}"
        return flatten.unsupported_reason(compiled)

    def __init__(self, compiled: CompiledScene, threads: Optional[int] = None,
                 savings: Optional[RaySavings] = None):
        if library._lib is None:
            raise TracerError(f"the C core is not available: {library.load_error}")
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
        count = library._lib.rt_object_tree(self._handle, None, None, _ptr(root, ctypes.c_int64))
        pairs = ctypes.create_string_buffer(max(1, int(count * root[4])))
        items = np.zeros(max(1, int(root[3])), dtype=np.int64)
        library._lib.rt_object_tree(self._handle, pairs, _ptr(items, ctypes.c_int64), _ptr(root, ctypes.c_int64))
        return pairs.raw[:int(count * root[4])], items[:int(root[3])], tuple(root[:4].tolist())

    def close(self) -> None:
        """Let go of the scene (the C core's scene itself lives as long as the compiled scene's FlatScene)."""
        self._handle = self._core = None

    def camera_rays(self, origins: np.ndarray, directions: np.ndarray) -> np.ndarray:
        o, d = _rays(origins, directions)
        colors = np.empty_like(o)
        counts = np.zeros(len(fields(RayCounts)), dtype=np.int64)
        status = self._polling_cancel(lambda: library._lib.rt_trace(
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
        import threading  # deferred: a command-line render, which has no cancel callback, never loads it

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
        if library._lib.rt_first_hits(self._handle, n, _ptr(o, ctypes.c_double), _ptr(d, ctypes.c_double),
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
        if library._lib.rt_occluded(self._handle, len(o), _ptr(o, ctypes.c_double), _ptr(d, ctypes.c_double),
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
        if library._lib.rt_texture_colors(self._handle, len(p), _ptr(s, ctypes.c_int32),
                                          _ptr(p, ctypes.c_double), _ptr(q, ctypes.c_int32), bary,
                                          _ptr(out, ctypes.c_double)) != 0:
            raise IndexError("primitive index out of range")
        return out

    def mesh_wide_nodes(self, mesh: int) -> int:
        """Nodes of mesh ``mesh``'s four-wide tree (tracer/native/mesh_wide.h, 128 bytes each), 0 where the C
        core walks it as a binary tree (SDL_TRACER_MESH_BVH=binary, or boxes that do not nest)."""
        count = library._lib.rt_mesh_wide_nodes(self._handle, int(mesh))
        if count < 0:
            raise IndexError(f"no mesh {mesh} in this scene")
        return int(count)

    def mesh_box_test(self) -> str:
        """How the C core's mesh walks test boxes in this scene (tracer/native/mesh_wide.h), chosen when it was
        made: "avx2" where the CPU has AVX2, else "sse2" (also with SDL_TRACER_SIMD=sse2), "scalar"
        (SDL_TRACER_SIMD=0, or a build without SSE2), "binary" (SDL_TRACER_MESH_BVH=binary: no wide tree)."""
        return ("binary", "scalar", "sse2", "avx2")[library._lib.rt_mesh_box_test(self._handle)]

    def object_hits(self, index: int, origin, direction) -> HitArrays:
        """Whole-line hits of top-level object ``index`` for one ray, as ``compiled.objects[index].intersect``
        (world normals, not unit, error bounds and offsets; only finite hits, so K is the number of hits)."""
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
            error, offset = np.empty(capacity), np.empty(capacity)
            n = library._lib.rt_object_hits(self._handle, int(index), _ptr(o, ctypes.c_double),
                                            _ptr(d, ctypes.c_double), capacity, _ptr(t, ctypes.c_double),
                                            _ptr(entering, ctypes.c_int8), _ptr(normal, ctypes.c_double),
                                            _ptr(shape, ctypes.c_int32), _ptr(part, ctypes.c_int32),
                                            _ptr(uv, ctypes.c_double), _ptr(inside, ctypes.c_int8),
                                            _ptr(error, ctypes.c_double), _ptr(offset, ctypes.c_double))
            if n < 0:
                raise MemoryError("the C core ran out of memory (or the object index is out of range)")
            if n <= capacity:
                break
            capacity = int(n)
        return HitArrays(t=t[None, :n].copy(), entering=entering[None, :n].astype(bool), normal=normal[None, :n].copy(),
                         part=part[None, :n].copy(), uv=uv[None, :n].copy(), inside_at_start=inside.astype(bool),
                         shape=shape[None, :n].copy(), error=error[None, :n].copy(), offset=offset[None, :n].copy())
