"""Rendering an image in blocks, coarse to fine, as the lecture's ``Camera::raytrace(scn, blockSize)``.

With block size B, one ray is traced per B x B block of pixels (through the centre of the block's
lower-left pixel) and the whole block takes its colour.  Progressive rendering runs passes B, B/2, ..., 1;
each pass traces only the pixels that are new at its stride, so every earlier sample is reused.

Work is cut into tiles (the unit that is traced as one vectorised batch and reported to the caller) by
:mod:`tracer.tiles`: after each tile of each pass, ``on_tile`` receives a :class:`TileUpdate`, and
``cancel()`` is checked.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Optional, Union

import numpy as np

from .camera import CameraFrame, scene_camera
from .compile import CompiledScene, compile_scene
from .errors import TracerError
from .imageio import bands_8bit, new_8bit_image, to_8bit
from .model import Scene
from . import sampling
from .backend import make_tracer
from .savings import RAY_BUDGET, RaySavings
from .tiles import DEFAULT_TILE, PixelTracer, Tile, TilePlan, TileRun, camera_rays_for
from .trace import RayCounts

#: Width/height limit: a 16k x 16k float image is already 3 GiB.
MAX_DIMENSION = 16384


@dataclass
class TileUpdate:
    """One finished tile of one pass.  Pixel rectangle in image coordinates (row 0 at the top)."""

    x0: int
    y0: int
    x1: int
    y1: int
    block_size: int  # this pass's stride
    pass_index: int
    pass_count: int
    tiles_done: int  # over all passes, this one included
    tiles_total: int
    image: Optional[np.ndarray]  # the whole film so far, (height, width, 3), row 0 at the top (a view):
    # float32, or uint8 (the file's bytes) in a render with eight_bit=True (float32 until its refinement pass
    # ends); None in a render that hands its rows to on_rows as they are done (it keeps no whole film)

    @property
    def fraction(self) -> float:
        return self.tiles_done / self.tiles_total


@dataclass
class RenderResult:
    image: Optional[np.ndarray]  # (height, width, 3), row 0 at the top: float32 linear colour, not clipped;
    # or, when rendered with eight_bit=True, uint8, the values the image file gets (tracer.imageio.to_8bit);
    # None when the rows went to on_rows
    rays: RayCounts
    seconds: float
    backend: str = "numpy"
    effects: frozenset = field(default_factory=frozenset)
    error_estimate: Optional[object] = None  # tracer.target.ErrorEstimate, when rendered to an error target
    size: Optional[tuple[int, int]] = None  # (width, height); by default the image's

    def stats(self) -> dict:
        width, height = self.size or (self.image.shape[1], self.image.shape[0])
        out = {"rays": self.rays.as_dict(), "skipped": self.rays.skipped(), "seconds": round(self.seconds, 6),
               "backend": self.backend, "width": int(width), "height": int(height),
               "effects": sorted(self.effects)}
        if self.error_estimate is not None:
            out["error"] = self.error_estimate.as_dict()
        return out


def budget_note(rays: RayCounts) -> Optional[str]:
    """What to tell a user when the ray budget cut rays (tracer.savings: RAY_BUDGET), else None."""
    if not rays.skipped_budget:
        return None
    return (f"{rays.skipped_budget:,} reflected or transmitted rays were not traced: a camera ray's tree traces "
            f"at most {RAY_BUDGET:,} (its rays double at every level: reflectivity and transparency that add up "
            f"to more than 1, or minReflectivity/minTransparency 0 with a deep maxRecursionDepth)")


def check_size(width: int, height: int) -> None:
    for name, value in (("width", width), ("height", height)):
        if not 1 <= value <= MAX_DIMENSION:
            raise TracerError(f"image {name} must be between 1 and {MAX_DIMENSION} pixels, not {value}")


def render(scene: Union[Scene, CompiledScene], width: int, height: int, *, block_size: int = 1,
           progressive: bool = False, tile: int = DEFAULT_TILE,
           on_tile: Optional[Callable[[TileUpdate], None]] = None,
           cancel: Optional[Callable[[], bool]] = None, backend: str = "auto",
           samples: int = 1, sampling_mode: str = "jittered",
           threshold: float = sampling.DEFAULT_THRESHOLD, seed: int = 0,
           threads: Optional[int] = None, savings: Optional[RaySavings] = None,
           target_error: Optional[float] = None, error_per_pixel: bool = False, eight_bit: bool = False,
           on_rows: Optional[Callable[[np.ndarray], None]] = None) -> RenderResult:
    """Ray trace ``scene`` into a (height, width, 3) float32 image.

    ``samples`` rays per traced pixel, placed by ``sampling_mode`` (see :mod:`tracer.sampling`).
    ``threads``: the C core's worker threads (default: $SDL_TRACER_THREADS, else every core).
    ``savings``: which rays that cannot change the image are skipped (default: tracer.savings' defaults).
    ``target_error``: instead of a fixed number of samples, sample until the image's estimated RMSE is at
    most this, or with ``error_per_pixel`` every pixel's standard error (see :mod:`tracer.target`; block
    size, samples and sampling mode are then not used).
    ``eight_bit``: keep only the 8-bit values an image file gets (3 bytes a pixel instead of 12), each tile
    converted as it is traced; the image is then uint8, the bytes :func:`tracer.imageio.to_8bit` gives for
    the float image, in memory that :func:`tracer.imageio.save_image` can release as it writes.  (Adaptive
    sampling judges its refinement on the whole float film, and sampling to an error target keeps per-pixel
    sums: those two keep floats while tracing and convert at the end.)
    ``on_rows``: keep no image: hand its 8-bit rows (the bytes of eight_bit), top row first, to ``on_rows``
    a band at a time (uint8 (rows, width, 3), a buffer reused for the next band); the result's image is then
    None.  Each band of tiles is traced start to finish, from the top of the image down, and handed over as
    soon as it is done, so that no whole film is ever held (the tiles' order does not change the pixels).
    Adaptive sampling and an error target need the whole film: they give their rows at the end.
    """
    if on_rows is not None:
        check_size(width, height)
        plan = None if target_error is not None else TilePlan(
            width, height, block_size=block_size, progressive=progressive, tile=tile, samples=samples,
            sampling_mode=sampling_mode, threshold=threshold, seed=seed)
        if plan is not None and not plan.adaptive:
            return _render_in_bands(scene, plan, on_rows, on_tile, cancel, backend, threads, savings)
        result = render(scene, width, height, block_size=block_size, progressive=progressive, tile=tile,
                        on_tile=on_tile, cancel=cancel, backend=backend, samples=samples,
                        sampling_mode=sampling_mode, threshold=threshold, seed=seed, threads=threads,
                        savings=savings, target_error=target_error, error_per_pixel=error_per_pixel,
                        eight_bit=True)
        for band in bands_8bit(result.image, release=True):
            on_rows(band)
        result.image, result.size = None, (width, height)
        return result
    check_size(width, height)
    if target_error is not None:
        result = _render_to_error(scene, width, height, target_error, error_per_pixel, backend, threads, seed,
                                  savings, cancel)
        if eight_bit:
            result.image = to_8bit(result.image, out=new_8bit_image(height, width))
        return result
    plan = TilePlan(width, height, block_size=block_size, progressive=progressive, tile=tile, samples=samples,
                    sampling_mode=sampling_mode, threshold=threshold, seed=seed)
    started = time.perf_counter()
    compiled, tracer, shade = _prepare(scene, plan, backend, threads, savings, cancel)
    # The image is kept row 0 at the top, as files and callers want it; the tiles are traced into a view of it
    # that counts rows from the bottom, as the lecture does (so no flipped copy is ever made).
    bytes_while_tracing = eight_bit and not plan.adaptive
    shown = new_8bit_image(height, width) if bytes_while_tracing else np.zeros((height, width, 3), np.float32)
    run = TileRun(plan, shown[::-1], lambda checkpoint: shade)  # (a tile at once: no chunks to check between)
    for done, item in enumerate(run.run(plan.items, cancel), 1):
        if on_tile is not None:
            on_tile(_update(plan, item, done, shown))
    run = None  # (its refinement mask is not kept through the conversion below)
    if eight_bit and not bytes_while_tracing:
        shown = to_8bit(shown, out=new_8bit_image(height, width))
    return RenderResult(image=shown, rays=tracer.counts,
                        seconds=time.perf_counter() - started, backend=tracer.name, effects=compiled.effects)


def _render_to_error(scene: Union[Scene, CompiledScene], width: int, height: int, target: float, per_pixel: bool,
                     backend: str, threads: Optional[int], seed: int, savings: Optional[RaySavings],
                     cancel: Optional[Callable[[], bool]]) -> RenderResult:
    """render(..., target_error=...): sampled by tracer.target, with the result's ``error_estimate``."""
    # deferred: sampling to an error target (and the SciPy it uses) is loaded only by the renders that ask
    # for it (tests/test_cli.py: what a plain render must not load)
    from .target import check, sample_to_error

    check(target)
    compiled = scene if isinstance(scene, CompiledScene) else compile_scene(scene)
    started = time.perf_counter()
    frame = CameraFrame.from_camera(scene_camera(compiled.scene, compiled, width / height), width / height)
    tracer = make_tracer(compiled, backend, threads, savings)
    film, estimate = sample_to_error(tracer.camera_rays, camera_rays_for(frame, width, height), width, height,
                                     target, seed, cancel, per_pixel)
    return RenderResult(image=np.ascontiguousarray(film[::-1]), rays=tracer.counts,
                        seconds=time.perf_counter() - started, backend=tracer.name, effects=compiled.effects,
                        error_estimate=estimate)


def _update(plan: TilePlan, item: Tile, done: int, image: Optional[np.ndarray]) -> TileUpdate:
    """The TileUpdate of a finished tile (in image coordinates, row 0 at the top)."""
    return TileUpdate(x0=item.c0, y0=plan.height - item.r1, x1=item.c1, y1=plan.height - item.r0,
                      block_size=item.stride, pass_index=item.pass_index, pass_count=plan.pass_count,
                      tiles_done=done, tiles_total=len(plan.items), image=image)


def _prepare(scene: Union[Scene, CompiledScene], plan: TilePlan, backend: str, threads: Optional[int],
             savings: Optional[RaySavings],
             cancel: Optional[Callable[[], bool]] = None) -> tuple[CompiledScene, object, PixelTracer]:
    """The compiled scene, the backend's tracer and the pixel tracer of a render."""
    width, height = plan.width, plan.height
    compiled = scene if isinstance(scene, CompiledScene) else compile_scene(scene)
    frame = CameraFrame.from_camera(scene_camera(compiled.scene, compiled, width / height), width / height)
    tracer = make_tracer(compiled, backend, threads, savings)
    tracer.cancel = cancel  # (asked while a batch is traced too, so that a long ray tree stops at once)
    return compiled, tracer, PixelTracer(plan, tracer, camera_rays_for(frame, width, height))


def _render_in_bands(scene: Union[Scene, CompiledScene], plan: TilePlan, on_rows: Callable[[np.ndarray], None],
                     on_tile: Optional[Callable[[TileUpdate], None]], cancel: Optional[Callable[[], bool]],
                     backend: str, threads: Optional[int], savings: Optional[RaySavings]) -> RenderResult:
    """render(..., on_rows=...) for a plan without a refinement pass: the tiles one band of tile rows at a
    time, from the top of the image, every pass of a tile before the next tile, into one band of 8-bit
    rows that goes to ``on_rows`` when its tiles are done."""
    started = time.perf_counter()
    compiled, tracer, shade = _prepare(scene, plan, backend, threads, savings, cancel)
    width, height = plan.width, plan.height
    band = np.zeros((min(plan.tile, height), width, 3), dtype=np.uint8)  # row 0 at the top, as files want
    rects_from = {}  # each band's tiles, by their first row
    for rect in plan.rects:
        rects_from.setdefault(rect[0], []).append(rect)
    done = 0
    for r0 in sorted(rects_from, reverse=True):  # (tile rows are counted from the bottom)
        r1 = min(r0 + plan.tile, height)
        rows = band[:r1 - r0]
        # the band as tiles are traced: rows from the bottom, image row r0 first
        run = TileRun(plan, rows[::-1], lambda checkpoint: shade, at=(r0, 0))
        for item in run.run((item for rect in rects_from[r0] for item in plan.rect_items(rect)), cancel):
            done += 1
            if on_tile is not None:
                on_tile(_update(plan, item, done, None))
        on_rows(rows)
    return RenderResult(image=None, rays=tracer.counts, seconds=time.perf_counter() - started,
                        backend=tracer.name, effects=compiled.effects, size=(width, height))
