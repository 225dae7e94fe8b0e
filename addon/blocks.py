"""Tracing an image in blocks, coarse to fine, for the render engine and the viewport (no bpy).

The same rule as ``tracer.render`` (the lecture's ``raytrace(scn, blockSize)``): in a pass of stride B one
ray is traced per B x B block, through the block's lower-left pixel, and the whole block takes its
colour; progressive refinement runs B, B/2, ..., 1 and each pass traces only the pixels that are new at
its stride.  What differs is where the rays come from (any function of pixel rows and columns, so that
Blender's camera and viewport can be matched exactly), and how the work is driven: a tile of a pass is
one work item; items are traced in chunks of rays with a cancel check between chunks (so Esc is
honoured *within* a block), by several threads at once, or a time slice at a time for the viewport.

The film is stored bottom row first, as Blender's render results and textures are.
"""
from __future__ import annotations

import concurrent.futures
import threading
import time
from dataclasses import dataclass
from typing import Callable, Iterator, Optional

import numpy as np

from . import deps

RaysFor = Callable[..., tuple[np.ndarray, np.ndarray]]  # (rows, cols, dy, dx) -> (origins, directions)

DEFAULT_TILE = 64
DEFAULT_CHUNK = 2048


def block_passes(block_size: int, progressive: bool) -> list[int]:
    return deps.module("render").block_passes(int(block_size), bool(progressive))


def resolve_threads(threads: int) -> int:
    """0 means the tracer's default: $SDL_TRACER_THREADS, else every core this process may run on."""
    return int(threads) if threads and threads > 0 else deps.module("native").default_threads()


@dataclass(frozen=True)
class WorkItem:
    pass_index: int
    stride: int
    r0: int
    c0: int
    r1: int
    c1: int

    def positions(self):
        """Sample positions of this tile at its stride, and which of them are new in this pass."""
        rows = np.arange(self.r0, self.r1, self.stride)
        cols = np.arange(self.c0, self.c1, self.stride)
        grid_r, grid_c = np.meshgrid(rows, cols, indexing="ij")
        if self.pass_index == 0:
            new = np.ones(grid_r.shape, dtype=bool)
        else:
            new = (grid_r % (2 * self.stride) != 0) | (grid_c % (2 * self.stride) != 0)
        return grid_r, grid_c, new


class Cancelled(Exception):
    pass


class BlockRenderer:
    """Traces ``compiled`` into a ``width`` x ``height`` film; ``rays_for(rows, cols, dy, dx)`` gives the rays
    of film pixels (row 0 at the bottom) at (dx, dy) inside each pixel.

    ``samples`` rays per traced pixel placed by ``sampling`` (tracer.sampling's modes); with ``adaptive`` the
    passes trace one ray per pixel and a last pass traces ``samples`` rays where neighbours differ by more
    than ``threshold``.  ``threads``: with the C core, its own worker threads (one work item at a time);
    with NumPy, work items traced at once.
    """

    def __init__(self, compiled, rays_for: RaysFor, width: int, height: int, *, block_size: int = 1,
                 progressive: bool = False, threads: int = 1, tile: int = DEFAULT_TILE,
                 chunk: Optional[int] = None, alpha: bool = False, backend: str = "auto", samples: int = 1,
                 sampling: str = "jittered", threshold: float = 0.05, seed: int = 0):
        deps.module("sampling").check(int(samples), sampling, float(threshold))
        self.compiled = compiled
        self.rays_for = rays_for
        self.width, self.height = int(width), int(height)
        self.passes = block_passes(block_size, progressive)
        self.samples, self.sampling, self.threshold, self.seed = int(samples), sampling, float(threshold), seed
        self.adaptive = sampling == "adaptive" and self.samples > 1
        self.threads = resolve_threads(threads)
        self.chunk = max(1, int(DEFAULT_CHUNK if chunk is None else chunk))
        self.want_alpha = alpha
        self.backend = backend
        # One RGBA film (what Blender's passes and textures take, so handing it over copies nothing);
        # colour and coverage are views of it.
        self.film = np.zeros((self.height, self.width, 4), dtype=np.float32)
        self.film[..., 3] = 1.0
        self.color = self.film[..., :3]
        self.alpha = self.film[..., 3]
        top = self.passes[0]
        tile = max(int(tile), top)
        tile -= tile % top  # tiles start on multiples of every stride
        self.tile = tile
        self.items = []
        for p, stride in enumerate(self.passes):
            # A coarse pass traces one ray per stride x stride block: its tiles are stride times wider, so
            # each item still traces about tile x tile rays (per-item costs would dominate otherwise).
            side = tile * (stride // self.passes[-1])
            self.items += [WorkItem(p, stride, r, c, min(r + side, self.height), min(c + side, self.width))
                           for r in range(0, self.height, side) for c in range(0, self.width, side)]
        tiles = [(r, c) for r in range(0, self.height, tile) for c in range(0, self.width, tile)]
        if self.adaptive:  # the refinement pass: stride 1, after every block pass
            self.items += [WorkItem(len(self.passes), 1, r, c, min(r + tile, self.height), min(c + tile, self.width))
                           for r, c in tiles]
        self.pass_count = len(self.passes) + self.adaptive
        self.done = 0
        self.seconds = 0.0
        self._local = threading.local()
        self._tracers = []
        self._lock = threading.Lock()
        self._refine: Optional[np.ndarray] = None
        self.backend_name = ""

    # -- tracing ---------------------------------------------------------------------------------------

    def _tracer(self):
        tracer = getattr(self._local, "tracer", None)
        if tracer is None:
            tracer = deps.module("backend").make_tracer(self.compiled, self.backend)
            if getattr(tracer, "name", "") == "c":
                tracer.threads = self.threads  # the C core spreads each chunk over its own threads
            self._local.tracer = tracer
            with self._lock:
                self._tracers.append(tracer)
                self.backend_name = getattr(tracer, "name", "numpy")
        return tracer

    @property
    def item_threads(self) -> int:
        """Work items traced at once: one with the C core (it is already parallel), else ``threads``."""
        self._tracer()
        return 1 if self.backend_name == "c" else self.threads

    def _trace(self, rows: np.ndarray, cols: np.ndarray, per_pixel: int, rng, cancel) -> tuple:
        """Mean colour (and coverage) of ``per_pixel`` rays in each given pixel, in chunks of rays."""
        tracer = self._tracer()
        colors = np.empty((rows.size, 3), dtype=np.float64)
        cover = np.ones(rows.size, dtype=np.float32)
        pixels_per_chunk = max(1, self.chunk // per_pixel)
        for start in range(0, rows.size, pixels_per_chunk):
            if cancel is not None and cancel():
                raise Cancelled()
            stop = min(start + pixels_per_chunk, rows.size)
            r, c = rows[start:stop], cols[start:stop]
            if per_pixel == 1:
                dy = dx = 0.5
            else:
                dy, dx = deps.module("sampling").offsets(per_pixel, self.sampling != "regular", r.size, rng)
                dy, dx = dy.ravel(), dx.ravel()
                r, c = np.repeat(r, per_pixel), np.repeat(c, per_pixel)
            origins, directions = self.rays_for(r, c, dy, dx)
            origins = np.ascontiguousarray(origins, dtype=np.float64)
            directions = np.ascontiguousarray(directions, dtype=np.float64)
            traced = np.asarray(tracer.camera_rays(origins, directions), dtype=np.float64)
            if self.want_alpha:  # coverage: the share of a pixel's rays that hit something
                hit = self._hits(tracer, origins, directions)
                traced = np.where(hit[:, None], traced, 0.0)
                cover[start:stop] = hit.reshape(-1, per_pixel).mean(axis=1)
            colors[start:stop] = traced.reshape(-1, per_pixel, 3).mean(axis=1)
        return colors, cover

    def _hits(self, tracer, origins, directions) -> np.ndarray:
        """Which rays hit anything (for the film's alpha), by the same backend that shades them."""
        if hasattr(tracer, "first_hits"):
            return np.isfinite(tracer.first_hits(origins, directions)["t"])
        return deps.module("trace").first_hits(self.compiled, origins, directions).hit

    def _refine_mask(self) -> np.ndarray:
        with self._lock:  # judged once, on the film every block pass has finished
            if self._refine is None:
                self._refine = deps.module("sampling").contrast_mask(self.color, self.threshold)
            return self._refine

    def trace_item(self, item: WorkItem, cancel: Optional[Callable[[], bool]] = None) -> WorkItem:
        # (one ray per pixel goes through the pixel's centre: no random numbers)
        rng = np.random.default_rng((self.seed, item.pass_index, item.r0, item.c0)) if self.samples > 1 else None
        if item.pass_index >= len(self.passes):  # adaptive refinement
            rr, cc = np.nonzero(self._refine_mask()[item.r0:item.r1, item.c0:item.c1])
            rr, cc = rr + item.r0, cc + item.c0
            if rr.size:
                colors, cover = self._trace(rr, cc, self.samples, rng, cancel)
                self.color[rr, cc] = colors
                self.alpha[rr, cc] = cover
            return item
        grid_r, grid_c, new = item.positions()
        samples = self.color[grid_r, grid_c]
        cover = self.alpha[grid_r, grid_c]
        per_pixel = 1 if self.adaptive else self.samples
        colors, hit = self._trace(grid_r[new], grid_c[new], per_pixel, rng, cancel)
        samples[new] = colors
        cover[new] = hit
        s = item.stride
        block = np.repeat(np.repeat(samples, s, axis=0), s, axis=1)
        self.color[item.r0:item.r1, item.c0:item.c1] = block[: item.r1 - item.r0, : item.c1 - item.c0]
        block_a = np.repeat(np.repeat(cover, s, axis=0), s, axis=1)
        self.alpha[item.r0:item.r1, item.c0:item.c1] = block_a[: item.r1 - item.r0, : item.c1 - item.c0]
        return item

    def pass_items(self, pass_index: int) -> list[WorkItem]:
        return [i for i in self.items if i.pass_index == pass_index]

    def run(self, cancel: Optional[Callable[[], bool]] = None,
            on_item: Optional[Callable[[WorkItem], None]] = None, poll: float = 0.05) -> None:
        """Trace everything.  ``cancel`` and ``on_item`` are only ever called on the calling thread (Blender's
        API wants that); worker threads see cancellation through an event checked between chunks."""
        started = time.perf_counter()
        stop = threading.Event()

        def stopped() -> bool:
            return stop.is_set()

        try:
            if self.item_threads == 1:
                for item in self.items:
                    self.trace_item(item, cancel)
                    self.done += 1
                    if on_item is not None:
                        on_item(item)
                return
            with concurrent.futures.ThreadPoolExecutor(max_workers=self.item_threads,
                                                       thread_name_prefix="sdl-trace") as pool:
                try:
                    for p in range(self.pass_count):  # a pass reuses the samples of the one before
                        pending = {pool.submit(self.trace_item, item, stopped) for item in self.pass_items(p)}
                        while pending:
                            finished, pending = concurrent.futures.wait(
                                pending, timeout=poll, return_when=concurrent.futures.FIRST_COMPLETED)
                            for future in finished:
                                item = future.result()
                                self.done += 1
                                if on_item is not None:
                                    on_item(item)
                            if cancel is not None and cancel():
                                raise Cancelled()
                except BaseException:
                    stop.set()
                    raise
        finally:
            self.seconds += time.perf_counter() - started

    def steps(self) -> Iterator[WorkItem]:
        """The remaining items one at a time, on the calling thread (for time-sliced viewport drawing)."""
        while self.done < len(self.items):
            item = self.items[self.done]
            started = time.perf_counter()
            self.trace_item(item)
            self.seconds += time.perf_counter() - started
            self.done += 1
            yield item

    def run_for(self, seconds: float) -> bool:
        """Trace items for about ``seconds``; True when the image is finished."""
        deadline = time.perf_counter() + seconds
        for _ in self.steps():
            if time.perf_counter() >= deadline:
                break
        return self.finished

    # -- results ---------------------------------------------------------------------------------------

    @property
    def finished(self) -> bool:
        return self.done >= len(self.items)

    @property
    def fraction(self) -> float:
        return self.done / max(1, len(self.items))

    def current_pass(self) -> int:
        return self.items[min(self.done, len(self.items) - 1)].pass_index if self.items else 0

    def rgba(self) -> np.ndarray:
        """(height, width, 4) float32, bottom row first; colour as traced (linear), premultiplied by alpha.
        The film itself, not a copy: it changes while tracing goes on."""
        return self.film

    def counts(self):
        total = deps.module("trace").RayCounts()
        for tracer in self._tracers:
            total.add(tracer.counts)
        return total
