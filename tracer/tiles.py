"""The tile scheduler: which pixels are traced in which order, for every way of running a render.

The lecture's ``raytrace(scn, blockSize)``: in a pass of stride B one ray is traced per B x B block of
pixels, through the block's lower-left pixel, and the whole block takes its colour.  Progressive rendering
runs passes B, B/2, ..., 1 and each pass traces only the pixels that are *new at its stride* (those not on
the grid of the pass before), so every earlier sample is reused.  With adaptive sampling the block passes
trace one ray per pixel, a *pilot* pass traces jittered rays in a random 1 in 16 pixels, and a last
*refinement* pass traces jittered rays where an error model fitted to the pilot says they lower the image's
error most, judged on the whole finished film (:mod:`tracer.adaptive`).

The image is cut into square tiles whose side is a multiple of every stride, so a tile's passes read and
write only that tile: the tiles of a pass can be traced in any order, by any number of threads or machines.
A :class:`TilePlan` holds the passes and tiles; :func:`trace_tile` traces one tile of one pass into a film
(or a window of it) through a :class:`PixelTracer`, which shoots a pixel's rays and averages them.  The
random sub-pixel offsets depend on (seed, pixel) alone (:func:`tracer.sampling.pixel_uniforms`), so any
schedule gives identical bytes.  :class:`TileRun` is the one loop that drives tiles: a list of them traced
into one film in order, with cancelling and adaptive sampling's pilot and refinement, on this thread or on
several.

Used by :func:`tracer.render.render` (the command line: the whole film, or a band of it at a time),
``tracer.distributed`` (a Dask cluster: one tile's passes per task, :func:`trace_rect`) and the Blender
add-on (``addon/pure/blocks.py``).  Films are stored bottom row first, as the lecture counts rows.
"""
from __future__ import annotations

from dataclasses import dataclass
from itertools import groupby
from typing import Callable, Iterable, Iterator, Optional

import numpy as np

from . import sampling
from .errors import RenderCancelled, TracerError
from .imageio import to_8bit

DEFAULT_TILE = 64

#: ``rays_for(rows, cols, dy, dx) -> (origins, directions)``: the rays through film pixels (row 0 at the
#: bottom) at (dx, dy) inside each pixel; dy and dx are arrays (one per ray) or the scalar 0.5 (the centre).
RaysFor = Callable[..., tuple[np.ndarray, np.ndarray]]
#: ``shade(rows, cols, per_pixel, seed=None) -> (N, channels)``: the mean of ``per_pixel`` rays in each given
#: pixel (jittered with ``seed``, by default the plan's).
Shade = Callable[..., np.ndarray]
#: Called between pieces of work; raises RenderCancelled to stop.
Checkpoint = Callable[[], None]


def block_passes(block_size: int, progressive: bool) -> list[int]:
    """Strides of the passes: [B] or [B, B/2, ..., 1] (B rounded down to a power of two when progressive)."""
    if block_size < 1:
        raise TracerError(f"block size must be at least 1, not {block_size}")
    if not progressive:
        return [block_size]
    top = 1 << (int(block_size).bit_length() - 1)
    passes = []
    while top >= 1:
        passes.append(top)
        top //= 2
    return passes


@dataclass(frozen=True)
class Tile:
    """One tile of one pass: pixel rows r0..r1-1 (counted from the bottom) and columns c0..c1-1."""

    pass_index: int
    stride: int
    r0: int
    c0: int
    r1: int
    c1: int

    @property
    def rect(self) -> tuple[int, int, int, int]:
        return self.r0, self.c0, self.r1, self.c1

    def positions(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The sample positions of this tile at its stride (rows, columns), and which are new in this pass."""
        rows = np.arange(self.r0, self.r1, self.stride)
        cols = np.arange(self.c0, self.c1, self.stride)
        grid_r, grid_c = np.meshgrid(rows, cols, indexing="ij")
        if self.pass_index == 0:
            new = np.ones(grid_r.shape, dtype=bool)
        else:  # on the grid of the pass before (stride 2s) means traced already
            new = (grid_r % (2 * self.stride) != 0) | (grid_c % (2 * self.stride) != 0)
        return grid_r, grid_c, new


class TilePlan:
    """The passes and tiles of a ``width`` x ``height`` render, and how its pixels are sampled.

    ``items`` lists every tile of every pass in the order a single-threaded render traces them: pass by pass
    (so that an interactive display refines the whole image coarse to fine), adaptive sampling's pilot and
    refinement passes last.
    """

    def __init__(self, width: int, height: int, *, block_size: int = 1, progressive: bool = False,
                 tile: int = DEFAULT_TILE, samples: int = 1, sampling_mode: str = "jittered", seed: int = 0):
        sampling.check(int(samples), sampling_mode)
        self.width, self.height = int(width), int(height)
        # A block larger than the image traces the same single ray as a block of the image's size, and the
        # passes above that size trace nothing new: clamped, so that memory follows the image, not the request
        # (a tile is at least one block: a block of 10^9 asked for a 10^9-square tile).
        block_size = int(block_size)
        if block_size > max(self.width, self.height):
            block_size = max(self.width, self.height)
        self.passes = block_passes(block_size, bool(progressive))
        self.samples, self.sampling_mode, self.seed = int(samples), sampling_mode, int(seed)
        self.adaptive = sampling_mode == "adaptive" and self.samples > 1
        top = self.passes[0]
        size = max(int(tile), top)
        self.tile = size - size % top  # tiles start on multiples of every stride
        self.rects = [(r, c, min(r + self.tile, self.height), min(c + self.tile, self.width))
                      for r in range(0, self.height, self.tile) for c in range(0, self.width, self.tile)]
        self.items = [Tile(p, stride, *rect) for p, stride in enumerate(self.passes) for rect in self.rects]
        if self.adaptive:
            self.items += [Tile(p, 1, *rect) for p in (self.pilot_pass, self.pilot_pass + 1) for rect in self.rects]

    @property
    def pass_count(self) -> int:
        return len(self.passes) + 2 * self.adaptive

    @property
    def per_pixel(self) -> int:
        """Rays per pixel in the block passes (one when adaptive sampling's passes add the rest)."""
        return 1 if self.adaptive else self.samples

    @property
    def pilot_pass(self) -> int:
        """The pass index of adaptive sampling's pilot (the refinement's is the next)."""
        return len(self.passes)

    def is_pilot(self, item: Tile) -> bool:
        return item.pass_index == self.pilot_pass

    def is_refinement(self, item: Tile) -> bool:
        return item.pass_index > self.pilot_pass

    def pass_items(self, pass_index: int) -> list[Tile]:
        return [item for item in self.items if item.pass_index == pass_index]

    def rect_items(self, rect: tuple[int, int, int, int]) -> list[Tile]:
        """The block passes' tiles over one rectangle, coarse to fine (a tile traced start to finish)."""
        return [Tile(p, stride, *rect) for p, stride in enumerate(self.passes)]

    def sample_positions(self, rows: np.ndarray, cols: np.ndarray, per_pixel: int, seed: Optional[int] = None):
        """(rows, cols, dy, dx) of every ray of the given pixels, ``per_pixel`` consecutive rays per pixel,
        jittered (unless regular) with ``seed``, by default the plan's."""
        if per_pixel == 1:
            return rows, cols, 0.5, 0.5
        dy, dx = sampling.offsets(per_pixel, self.sampling_mode != "regular", rows, cols,
                                  self.seed if seed is None else seed)
        return np.repeat(rows, per_pixel), np.repeat(cols, per_pixel), dy.ravel(), dx.ravel()


def trace_tile(plan: TilePlan, item: Tile, film: np.ndarray, shade: Shade, at: tuple[int, int] = (0, 0)) -> None:
    """Trace one tile of one block pass into ``film`` (rows from the bottom, any number of channels).

    A float film gets the colours; a uint8 film gets their 8-bit values (:func:`tracer.imageio.to_8bit`),
    the bytes that converting the float film afterwards would give (a later pass copies an earlier pass's
    sample as its byte, which is the byte of its colour).  ``film`` may be a window of the image whose pixel
    (0, 0) is image pixel ``at`` (row, column); it must cover the tile.  (Adaptive sampling's pilot and
    refinement tiles are :class:`TileRun`'s: they need the whole film's judgement.)
    """
    if item.pass_index >= len(plan.passes):
        raise ValueError("trace_tile traces the block passes; adaptive sampling's are TileRun's")
    r0, c0 = item.r0 - at[0], item.c0 - at[1]
    r1, c1 = item.r1 - at[0], item.c1 - at[1]
    if item.stride == 1 and item.pass_index == 0:  # every pixel new: no earlier samples to keep
        rows, cols = np.arange(item.r0, item.r1), np.arange(item.c0, item.c1)
        values = shade(np.repeat(rows, cols.size), np.tile(cols, rows.size), plan.per_pixel)
        film[r0:r1, c0:c1] = in_film(values, film).reshape(rows.size, cols.size, -1)
        return
    grid_r, grid_c, new = item.positions()
    values = film[grid_r - at[0], grid_c - at[1]]  # earlier passes' samples keep their value
    if new.any():
        values[new] = in_film(shade(grid_r[new], grid_c[new], plan.per_pixel), film)
    s = item.stride
    block = np.repeat(np.repeat(values, s, axis=0), s, axis=1)
    film[r0:r1, c0:c1] = block[: r1 - r0, : c1 - c0]


def in_film(colours: np.ndarray, film: np.ndarray) -> np.ndarray:
    """Shaded colours as ``film`` keeps them: as they are in a float film, as bytes in an 8-bit one."""
    return to_8bit(colours) if film.dtype == np.uint8 else colours


def trace_rect(plan: TilePlan, rect: tuple[int, int, int, int], shade: Shade, channels: int = 3) -> np.ndarray:
    """Every block pass over one rectangle, coarse to fine: the rectangle's film (rows from the bottom,
    float32).  What a tile is worth to a worker that traces whole tiles (adaptive sampling's passes are
    TileRun's)."""
    r0, c0, r1, c1 = rect
    window = np.zeros((r1 - r0, c1 - c0, channels), dtype=np.float32)
    TileRun(plan, window, lambda checkpoint: shade, at=(r0, c0)).trace_all(plan.rect_items(rect))
    return window


class TileRun:
    """Tiles of a plan traced into one film, in the order given: the loop that drives tiles, for every way of
    rendering (tracer.render's whole film or one band of it, a cluster worker's tile, the add-on's blocks).

    ``film`` and ``at`` are as for :func:`trace_tile`.  ``shade_for(checkpoint)`` is the Shade of one tile,
    calling ``checkpoint`` (or nothing, when None) between its chunks of rays: the add-on makes one per tile
    on the thread that traces it; a shade that traces a tile at once can ignore it.  Items come pass by pass.
    Adaptive sampling's pilot tiles leave their rays in ``pilot`` (by tile rectangle); its refinement is
    judged on the film the block passes left and on the pilot (:func:`tracer.adaptive.refinement`, which
    needs the whole film: ``at`` (0, 0)) when the first refinement tile is reached, and kept in ``refinement``.
    """

    def __init__(self, plan: TilePlan, film: np.ndarray, shade_for: Callable[[Optional[Checkpoint]], Shade], *,
                 at: tuple[int, int] = (0, 0)):
        self.plan, self.film, self.shade_for, self.at = plan, film, shade_for, at
        self.pilot: dict = {}  # tile rectangle -> tracer.adaptive.PilotTile
        self.refinement: Optional[np.ndarray] = None  # rays per pixel, once judged

    def trace(self, item: Tile, checkpoint: Optional[Checkpoint] = None) -> Tile:
        """Trace one tile (``checkpoint`` is asked first, then between chunks of rays); returns it."""
        if checkpoint is not None:
            checkpoint()
        if item.pass_index < len(self.plan.passes):
            trace_tile(self.plan, item, self.film, self.shade_for(checkpoint), self.at)
            return item
        # deferred: adaptive sampling (and the error model of tracer.target) is loaded by the renders that
        # use it (tests/test_cli.py: what a plain render must not load)
        from . import adaptive

        if self.plan.is_pilot(item):
            self.pilot[item.rect] = adaptive.trace_pilot(self.plan, item.rect, self.shade_for(checkpoint))
            return item
        self.judge_refinement()
        r0, c0, r1, c1 = item.rect
        rows, cols, values = adaptive.trace_refinement(self.plan, item.rect, self.shade_for(checkpoint),
                                                       self.refinement[r0:r1, c0:c1], self.pilot.get(item.rect))
        self.film[rows, cols] = in_film(values, self.film)
        return item

    def judge_refinement(self) -> None:
        """Judge adaptive sampling's refinement, once, on the film as it is now (the block passes done)."""
        if self.refinement is None:
            from . import adaptive  # deferred: as in trace (adaptive renders alone load it)

            if self.at != (0, 0):
                raise ValueError("adaptive sampling's refinement is judged on the whole film")
            self.refinement = adaptive.refinement(self.plan, self.film, self.pilot.values())

    def run(self, items: Iterable[Tile], cancel: Optional[Callable[[], bool]] = None) -> Iterator[Tile]:
        """Trace ``items`` one after another on this thread, yielding each when it is done; ``cancel()`` is
        asked before each tile and between its chunks of rays (True: RenderCancelled)."""
        checkpoint = None if cancel is None else _checkpoint(cancel)
        for item in items:
            yield self.trace(item, checkpoint)

    def trace_all(self, items: Iterable[Tile], cancel: Optional[Callable[[], bool]] = None) -> None:
        for _ in self.run(items, cancel):
            pass

    def run_on_threads(self, items: Iterable[Tile], threads: int, cancel: Optional[Callable[[], bool]] = None,
                       poll: float = 0.05) -> Iterator[Tile]:
        """:meth:`run` with the tiles of one pass traced ``threads`` at a time (a pass reuses the samples of
        the one before, so passes still go one after another).  ``cancel()`` is asked, and the tiles yielded,
        on this thread only (Blender's API wants that), every ``poll`` seconds; the tracing threads see a
        cancellation between their chunks of rays."""
        # deferred: threads are for the add-on's NumPy renders; a command-line render loads no threading
        # (tests/test_cli.py's import set)
        import concurrent.futures
        import threading

        stop = threading.Event()
        checkpoint = _checkpoint(stop.is_set)
        with concurrent.futures.ThreadPoolExecutor(max_workers=threads, thread_name_prefix="sdl-trace") as pool:
            try:
                for _, same_pass in groupby(items, key=lambda item: item.pass_index):
                    same_pass = list(same_pass)
                    if self.plan.is_refinement(same_pass[0]):
                        self.judge_refinement()  # (here, before the threads read it)
                    pending = {pool.submit(self.trace, item, checkpoint) for item in same_pass}
                    while pending:
                        finished, pending = concurrent.futures.wait(
                            pending, timeout=poll, return_when=concurrent.futures.FIRST_COMPLETED)
                        for future in finished:
                            yield future.result()
                        if cancel is not None and cancel():
                            raise RenderCancelled("render cancelled")
            except BaseException:
                stop.set()
                raise


def _checkpoint(stopped: Callable[[], bool]) -> Checkpoint:
    def checkpoint() -> None:
        if stopped():
            raise RenderCancelled("render cancelled")
    return checkpoint


class PixelTracer:
    """Traces pixels of a plan with a backend tracer (``camera_rays(origins, directions)``): the mean colour
    of each pixel's rays.  Rays go ``chunk`` at a time with ``checkpoint()`` called between chunks (it
    raises to stop; TileRun asks it before the first); ``alpha`` adds a fourth channel, the share of each pixel's rays that hit something (and
    the rays that miss count as black)."""

    def __init__(self, plan: TilePlan, tracer, rays_for: RaysFor, *, chunk: Optional[int] = None,
                 checkpoint: Optional[Callable[[], None]] = None, alpha: bool = False,
                 first_hits: Optional[Callable[[np.ndarray, np.ndarray], np.ndarray]] = None):
        self.plan, self.tracer, self.rays_for = plan, tracer, rays_for
        self.chunk = chunk
        self.checkpoint = checkpoint
        self.alpha = alpha
        self.first_hits = first_hits  # (origins, directions) -> bool per ray; needed with alpha

    def __call__(self, rows: np.ndarray, cols: np.ndarray, per_pixel: int, seed: Optional[int] = None) -> np.ndarray:
        out = np.empty((rows.size, 4 if self.alpha else 3), dtype=np.float64)
        step = rows.size if not self.chunk else max(1, self.chunk // per_pixel)
        for start in range(0, rows.size, max(step, 1)):
            if self.checkpoint is not None and start > 0:
                self.checkpoint()
            stop = min(start + step, rows.size)
            r, c, dy, dx = self.plan.sample_positions(rows[start:stop], cols[start:stop], per_pixel, seed)
            origins, directions = self.rays_for(r, c, dy, dx)
            origins = np.ascontiguousarray(origins, dtype=np.float64)
            directions = np.ascontiguousarray(directions, dtype=np.float64)
            colors = np.asarray(self.tracer.camera_rays(origins, directions), dtype=np.float64)
            if self.alpha:
                hit = self.first_hits(origins, directions)
                colors = np.where(hit[:, None], colors, 0.0)
                out[start:stop, 3] = hit.reshape(-1, per_pixel).mean(axis=1)
            out[start:stop, :3] = colors if per_pixel == 1 else colors.reshape(-1, per_pixel, 3).mean(axis=1)
        return out


def camera_rays_for(frame, width: int, height: int) -> RaysFor:
    """The rays of a :class:`tracer.camera.CameraFrame` for a ``width`` x ``height`` film (every ray starts at
    the eye; the repeated eye is kept between calls rather than made again for every batch)."""
    eye_rows = [np.empty((0, 3))]

    def rays_for(rows, cols, dy=0.5, dx=0.5):
        directions = frame.directions(rows, cols, height, width, dy=dy, dx=dx)
        if len(eye_rows[0]) < len(directions):
            eye_rows[0] = np.ascontiguousarray(np.broadcast_to(frame.eye, directions.shape))
        return eye_rows[0][:len(directions)], directions

    return rays_for
