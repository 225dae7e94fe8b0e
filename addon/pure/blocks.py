"""Tracing an image in blocks, coarse to fine, for the render engine and the viewport (no bpy).

The passes, tiles, new-at-this-stride rule and pixel sampling are the tracer's own, and so is the loop that
drives the tiles (``tracer.tiles``: the scheduler and TileRun the command line and a Dask cluster use), so
the add-on's image is the command line's.  What differs here is where the rays come from (any function of
pixel rows and columns, so that Blender's camera and viewport can be matched exactly), and how the work is
cut: a tile of a pass is one work item; items are traced in chunks of rays with a cancel check between
chunks (so Esc is honoured *within* a block), by several threads at once, or a time slice at a time for the
viewport.

The film is stored bottom row first, as Blender's render results and textures are.
"""
from __future__ import annotations

import threading
import time
from typing import Callable, Iterator, Optional

import numpy as np

from ..tracer import tiles
from ..tracer.backend import make_tracer
from ..tracer.errors import RenderCancelled
from ..tracer.target import sample_to_error
from ..tracer.threads import default_threads
from ..tracer.trace import RayCounts, first_hits

RaysFor = Callable[..., tuple[np.ndarray, np.ndarray]]  # (rows, cols, dy, dx) -> (origins, directions)

DEFAULT_TILE = 64
DEFAULT_CHUNK = 4096  # rays per call into the tracer: a 64 x 64 tile in one, Esc still within ms


def block_passes(block_size: int, progressive: bool) -> list[int]:
    return tiles.block_passes(int(block_size), bool(progressive))


def resolve_threads(threads: int) -> int:
    """0 means the tracer's default: $SDL_TRACER_THREADS, else every core this process may run on."""
    return int(threads) if threads and threads > 0 else default_threads()


def _work_items(plan) -> list:
    """The plan's tiles, pass by pass, except that a coarse pass's tiles are ``stride`` times wider: such a
    pass traces one ray per stride x stride block, so each work item still traces about tile x tile rays
    (at 1080p with block size 8 this is 700 items instead of 2,040, and a second less in Blender 3.4).
    Sub-pixel offsets depend on the pixel alone, so the image is the same for any tiling.  Adaptive
    sampling's pilot and refinement tiles are the plan's (the pilot is kept by the plan's tile)."""
    finest = plan.passes[-1]
    items = []
    for p, stride in enumerate(plan.passes):
        side = plan.tile * (stride // finest)
        items += [tiles.Tile(p, stride, r, c, min(r + side, plan.height), min(c + side, plan.width))
                  for r in range(0, plan.height, side) for c in range(0, plan.width, side)]
    return items + [item for item in plan.items if item.pass_index >= len(plan.passes)]


def _stopping(checkpoint: tiles.Checkpoint) -> Callable[[], bool]:
    """A tile's checkpoint (which raises RenderCancelled to stop) as the backend tracer's ``cancel()``."""
    def stop() -> bool:
        try:
            checkpoint()
        except RenderCancelled:
            return True
        return False
    return stop


class Cancelled(Exception):
    pass


class BlockRenderer:
    """Traces ``compiled`` into a ``width`` x ``height`` film; ``rays_for(rows, cols, dy, dx)`` gives the rays
    of film pixels (row 0 at the bottom) at (dx, dy) inside each pixel.

    ``samples`` rays per traced pixel placed by ``sampling`` (tracer.sampling's modes); with ``adaptive`` the
    passes trace one ray per pixel, then a pilot and a refinement pass spend about ``samples`` rays per pixel
    in all where they lower the error most (tracer.adaptive).  ``threads``: with the C core, its own worker
    threads (one work item at a time); with NumPy, work items traced at once.
    """

    def __init__(self, compiled, rays_for: RaysFor, width: int, height: int, *, block_size: int = 1,
                 progressive: bool = False, threads: int = 1, tile: int = DEFAULT_TILE,
                 chunk: Optional[int] = None, alpha: bool = False, backend: str = "auto", samples: int = 1,
                 sampling: str = "jittered", seed: int = 0):
        self.plan = tiles.TilePlan(
            int(width), int(height), block_size=int(block_size), progressive=bool(progressive), tile=int(tile),
            samples=int(samples), sampling_mode=sampling, seed=int(seed))
        self.compiled = compiled
        self.rays_for = rays_for
        self.width, self.height = self.plan.width, self.plan.height
        self.passes = self.plan.passes
        self.tile = self.plan.tile
        self.items = _work_items(self.plan)
        self.pass_count = self.plan.pass_count
        self.threads = resolve_threads(threads)
        self.chunk = max(1, int(DEFAULT_CHUNK if chunk is None else chunk))
        self.want_alpha = alpha
        self.backend = backend
        # One RGBA film, what Blender's render passes and textures take (so handing it over copies nothing);
        # with alpha the coverage is traced as its fourth channel, else that stays 1.
        self._film = np.zeros((self.height, self.width, 4), dtype=np.float32)
        self.color = self._film[..., :3]
        self.alpha = self._film[..., 3]
        self.alpha[...] = 1.0
        self._traced = self._film if alpha else self.color
        self.done = 0
        self.seconds = 0.0
        self._local = threading.local()
        self._tracers = []
        self._lock = threading.Lock()
        self._tiles = tiles.TileRun(self.plan, self._traced, self._shade)
        self.backend_name = ""

    def restart(self) -> None:
        """Trace the film again from its first item, for a scene edited in place (tracer.edit) under an
        unchanged view: the plan is kept (made again it costs tens of milliseconds for a whole viewport), and
        so is the film, whose old image shows until each of its tiles is traced again; the tracers, and what
        they counted, are made anew, and so is adaptive sampling's pilot and refinement (judged again on the
        new film)."""
        self.done = 0
        self.seconds = 0.0
        self._local = threading.local()
        self._tracers = []
        self._tiles = tiles.TileRun(self.plan, self._traced, self._shade)

    # -- tracing ---------------------------------------------------------------------------------------

    def _tracer(self):
        tracer = getattr(self._local, "tracer", None)
        if tracer is None:
            tracer = make_tracer(self.compiled, self.backend)
            if getattr(tracer, "name", "") == "c":
                tracer.threads = self.threads  # the C core spreads each chunk over its own threads
            self._local.tracer = tracer
            with self._lock:
                self._tracers.append(tracer)
                self.backend_name = getattr(tracer, "name", "numpy")
        return tracer

    def backend_tracer(self):
        """The backend tracer that shades this film (the calling thread's), for first-hit queries."""
        return self._tracer()

    @property
    def item_threads(self) -> int:
        """Work items traced at once: one with the C core (it is already parallel), else ``threads``."""
        self._tracer()
        return 1 if self.backend_name == "c" else self.threads

    def _hits(self, tracer, origins, directions) -> np.ndarray:
        """Which rays hit anything (for the film's alpha), by the same backend that shades them."""
        if hasattr(tracer, "first_hits"):
            return np.isfinite(tracer.first_hits(origins, directions)["t"])
        return first_hits(self.compiled, origins, directions).hit

    def _shade(self, checkpoint: Optional[tiles.Checkpoint]) -> tiles.PixelTracer:
        """The pixel tracer of one work item, with the calling thread's backend tracer."""
        tracer = self._tracer()
        # (asked while a chunk is traced too: a deep ray tree stops within 50 ms of a cancel)
        tracer.cancel = None if checkpoint is None else _stopping(checkpoint)
        return tiles.PixelTracer(self.plan, tracer, self.rays_for, chunk=self.chunk, checkpoint=checkpoint,
                                 alpha=self.want_alpha,
                                 first_hits=lambda origins, directions: self._hits(tracer, origins, directions))

    def pass_items(self, pass_index: int) -> list[tiles.Tile]:
        return [item for item in self.items if item.pass_index == pass_index]

    def run(self, cancel: Optional[Callable[[], bool]] = None,
            on_item: Optional[Callable[[tiles.Tile], None]] = None, poll: float = 0.05) -> None:
        """Trace everything.  ``cancel`` and ``on_item`` are only ever called on the calling thread (Blender's
        API wants that); worker threads see cancellation between chunks (tracer.tiles.TileRun)."""
        started = time.perf_counter()
        try:
            if self.item_threads == 1:
                traced = self._tiles.run(self.items, cancel)
            else:
                traced = self._tiles.run_on_threads(self.items, self.item_threads, cancel, poll)
            for item in traced:
                self.done += 1
                if on_item is not None:
                    on_item(item)
        except RenderCancelled:
            raise Cancelled() from None
        finally:
            self.seconds += time.perf_counter() - started

    def run_to_error(self, target: float, cancel: Optional[Callable[[], bool]] = None):
        """Trace the whole film to an error target instead of the block plan (tracer.target: rays where they
        lower the image's estimated RMSE most, until it is below ``target``); returns the tracer's ErrorEstimate.  The alpha
        stays 1: the target's sampling shades colour only."""
        started = time.perf_counter()
        try:
            film, estimate = sample_to_error(self._tracer().camera_rays, self.rays_for, self.width, self.height,
                                             float(target), self.plan.seed, cancel)
        except RenderCancelled:
            raise Cancelled() from None
        finally:
            self.seconds += time.perf_counter() - started
        self.color[...] = film
        self.done = len(self.items)
        return estimate

    def steps(self) -> Iterator[tiles.Tile]:
        """The remaining items one at a time, on the calling thread (for time-sliced viewport drawing)."""
        while self.done < len(self.items):
            item = self.items[self.done]
            started = time.perf_counter()
            self._tiles.trace(item)
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
        return self._film

    def counts(self):
        total = RayCounts()
        for tracer in self._tracers:
            total.add(tracer.counts)
        return total
