"""Rendering on a Dask cluster (``python -m tracer render SCENE -o OUT --scheduler ADDRESS``).

The engine is Dask distributed: a scheduler that hands out tasks, restarts the tasks of a worker that died
and reaches Slurm, PBS or Kubernetes through dask-jobqueue and dask-kubernetes.  What is ours:

* :class:`SceneBundle`: the scene file and every file it reads (.3vn meshes, pixmaps, USD layers and
  assets), as bytes.  It is scattered to every worker once; each worker process unpacks it into a
  folder of its own, reads and compiles it once per frame and keeps the compiled scene (and one backend
  tracer per worker thread) while tiles arrive.
* Tasks are tiles of :mod:`tracer.tiles`: one task traces every block pass of one tile of one frame (and,
  with adaptive sampling, the tile's pilot); with adaptive sampling a second task per tile traces the
  refinement pass once its frame's film and pilot are whole (the refinement is judged on the whole film:
  :mod:`tracer.adaptive`).  Sub-pixel samples are keyed by pixel, so the image is the local render's, byte
  for byte, whichever worker traces which tile and however often a tile is traced again.
* The client assembles tiles as they complete and hands each finished frame back.

``--scheduler local:N`` starts a LocalCluster of N worker processes on this machine, one thread each, whose
C cores share this machine's cores.  Dask is optional: ``pip install sdl-raytracer[distributed]``.
"""
from __future__ import annotations

import collections
import contextlib
import copy
import dataclasses
import functools
import hashlib
import logging
import os
import re
import signal
import tempfile
import threading
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator, Optional, Sequence

import numpy as np

from .backend import make_tracer
from .camera import CameraFrame, scene_camera
from .compile import compile_scene
from .errors import SDLError, TracerError
from .imageio import new_8bit_image, to_8bit
from .model import Scene, ShapeTable
from .render import TileUpdate
from .savings import RaySavings
from .sdl.parser import load
from .threads import default_threads
from .tiles import PixelTracer, TilePlan, camera_rays_for, trace_rect
from .trace import RayCounts

INSTALL_HINT = "pip install 'sdl-raytracer[distributed]' (or: pip install distributed)"
#: Tile side on a cluster.  Each task costs about 5 ms of CPU beyond its tracing (scheduler, transfer,
#: assembly: bench/cluster.py); a 256 x 256 tile of a 16-sample 4K frame traces for about 0.4 s, so the
#: overhead stays near 1 %, while a 4K frame still has 135 tiles to spread over the workers.
CLUSTER_TILE = 256
LOCAL_PREFIX = "local:"
#: Dask settings for ``local:N`` clusters, whose workers share this machine's cores with this process:
#:
#: * no MALLOC_TRIM_THRESHOLD_ in the workers' environment.  Dask's nanny sets it (to 64 KiB, so that freed
#:   memory goes back to the system at once), and setting it turns off glibc's adaptive mmap threshold: every
#:   array over 128 KiB is then mapped, faulted in page by page and unmapped again.  A tile's rays go through
#:   dozens of megabyte-sized temporaries per call into the C core, and the workers spent about a fifth of
#:   their time in the kernel (3.0 s of system time against 0.9 s for the local render of the same 1080p
#:   image; 0.4 s without it).
#: * no statistical profiler in the workers (it samples every thread's stack 100 times a second), and the
#:   event-loop, system and memory monitors sample less often (idle, a one-worker cluster then takes 0.43 s
#:   of CPU per 30 s instead of 0.9 s).
LOCAL_CLUSTER_CONFIG = {"distributed.nanny.pre-spawn-environ.MALLOC_TRIM_THRESHOLD_": None,
                        "distributed.worker.profile.enabled": False,
                        "distributed.admin.tick.interval": "1s",
                        "distributed.admin.system-monitor.interval": "5s",
                        "distributed.worker.memory.monitor-interval": "1s"}


def require_dask():
    """The ``distributed`` module, or a TracerError that says how to install it."""
    try:
        import distributed
    except ImportError:
        raise TracerError(f"--scheduler needs Dask distributed, which is not installed: {INSTALL_HINT}") from None
    return distributed


# -- the scene and its files -------------------------------------------------------------------------------


def scene_files(path: str | os.PathLike, scene: Scene) -> list[Path]:
    """The files reading ``path`` (already read into ``scene``) opens: the scene file, its pixmaps and .3vn
    meshes, and for USD every layer and asset the stage depends on."""
    path = Path(path)
    files = [path]
    files += [Path(name) for name in scene.pixmaps.values()]
    if not (isinstance(scene.objects, ShapeTable) and scene.objects.columns is not None):
        # (a table's rows read no mesh file: not made into a million Shapes to find that out)
        files += [path.parent / shape.mesh_file for shape in scene.shapes() if shape.mesh_file]
    if path.suffix.lower() in (".usd", ".usda", ".usdc"):
        from .usd.common import pxr  # deferred: the USD package, for USD stages only
        pxr()  # (a TracerError saying how to install usd-core, where it is missing)
        from pxr import UsdUtils
        layers, assets, _unresolved = UsdUtils.ComputeAllDependencies(os.fspath(path))
        files += [Path(layer.realPath) for layer in layers if layer.realPath]
        files += [Path(asset) for asset in assets]
    unique: dict[str, Path] = {}
    for file in files:
        if file.is_file():
            unique.setdefault(os.path.realpath(file), file)
    return [Path(real) for real in unique]


@dataclass(frozen=True)
class SceneBundle:
    """A scene file and the files it reads, by path relative to their common folder."""

    scene: str  # the scene file, relative
    files: dict[str, bytes]
    origin: str  # the common folder on the client (for messages)
    lenient: bool = False
    digest: str = ""  # names the bundle in workers' caches

    @classmethod
    def of(cls, path: str | os.PathLike, scene: Scene, lenient: bool = False) -> "SceneBundle":
        paths = scene_files(path, scene)
        root = Path(os.path.commonpath([os.path.dirname(p) for p in paths]))
        files = {}
        for p in paths:
            try:
                files[p.relative_to(root).as_posix()] = p.read_bytes()
            except OSError as err:
                raise TracerError(f"{p}: cannot read ({err.strerror or err})") from None
        scene_rel = Path(os.path.realpath(path)).relative_to(root).as_posix()
        h = hashlib.sha256(f"{scene_rel}\0{lenient}".encode())
        for name in sorted(files):
            h.update(name.encode() + b"\0" + hashlib.sha256(files[name]).digest())
        return cls(scene_rel, files, str(root), lenient, h.hexdigest())

    def unpack(self, folder: Path) -> Path:
        """Write the files under ``folder``; the scene file's path there."""
        for name, data in self.files.items():
            target = folder / name
            target.parent.mkdir(parents=True, exist_ok=True)
            target.write_bytes(data)
        return folder / self.scene


def read_scene(path: str | os.PathLike, lenient: bool = False, time: Optional[float] = None) -> Scene:
    """SDL or USD by extension (USD at time code ``time``)."""
    from .usd.common import USD_EXTENSIONS  # deferred: (the USD package, as in scene_files)

    if Path(path).suffix.lower() in USD_EXTENSIONS:
        from .usd import load_usd  # deferred: (as above)
        return load_usd(path, strict=not lenient, time=time)
    if time is not None:
        raise TracerError(f"{path}: frames need a USD stage with time samples (an SDL file has no time)")
    return load(path, strict=not lenient)


# -- what a tile needs besides the scene ---------------------------------------------------------------------


@dataclass(frozen=True)
class Job:
    """The settings of a render: image size, passes, sampling, backend."""

    width: int
    height: int
    block_size: int = 1
    progressive: bool = False
    tile: int = CLUSTER_TILE
    samples: int = 1
    sampling_mode: str = "jittered"
    seed: int = 0
    backend: str = "auto"
    threads: Optional[int] = None  # the C core's threads per task (None: the worker's cores / its threads)
    max_depth: Optional[int] = None
    savings: Optional[RaySavings] = None  # rays not cast (None: tracer.savings' defaults)

    def plan(self):
        return TilePlan(self.width, self.height, block_size=self.block_size, progressive=self.progressive,
                        tile=self.tile, samples=self.samples, sampling_mode=self.sampling_mode, seed=self.seed)


# -- the worker side -----------------------------------------------------------------------------------------

#: Rays traced per call into the backend within a task: a big tile's rays in one batch would make arrays
#: of tens of megabytes that fall out of the processor's caches between the steps that fill them.
RAYS_PER_CALL = 1 << 16

#: Compiled scenes a worker process keeps (a frame each, for sequences; the oldest go first).
KEPT_SCENES = 4
#: Bundles a worker process keeps unpacked (the oldest, with its scenes, go first).
KEPT_BUNDLES = 4

_lock = threading.Lock()
_folders: "collections.OrderedDict[str, tempfile.TemporaryDirectory]" = collections.OrderedDict()  # digest -> files
_scenes: "collections.OrderedDict[tuple, object]" = collections.OrderedDict()  # (digest, time, depth) -> compiled
_read: dict[str, Scene] = {}  # bundle digest -> its scene as read (for scene_task)
_local = threading.local()  # per worker thread: the tracer of the scene it traced last


def _where() -> str:
    try:
        from distributed import get_worker
        return f"worker {get_worker().address}"
    except (ImportError, ValueError):
        return "worker"


def _unpacked(bundle: SceneBundle) -> str:
    """The folder this worker process unpacked a bundle into, unpacked on first use.  (Removed when the
    process ends, or when KEPT_BUNDLES newer bundles have arrived.)  Call with _lock held."""
    folder = _folders.get(bundle.digest)
    if folder is not None:
        _folders.move_to_end(bundle.digest)
        return folder.name
    folder = _folders[bundle.digest] = tempfile.TemporaryDirectory(prefix="sdl-scene-")
    bundle.unpack(Path(folder.name))
    while len(_folders) > KEPT_BUNDLES:
        digest, oldest = _folders.popitem(last=False)
        oldest.cleanup()
        _read.pop(digest, None)
        for key in [key for key in _scenes if key[0] == digest]:
            del _scenes[key]
    return folder.name


@contextlib.contextmanager
def _as_the_user_knows_it(bundle: SceneBundle, folder: str) -> Iterator[None]:
    """A scene's failure on a worker as one line naming the worker and the file as the user knows it, not
    the worker's copy."""
    try:
        yield
    except (SDLError, TracerError, OSError, ValueError) as err:
        raise TracerError(f"{_where()}: {str(err).replace(folder, bundle.origin)}") from None


def _compiled(bundle: SceneBundle, time: Optional[float], max_depth: Optional[int]):
    """The compiled scene of a bundle at a time: read and compiled once per worker process."""
    key = (bundle.digest, time, max_depth)
    with _lock:
        if key in _scenes:
            _scenes.move_to_end(key)
            return _scenes[key]
        folder = _unpacked(bundle)
        with _as_the_user_knows_it(bundle, folder):
            scene = read_scene(Path(folder) / bundle.scene, bundle.lenient, time)
            if max_depth is not None:
                scene.settings.max_recursion_depth = max_depth
            compiled = compile_scene(scene)
        _scenes[key] = compiled
        while len(_scenes) > KEPT_SCENES:
            _scenes.popitem(last=False)
        return compiled


def _worker_core_threads() -> int:
    """C-core threads for each task when the job leaves it open: this machine's cores shared among the
    worker's task threads (which trace tiles at the same time)."""
    try:
        from distributed import get_worker
        tasks_at_once = get_worker().state.nthreads
    except (ImportError, ValueError, AttributeError):
        tasks_at_once = 1
    return max(1, default_threads() // max(1, tasks_at_once))


def _tracer(bundle: SceneBundle, job: Job, time: Optional[float]):
    compiled = _compiled(bundle, time, job.max_depth)
    key = (bundle.digest, time, job.max_depth, job.backend, job.threads, job.savings)
    kept = getattr(_local, "kept", None)
    if kept is None or kept[0] != key:  # a thread keeps one tracer: tiles of one frame come together
        tracer = make_tracer(compiled, job.backend, job.threads or _worker_core_threads(), job.savings)
        kept = _local.kept = (key, tracer)
    return compiled, kept[1]


@functools.lru_cache(maxsize=8)
def _plan(job: Job):
    """A worker's plan of a job, made once (it lists every tile: making it per task would cost as much as
    the number of tiles, for every tile)."""
    return job.plan()


def trace_tile_task(bundle: SceneBundle, job: Job, time: Optional[float], rect: tuple[int, int, int, int]):
    """A task: every block pass of one tile, and with adaptive sampling its pilot.  Returns (the tile's
    film, bottom row first; its tracer.adaptive.PilotTile or None; the rays it cast; the backend's name)."""
    with _tile_tracing(bundle, job, time) as (plan, shade, rays):
        window = trace_rect(plan, rect, shade)
        pilot = None
        if plan.adaptive:
            from .adaptive import trace_pilot  # deferred: adaptive renders alone load it (as tracer.tiles does)

            pilot = trace_pilot(plan, rect, shade)
    return window, pilot, rays, shade.tracer.name


def refine_tile_task(bundle: SceneBundle, job: Job, time: Optional[float], rect: tuple[int, int, int, int],
                     counts: np.ndarray, pilot):
    """A task: adaptive sampling's refinement of one tile, given its window of the refinement's rays per
    pixel and its pilot.  Returns ((rows, columns, colours) of the pixels it gives a colour, as
    tracer.adaptive.trace_refinement; the rays it cast; the backend's name)."""
    from .adaptive import trace_refinement  # deferred: adaptive renders alone load it (as tracer.tiles does)

    with _tile_tracing(bundle, job, time) as (plan, shade, rays):
        pixels = trace_refinement(plan, rect, shade, counts, pilot)
    return pixels, rays, shade.tracer.name


@contextlib.contextmanager
def _tile_tracing(bundle: SceneBundle, job: Job, time: Optional[float]) -> Iterator[tuple]:
    """(plan, shade, rays) for a task's tracing: the job's plan, a PixelTracer of the worker's tracer for
    the frame's camera, and a RayCounts that holds the rays the task cast when the block ends."""
    compiled, tracer = _tracer(bundle, job, time)
    plan = _plan(job)
    aspect = job.width / job.height
    frame = CameraFrame.from_camera(scene_camera(compiled.scene, compiled, aspect), aspect)
    before = copy.copy(tracer.counts)
    rays = RayCounts()
    yield plan, PixelTracer(plan, tracer, camera_rays_for(frame, job.width, job.height), chunk=RAYS_PER_CALL), rays
    for f in dataclasses.fields(RayCounts):
        setattr(rays, f.name, getattr(tracer.counts, f.name) - getattr(before, f.name))


def scene_task(bundle: SceneBundle, fn: Callable, args: tuple):
    """A task: ``fn(scene, *args)`` on the scene of a bundle, read once per worker process and shared by the
    tasks (which must not change it)."""
    with _lock:
        folder = _unpacked(bundle)
        scene = _read.get(bundle.digest)
        if scene is None:
            with _as_the_user_knows_it(bundle, folder):
                scene = _read[bundle.digest] = read_scene(Path(folder) / bundle.scene, bundle.lenient)
    with _as_the_user_knows_it(bundle, folder):  # (compiling reads the pixmaps and meshes)
        return fn(scene, *args)


# -- the client side -----------------------------------------------------------------------------------------


def parse_address(address: str) -> Optional[int]:
    """N for ``local:N`` (worker processes of a LocalCluster), None for a scheduler's address."""
    if address.startswith(LOCAL_PREFIX):
        text = address[len(LOCAL_PREFIX):]
        if not text.isdigit() or not 1 <= int(text) <= 256:
            raise TracerError(f"--scheduler {address}: expected local:N with N worker processes from 1 to 256")
        return int(text)
    if "://" not in address and ":" not in address:
        raise TracerError(f"--scheduler {address}: expected an address such as tcp://HOST:8786 or local:N")
    return None


@contextlib.contextmanager
def connect(address: str) -> Iterator[object]:
    """A Dask client for ``address`` (closed, with any cluster it started, when the block ends).

    ``tls://`` addresses use Dask's own security settings (``distributed.comm.tls.*`` in Dask's
    configuration).  Connecting, and then waiting for a first worker, take at most Dask's
    ``distributed.comm.timeouts.connect`` each: a scheduler without workers would leave the render waiting."""
    workers = parse_address(address)
    distributed = require_dask()
    import dask

    timeout = dask.config.get("distributed.comm.timeouts.connect")
    if address.startswith("tls://") and \
            distributed.security.Security().get_connection_args("client").get("ssl_context") is None:
        raise TracerError(f"--scheduler {address}: TLS needs Dask's TLS settings for a client "
                          "(distributed.comm.tls.ca-file, .client.cert, .client.key in Dask's configuration; "
                          "see docs/distributed.md)")
    # For local:N, Dask's diagnostics, which wake every process 50 times a second, sample less often: the
    # workers share this machine's cores with this process.
    with dask.config.set(LOCAL_CLUSTER_CONFIG if workers is not None else {}):
        cluster = None
        try:
            if workers is not None:
                # No dashboard; the scheduler's HTTP endpoint on any free loopback port (not a warning
                # when 8787 is taken by another cluster).  Dask's own logs stay quiet: what fails reaches the
                # user as one line through the tasks, and closing after a Ctrl-C makes workers log, at ERROR,
                # the heartbeats the closed scheduler no longer answers.
                with _workers_deaf_to_interrupts():
                    cluster = distributed.LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       host="127.0.0.1", dashboard_address=None,
                                                       silence_logs=logging.CRITICAL,
                                                       scheduler_kwargs={"dashboard_address": "127.0.0.1:0"})
                client = distributed.Client(cluster, timeout=timeout)
            else:
                client = distributed.Client(address, timeout=timeout)
        except (OSError, TimeoutError) as err:
            if cluster is not None:
                cluster.close()
            reason = " ".join(str(err).split()) or type(err).__name__
            raise TracerError(f"--scheduler {address}: cannot reach the scheduler ({reason})") from None
        except ValueError as err:  # a malformed address, an unknown protocol
            raise TracerError(f"--scheduler {address}: {err}") from None
        try:
            try:
                client.wait_for_workers(1, timeout=dask.utils.parse_timedelta(timeout))
            except (OSError, TimeoutError):
                raise TracerError(f"--scheduler {address}: no worker joined the scheduler within {timeout}") \
                    from None
            yield client
        finally:
            client.close()
            if cluster is not None:
                cluster.close()


#: Signals that a terminal sends to the whole process group (Ctrl-C) or that stop a job (SIGTERM).
_SHIELDED_SIGNALS = (signal.SIGINT, signal.SIGTERM)


@contextlib.contextmanager
def _workers_deaf_to_interrupts() -> Iterator[None]:
    """Starts a LocalCluster's worker processes with Ctrl-C and SIGTERM ignored.

    A terminal sends Ctrl-C to the whole process group: without this, every worker would print its own
    KeyboardInterrupt traceback while this process stops the render with one line and closes the cluster
    (which ends the workers).  An ignored disposition is what a spawned Python inherits and keeps (a handler
    would be reset by exec, and blocking is undone by the event-loop thread that spawns the workers), so the
    signals are ignored here while the cluster starts: a Ctrl-C in those few seconds is not seen."""
    previous = {number: signal.signal(number, signal.SIG_IGN) for number in _SHIELDED_SIGNALS}
    try:
        yield
    finally:
        for number, handler in previous.items():
            signal.signal(number, handler)


def local_threads(address: str) -> Optional[int]:
    """C-core threads per worker for ``local:N``: this machine's cores shared out (None for a remote
    scheduler: each worker uses its own machine's default)."""
    workers = parse_address(address)
    if workers is None:
        return None
    return max(1, default_threads() // workers)


@dataclass
class _Frame:
    """A frame being assembled on the client: its image, row 0 at the top (``film`` is the same pixels
    counted from the bottom, as tiles are)."""

    index: int
    time: Optional[float]
    image: np.ndarray
    waiting: int
    refining: bool = False
    pilot: dict = field(default_factory=dict)  # adaptive sampling: tile rectangle -> tracer.adaptive.PilotTile
    rays: RayCounts = field(default_factory=RayCounts)

    @property
    def film(self) -> np.ndarray:
        return self.image[::-1]


def render_frames(client, bundle: SceneBundle, job: Job, times: Sequence[Optional[float]],
                  on_frame: Callable[[int, np.ndarray, RayCounts, str], None],
                  on_tile: Optional[Callable] = None, eight_bit: bool = False) -> None:
    """Render the frames at ``times`` (None: the scene as read) on the cluster.  Each finished frame goes to
    ``on_frame(index, image, rays, backend)`` (image row 0 at the top, float32), in order of completion;
    ``on_tile`` gets a :class:`tracer.render.TileUpdate` as each tile arrives (image: that frame so far).
    ``eight_bit``: as for :func:`tracer.render.render`, keep only the 8-bit values (each tile converted as it
    arrives, unless adaptive sampling needs the float film) and hand uint8 images to ``on_frame``."""
    distributed = require_dask()
    plan = job.plan()
    bytes_on_arrival = eight_bit and not plan.adaptive
    [bundle_future] = client.scatter([bundle], broadcast=True, hash=False)
    blank = (lambda: new_8bit_image(job.height, job.width)) if bytes_on_arrival else \
        (lambda: np.zeros((job.height, job.width, 3), np.float32))
    frames = [_Frame(i, t, blank(), len(plan.rects)) for i, t in enumerate(times)]
    total = len(frames) * len(plan.rects) * (1 + plan.adaptive)
    meta: dict = {}
    tasks = distributed.as_completed()

    def submit(frame: _Frame, rect, task=trace_tile_task, *more):
        future = client.submit(task, bundle_future, job, frame.time, rect, *more, pure=False,
                               priority=-frame.index)  # earlier frames first: they are written sooner
        meta[future.key] = (frame, rect, task is not trace_tile_task)
        tasks.add(future)

    for frame in frames:
        for rect in plan.rects:
            submit(frame, rect)
    done = 0
    backend = ""
    try:
        for future in tasks:
            frame, rect, refining = meta.pop(future.key)
            r0, c0, r1, c1 = rect
            if refining:
                (rows, cols, values), rays, backend = _result(future, "a tile")
                frame.film[rows, cols] = values
            else:
                window, pilot, rays, backend = _result(future, "a tile")
                frame.film[r0:r1, c0:c1] = to_8bit(window) if bytes_on_arrival else window
                if pilot is not None:
                    frame.pilot[rect] = pilot
            frame.rays.add(rays)
            frame.waiting -= 1
            done += 1
            if on_tile is not None:
                on_tile(TileUpdate(x0=c0, y0=job.height - r1, x1=c1, y1=job.height - r0, block_size=1,
                                   pass_index=plan.pass_count - 1 if refining else 0,
                                   pass_count=plan.pass_count, tiles_done=done, tiles_total=total,
                                   image=frame.image))
            if frame.waiting:
                continue
            if plan.adaptive and not frame.refining:
                from .adaptive import refinement  # deferred: adaptive renders alone load it (as tracer.tiles does)

                frame.refining = True
                counts = refinement(plan, frame.film, frame.pilot.values())
                frame.waiting = len(plan.rects)
                for r0, c0, r1, c1 in plan.rects:
                    submit(frame, (r0, c0, r1, c1), refine_tile_task,
                           np.ascontiguousarray(counts[r0:r1, c0:c1]), frame.pilot.pop((r0, c0, r1, c1)))
                continue
            image, frame.image = frame.image, np.empty((0, 0, 3), np.float32)  # (no finished frame is kept)
            if eight_bit and not bytes_on_arrival:
                image = to_8bit(image, out=new_8bit_image(job.height, job.width))
            on_frame(frame.index, image, frame.rays, backend)
    finally:
        for future in list(tasks.futures):
            future.cancel()
        client.cancel([bundle_future])


class SceneTasks:
    """Runs ``fn(scene, *args)`` for many ``(fn, args)`` on a cluster, the scene's bundle scattered once (the
    ``run_tasks`` of tracer.accuracy.measure).  The functions must be importable on the workers (functions of
    the tracer's modules)."""

    def __init__(self, client, bundle: SceneBundle):
        self.client, self.bundle = client, bundle

    def __call__(self, calls: Sequence[tuple[Callable, tuple]], on_result: Callable[[int, object], None]) -> list:
        distributed = require_dask()
        [bundle_future] = self.client.scatter([self.bundle], broadcast=True, hash=False)
        tasks = distributed.as_completed()
        index_of = {}
        for index, (fn, args) in enumerate(calls):
            # (earlier calls first: the caller reports whole steps as they finish)
            future = self.client.submit(scene_task, bundle_future, fn, args, pure=False, priority=-index)
            index_of[future.key] = index
            tasks.add(future)
        results: list = [None] * len(calls)
        try:
            for future in tasks:
                index = index_of[future.key]
                results[index] = _result(future, "a task")
                on_result(index, results[index])
        finally:
            for future in list(tasks.futures):
                future.cancel()
            self.client.cancel([bundle_future])
        return results


def _result(future, what: str):
    """A finished task's result; its failure as one line (a TracerError from the worker as it is)."""
    try:
        return future.result()
    except TracerError:
        raise
    except Exception as err:  # noqa: BLE001 - a worker's failure becomes one line for the user
        raise TracerError(f"{what} failed on the cluster: {type(err).__name__}: {err}") from None


def frame_times(text: str) -> list[float]:
    """``A-B`` (or ``A``): the frames A, A+1, ..., B as USD time codes."""
    found = re.fullmatch(r"\s*(-?\d+)\s*(?:-\s*(-?\d+)\s*)?", text)
    first, last = (int(found.group(1)), int(found.group(2) or found.group(1))) if found else (0, -1)
    if first > last or last - first >= 100000:
        raise TracerError(f"--frames {text}: expected A-B, whole numbers with A <= B (or one frame A)")
    return [float(f) for f in range(first, last + 1)]


def frame_path(output: str, frame: float) -> str:
    """OUT.png -> OUT_0001.png for frame 1."""
    stem, suffix = os.path.splitext(output)
    return f"{stem}_{int(frame):04d}{suffix}"


__all__ = ["INSTALL_HINT", "Job", "SceneBundle", "SceneTasks", "connect", "frame_path", "frame_times", "local_threads",
           "read_scene", "render_frames", "require_dask", "scene_files"]
