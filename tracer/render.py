"""Rendering an image in blocks, coarse to fine, as the lecture's ``Camera::raytrace(scn, blockSize)``.

With block size B, one ray is traced per B x B block of pixels (through the centre of the block's
lower-left pixel) and the whole block takes its colour.  Progressive rendering runs passes B, B/2, ..., 1;
each pass traces only the pixels that are new at its stride, so every earlier sample is reused.

Work is cut into tiles (the unit that is traced as one vectorised batch and reported to the caller):
after each tile of each pass, ``on_tile`` receives a :class:`TileUpdate`, and ``cancel()`` is checked.
"""
from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Callable, Optional, Union

import numpy as np

from .camera import CameraFrame, scene_camera
from .compile import CompiledScene, compile_scene
from .errors import RenderCancelled, TracerError
from .model import Scene
from . import sampling
from .backend import make_tracer
from .savings import RaySavings
from .trace import RayCounts

#: Width/height limit: a 16k x 16k float image is already 3 GiB.
MAX_DIMENSION = 16384
DEFAULT_TILE = 64


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
    image: np.ndarray  # the whole film so far, (height, width, 3) float32, row 0 at the top (a view)

    @property
    def fraction(self) -> float:
        return self.tiles_done / self.tiles_total


@dataclass
class RenderResult:
    image: np.ndarray  # (height, width, 3) float32, row 0 at the top, linear colour, not clipped
    rays: RayCounts
    seconds: float
    backend: str = "numpy"
    effects: frozenset = field(default_factory=frozenset)

    def stats(self) -> dict:
        return {"rays": self.rays.as_dict(), "skipped": self.rays.skipped(), "seconds": round(self.seconds, 6), "backend": self.backend,
                "width": int(self.image.shape[1]), "height": int(self.image.shape[0]),
                "effects": sorted(self.effects)}


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
           threads: Optional[int] = None, savings: Optional[RaySavings] = None) -> RenderResult:
    """Ray trace ``scene`` into a (height, width, 3) float32 image.

    ``samples`` rays per traced pixel, placed by ``sampling_mode`` (see :mod:`tracer.sampling`).
    ``threads``: the C core's worker threads (default: $SDL_TRACER_THREADS, else every core).
    ``savings``: which rays that cannot change the image are skipped (default: tracer.savings' defaults).
    """
    check_size(width, height)
    sampling.check(samples, sampling_mode, threshold)
    started = time.perf_counter()
    compiled = scene if isinstance(scene, CompiledScene) else compile_scene(scene)
    camera = scene_camera(compiled.scene, compiled, width / height)
    frame = CameraFrame.from_camera(camera, width / height)
    tracer = make_tracer(compiled, backend, threads, savings)
    passes = block_passes(block_size, progressive)
    # The film is stored bottom row first, as the lecture counts rows; the caller sees it flipped.
    film = np.zeros((height, width, 3), dtype=np.float32)
    shown = film[::-1]
    tile = max(tile, passes[0])
    tile -= tile % passes[0]  # tiles start on multiples of every stride
    tiles = [(r, c) for r in range(0, height, tile) for c in range(0, width, tile)]
    adaptive = sampling_mode == "adaptive" and samples > 1
    total = len(tiles) * (len(passes) + adaptive)
    done = 0
    rng = np.random.default_rng(seed)
    eye_rows: list[np.ndarray] = [np.empty((0, 3))]  # the eye, repeated: every camera ray's origin

    def trace_pixels(rows_from_bottom: np.ndarray, cols: np.ndarray, per_pixel: int) -> np.ndarray:
        """Mean colour of ``per_pixel`` rays in each of the given pixels."""
        if per_pixel == 1:
            dy = dx = 0.5
            rr, cc = rows_from_bottom, cols
        else:
            dy, dx = sampling.offsets(per_pixel, sampling_mode != "regular", rows_from_bottom.size, rng)
            rr = np.repeat(rows_from_bottom, per_pixel)
            cc = np.repeat(cols, per_pixel)
            dy, dx = dy.ravel(), dx.ravel()
        directions = frame.directions(rr, cc, height, width, dy=dy, dx=dx)
        if len(eye_rows[0]) < len(directions):
            eye_rows[0] = np.ascontiguousarray(np.broadcast_to(frame.eye, directions.shape))
        colors = tracer.camera_rays(eye_rows[0][:len(directions)], directions)
        return colors if per_pixel == 1 else colors.reshape(-1, per_pixel, 3).mean(axis=1)

    def report(r0, c0, r1, c1, stride, pass_index):
        if on_tile is not None:
            on_tile(TileUpdate(x0=c0, y0=height - r1, x1=c1, y1=height - r0, block_size=stride,
                               pass_index=pass_index, pass_count=len(passes) + adaptive, tiles_done=done,
                               tiles_total=total, image=shown))
    for pass_index, stride in enumerate(passes):
        first_pass = pass_index == 0
        for r0, c0 in tiles:
            if cancel is not None and cancel():
                raise RenderCancelled("render cancelled")
            r1, c1 = min(r0 + tile, height), min(c0 + tile, width)
            if stride == 1 and first_pass:  # one ray per pixel, all new: no earlier samples to keep
                rows, cols = np.arange(r0, r1), np.arange(c0, c1)
                colors = trace_pixels(np.repeat(rows, cols.size), np.tile(cols, rows.size), 1 if adaptive else samples)
                film[r0:r1, c0:c1] = colors.reshape(rows.size, cols.size, 3)
                done += 1
                report(r0, c0, r1, c1, stride, pass_index)
                continue
            rows = np.arange(r0, r1, stride)
            cols = np.arange(c0, c1, stride)
            grid_r, grid_c = np.meshgrid(rows, cols, indexing="ij")
            colors = film[grid_r, grid_c]  # earlier passes' samples keep their colour
            new = np.ones(grid_r.shape, dtype=bool) if first_pass else \
                (grid_r % (2 * stride) != 0) | (grid_c % (2 * stride) != 0)
            if new.any():
                colors[new] = trace_pixels(grid_r[new], grid_c[new], 1 if adaptive else samples)
            block = np.repeat(np.repeat(colors, stride, axis=0), stride, axis=1)
            film[r0:r1, c0:c1] = block[: r1 - r0, : c1 - c0]
            done += 1
            report(r0, c0, r1, c1, stride, pass_index)
    if adaptive:
        # Refine where neighbours disagree, judged on the finished film (which crosses tile borders).
        refine = sampling.contrast_mask(film, threshold)
        for r0, c0 in tiles:
            if cancel is not None and cancel():
                raise RenderCancelled("render cancelled")
            r1, c1 = min(r0 + tile, height), min(c0 + tile, width)
            rr, cc = np.nonzero(refine[r0:r1, c0:c1])
            if rr.size:
                film[rr + r0, cc + c0] = trace_pixels(rr + r0, cc + c0, samples)
            done += 1
            report(r0, c0, r1, c1, 1, len(passes))
    return RenderResult(image=np.ascontiguousarray(shown), rays=tracer.counts,
                        seconds=time.perf_counter() - started, backend=tracer.name, effects=compiled.effects)
