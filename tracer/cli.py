"""``python -m tracer``: render SDL scenes and describe them.

Errors in the user's input end the program with one line on stderr and exit status 2 — never a traceback.
"""
from __future__ import annotations

import argparse
import contextlib
import math
import os
import sys
from dataclasses import replace
from typing import Optional, Sequence

import numpy as np

# (Everything the tracer package itself imports (tracer/__init__.py: the reader, compiling, rendering) is
# imported here as usual: the program has loaded it anyway.  What only some commands use is imported by them.)
from . import signals
from .backend import load_core
from .bulk import collector_paused, one_blas_thread
from .compile import compile_scene, fold_tree
from .errors import RenderCancelled, TracerError, warnings_as_lines
from .imageio import output_format, png_rows, save_image
from .model import MAX_RECURSION_DEPTH, ShapeTable, traced_depth
from .render import MAX_DIMENSION, budget_note, check_size, render
from .reporting import error_message
from .savings import RaySavings
from .sdl.parser import load
from .shapes import REGISTRY
from .textures import drop_unreadable_textures
from .tiles import DEFAULT_TILE
from .trace import RayCounts

EXIT_USAGE = 2
EXIT_INTERRUPTED = 130
#: The status of a command whose output was closed by its reader (``info big.sdl | head``): what a Unix tool
#: ended by SIGPIPE reports to its shell.
EXIT_OUTPUT_CLOSED = 128 + 13


def _add_scene_options(p: argparse.ArgumentParser) -> None:
    p.add_argument("scene", help="scene file: SDL, or USD (.usda, .usd, .usdc)")
    p.add_argument("--lenient", action="store_true",
                   help="read what can be read: print one warning per problem in the file and go on")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="python -m tracer",
                                     description="Ray trace SDL scenes (F. S. Hill's Scene Description Language).")
    sub = parser.add_subparsers(dest="command", required=True)

    r = sub.add_parser("render", help="ray trace a scene to an image file")
    _add_scene_options(r)
    r.add_argument("-o", "--output", required=True, help="image file to write (.png, .bmp, .ppm, .jpg, .tif)")
    r.add_argument("--width", type=int, default=640,
                   help=f"image width in pixels (default 640, at most {MAX_DIMENSION})")
    r.add_argument("--height", type=int, default=480,
                   help=f"image height in pixels (default 480, at most {MAX_DIMENSION})")
    r.add_argument("--block-size", type=int, default=1, metavar="B",
                   help="trace one ray per BxB block of pixels (the lecture's blockSize; default 1)")
    r.add_argument("--progressive", action="store_true",
                   help="refine coarse to fine: passes B, B/2, ..., 1, reusing earlier samples")
    r.add_argument("--samples", type=int, default=1, metavar="N",
                   help="rays per pixel for anti-aliasing (default 1: one ray through the pixel centre)")
    r.add_argument("--sampling", choices=("regular", "jittered", "adaptive"), default="jittered",
                   help="where the samples go: a regular grid, one random point per stratum, or about N "
                        "rays per pixel on average, jittered, where an error model says they lower the "
                        "image's error most (default jittered)")
    r.add_argument("--threshold", type=float, default=None, metavar="T",
                   help="no longer used (adaptive sampling places its rays by an error model); accepted, with a "
                        "warning")
    r.add_argument("--backend", choices=("auto", "c", "numpy"), default="auto",
                   help="who does the per-ray work (default: the C core when it is built)")
    r.add_argument("--threads", type=int, default=None, metavar="N",
                   help="threads of the C core (default: $SDL_TRACER_THREADS, else every core)")
    r.add_argument("--max-depth", type=int, default=None, metavar="N",
                   help="override the scene's maxRecursionDepth")
    r.add_argument("--target-error", type=float, default=None, metavar="E",
                   help="sample until the image's estimated RMSE (linear colour clipped to [0, 1]; 1/255 is "
                        "one 8-bit step) is at most E, rays going where they lower it most, and report the "
                        "estimate (replaces --samples, --sampling, --block-size and --progressive)")
    r.add_argument("--per-pixel", action="store_true",
                   help="with --target-error: every pixel's standard error at most E instead of the image's "
                        "RMSE (many more rays)")
    r.add_argument("--cutoff", type=float, default=None, metavar="W",
                   help="do not trace reflected or transmitted rays whose weight in the pixel is below W "
                        "(default 1/512; 0 traces them all)")
    r.add_argument("--all-rays", action="store_true",
                   help="trace every ray the recursion asks for, even those that cannot change the image "
                        "(no cutoff, no skipped shadow feelers, total internal reflection traced twice)")
    r.add_argument("--stats", action="store_true",
                   help="print JSON statistics (ray counts, rays skipped per reason, seconds, backend) on stdout")
    r.add_argument("-q", "--quiet", action="store_true", help="no progress display")
    _add_cluster_options(r)

    b = sub.add_parser("bench", help="measurements")
    bench = b.add_subparsers(dest="bench", required=True)
    acc = bench.add_parser("accuracy", help="error against a dense reference, and time, for each setting")
    acc.add_argument("scenes", nargs="+", metavar="SCENE", help="SDL scene files")
    acc.add_argument("-o", "--output", required=True, metavar="DIR", help="folder for the CSV files and plots")
    acc.add_argument("--width", type=int, default=96, help="image width in pixels (default 96)")
    acc.add_argument("--height", type=int, default=72, help="image height in pixels (default 72)")
    acc.add_argument("--reference-samples", type=int, default=2048, metavar="N",
                     help="jittered rays per pixel of the reference (default 2048)")
    acc.add_argument("--seeds", type=int, default=5, metavar="K",
                     help="runs of each setting, one per seed: error mean and spread, time median and IQR "
                          "(default 5, at least 3)")
    acc.add_argument("--backend", choices=("auto", "c", "numpy"), default="auto",
                     help="who does the per-ray work (default: the C core when it is built)")
    acc.add_argument("--lenient", action="store_true",
                     help="read what can be read: print one warning per problem in the file and go on")
    acc.add_argument("--scheduler", metavar="ADDRESS",
                     help="run the renders of the sweep as tasks on a Dask cluster, as render --scheduler does "
                          "(the same results; see docs/distributed.md)")

    i = sub.add_parser("info", help="list a scene's objects, lights and live effects")
    _add_scene_options(i)
    i.add_argument("--json", action="store_true", help="print JSON instead of text")

    c = sub.add_parser("convert", help="convert a scene between SDL (.sdl, .dat) and USD (.usda, .usd, .usdc)")
    c.add_argument("source", metavar="SRC", help="scene to read (.sdl, .dat, .usda, .usd, .usdc)")
    c.add_argument("destination", metavar="DST", help="file to write; its extension picks the format")
    c.add_argument("--lenient", action="store_true",
                   help="read what can be read: print one warning per problem in the file and go on")
    return parser


def _add_cluster_options(r: argparse.ArgumentParser) -> None:
    r.add_argument("--scheduler", metavar="ADDRESS",
                   help="render the tiles on a Dask cluster: a scheduler's address (tcp://HOST:8786, tls://...) "
                        "or local:N for N worker processes on this machine (pip install "
                        "'sdl-raytracer[distributed]'; see docs/distributed.md)")
    r.add_argument("--frames", metavar="A-B",
                   help="a USD stage's frames A to B, written as OUT_####.png (OUT_0001.png for frame 1)")
    r.add_argument("--tile", type=int, default=None, metavar="N",
                   help="with --scheduler or --frames: tile side in pixels, one task each (default 256 on a "
                        "cluster, 64 on this machine); the image does not depend on it")


SDL_EXTENSIONS = (".sdl", ".dat")


def _scene_format(path: str, role: str) -> str:
    """'sdl' or 'usd' from a file name's extension (a scene to read may have any other extension: SDL)."""
    from .usd.common import USD_EXTENSIONS  # deferred: the USD package is loaded only for USD files

    suffix = os.path.splitext(path)[1].lower()
    if suffix in USD_EXTENSIONS:
        return "usd"
    if suffix in SDL_EXTENSIONS or role != "destination":
        return "sdl"
    raise TracerError(f"{path}: cannot tell the format of the {role} from its extension "
                      f"(use {', '.join(SDL_EXTENSIONS + USD_EXTENSIONS)})")


def _read_scene(path: str, lenient: bool, role: str = "scene"):
    if _scene_format(path, role) == "usd":
        from .usd import load_usd  # deferred: (as above)
        return load_usd(path, strict=not lenient)
    return load(path, strict=not lenient)


def _load(args):
    scene = _read_scene(args.scene, args.lenient)
    for message in scene.warnings:
        print(f"warning: {message}", file=sys.stderr)
    return scene


def _convert(args) -> int:
    target = _scene_format(args.destination, "destination")
    scene = _read_scene(args.source, args.lenient, "source")
    for message in scene.warnings:
        print(f"warning: {message}", file=sys.stderr)
    try:
        if target == "usd":
            from .usd import save_usd  # deferred: (the USD package, as above)
            save_usd(scene, args.destination)
        else:
            from .sdl.writer import save_sdl  # deferred: only convert writes SDL
            save_sdl(scene, args.destination)
    except TracerError:
        raise
    except ValueError as err:  # something SDL (or USD) cannot express
        raise TracerError(f"{args.destination}: {err}") from None
    except Exception as err:  # noqa: BLE001 — a problem writing (usd-core's, the system's): about the destination
        message = error_message(err, args.destination)
        if message is None:
            raise
        raise TracerError(message) from None
    return 0


class _Progress:
    """A one-line percentage on stderr, only when stderr is a terminal."""

    def __init__(self, enabled: bool):
        self.enabled = enabled and sys.stderr.isatty()
        self.shown = -1

    def __call__(self, update) -> None:
        percent = int(100 * update.fraction)
        if self.enabled and percent != self.shown:
            self.shown = percent
            sys.stderr.write(f"\rtracing: {percent:3d}%  (block size {update.block_size})")
            sys.stderr.flush()

    def close(self) -> None:
        if self.enabled and self.shown >= 0:
            sys.stderr.write("\n")


def _savings(args):
    """The RaySavings that --all-rays and --cutoff ask for."""
    savings = RaySavings.none() if args.all_rays else RaySavings()
    if args.cutoff is not None:
        if not (math.isfinite(args.cutoff) and 0.0 <= args.cutoff <= 1.0):
            raise TracerError(f"--cutoff must be a weight between 0 and 1, not {args.cutoff}")
        savings = replace(savings, cutoff=args.cutoff)
    return savings


#: The fixed-sampling options that --target-error replaces (argparse names), in the order --help lists them.
REPLACED_BY_TARGET_ERROR = ("block_size", "progressive", "samples", "sampling")


def _replaced_options_given(args) -> list[str]:
    """The options --target-error replaces that this command line set to something other than their default
    (one left at its default changes nothing, so it is not reported), as the user spelled them."""
    defaults = build_parser().parse_args(["render", args.scene, f"--output={args.output}"])
    return ["--" + name.replace("_", "-") for name in REPLACED_BY_TARGET_ERROR
            if getattr(args, name) != getattr(defaults, name)]


def _render(args) -> int:
    image_format = output_format(args.output)  # (an unknown extension, or no Pillow, is found before tracing)
    if args.threshold is not None:
        print("warning: --threshold is no longer used: adaptive sampling spends about --samples rays per pixel "
              "where its error model says they lower the image's error most (docs/accuracy.md)", file=sys.stderr)
    if args.scheduler is not None or args.frames is not None:
        if args.target_error is not None:  # rounds over the whole image: not cut into independent tiles
            raise TracerError("--target-error cannot be combined with --scheduler or --frames")
        return _render_job(args)
    if args.per_pixel and args.target_error is None:
        print("warning: --per-pixel only changes --target-error, which is not given", file=sys.stderr)
    if args.target_error is not None:
        replaced = _replaced_options_given(args)
        if replaced:
            print(f"warning: --target-error chooses the samples itself: {', '.join(replaced)} ignored",
                  file=sys.stderr)
    scene = _load(args)
    if args.lenient:
        for message in drop_unreadable_textures(scene):
            print(f"warning: {message}", file=sys.stderr)
    if args.max_depth is not None:
        if args.max_depth < 0:
            raise TracerError(f"--max-depth must be 0 or more, not {args.max_depth}")
        if args.max_depth > MAX_RECURSION_DEPTH:
            print(f"warning: --max-depth {args.max_depth} is more than the tracer follows: "
                  f"{MAX_RECURSION_DEPTH} used", file=sys.stderr)
        scene.settings.max_recursion_depth = traced_depth(args.max_depth)
    savings = _savings(args)
    load_core(args.backend)  # a first-use compile of the C core is not render time
    progress = _Progress(not args.quiet)
    options = dict(block_size=args.block_size, progressive=args.progressive, on_tile=progress,
                   samples=args.samples, sampling_mode=args.sampling, backend=args.backend, threads=args.threads,
                   savings=savings, target_error=args.target_error, error_per_pixel=args.per_pixel)
    try:
        if image_format == "PNG":  # the rows go into the file as bands of tiles are done: no whole image kept
            check_size(args.width, args.height)
            with png_rows(args.output, args.width, args.height) as add_rows:
                result = render(scene, args.width, args.height, on_rows=add_rows, **options)
        else:  # (Pillow writes these from the whole image: its 8-bit bytes, 3 a pixel, are all that is kept)
            result = render(scene, args.width, args.height, eight_bit=True, **options)
    finally:
        progress.close()
    if result.image is not None:
        save_image(result.image, args.output, release=True)  # (its rows go back to the system as Pillow takes them)
    _warn_about_budget(args.scene, result.rays)
    if result.error_estimate is not None and not args.quiet:
        from .target import MAX_SAMPLES  # deferred: only renders to an error target load tracer.target
        e = result.error_estimate
        goal = "every pixel" if e.kind == "pixel" else "the image's RMSE"
        print(f"estimated error: {e.rms:.3g} RMS, worst pixel {e.worst:.3g} (target {e.target:g} for {goal}); "
              f"{e.samples_mean:.1f} rays per pixel on average, {e.pixels_at_limit} pixels at the "
              f"{MAX_SAMPLES}-ray limit", file=sys.stderr)
    if args.stats:
        import json

        print(json.dumps(result.stats()))
    return 0


def _warn_about_budget(scene_file: str, rays) -> None:
    note = budget_note(rays)
    if note is not None:
        print(f"warning: {scene_file}: {note}", file=sys.stderr)


def _render_job(args) -> int:
    """``render --scheduler`` (tiles on a Dask cluster) and ``render --frames`` (a USD stage's frames)."""
    import dataclasses
    import time

    from . import distributed as dist  # deferred: only cluster and frame renders load it (and Dask)

    if args.scheduler is not None:
        dist.parse_address(args.scheduler)
        dist.require_dask()
    if args.max_depth is not None and args.max_depth < 0:
        raise TracerError(f"--max-depth must be 0 or more, not {args.max_depth}")
    check_size(args.width, args.height)
    times = dist.frame_times(args.frames) if args.frames is not None else [None]
    outputs = [args.output] if args.frames is None else [dist.frame_path(args.output, t) for t in times]
    scene = dist.read_scene(args.scene, args.lenient, times[0])
    for message in scene.warnings:
        print(f"warning: {message}", file=sys.stderr)
    if args.tile is not None and args.tile < 1:
        raise TracerError(f"--tile must be 1 or more, not {args.tile}")
    tile = args.tile or (dist.CLUSTER_TILE if args.scheduler is not None else DEFAULT_TILE)
    job = dist.Job(args.width, args.height, block_size=args.block_size, progressive=args.progressive,
                   tile=tile, samples=args.samples, sampling_mode=args.sampling, backend=args.backend,
                   threads=args.threads, max_depth=args.max_depth, savings=_savings(args))
    job.plan()  # bad settings are reported before any cluster starts
    load_core(args.backend)  # a first-use compile of the C core is not render time
    started = time.perf_counter()
    rays, backends = RayCounts(), set()

    def write(index, image, counts, backend):
        save_image(image, outputs[index], release=True)
        backends.add(backend)
        rays.add(counts)

    progress = _Progress(not args.quiet)
    try:
        if args.scheduler is None:  # frames on this machine, one after the other
            for index, frame in enumerate(times):
                if index:
                    scene = dist.read_scene(args.scene, args.lenient, frame)
                if args.max_depth is not None:
                    scene.settings.max_recursion_depth = args.max_depth
                result = render(scene, args.width, args.height, block_size=args.block_size,
                                progressive=args.progressive, tile=tile, on_tile=progress, samples=args.samples,
                                sampling_mode=args.sampling, backend=args.backend, threads=args.threads,
                                savings=job.savings, eight_bit=True)
                write(index, result.image, result.rays, result.backend)
        else:
            bundle = dist.SceneBundle.of(args.scene, scene, args.lenient)
            threads = args.threads or dist.local_threads(args.scheduler)
            with dist.connect(args.scheduler) as client:
                dist.render_frames(client, bundle, dataclasses.replace(job, threads=threads), times, write,
                                   progress, eight_bit=True)
    finally:
        progress.close()
    _warn_about_budget(args.scene, rays)
    if args.stats:
        import json

        print(json.dumps({"rays": rays.as_dict(), "skipped": rays.skipped(),
                          "seconds": round(time.perf_counter() - started, 6),
                          "backend": ",".join(sorted(backends)), "width": args.width, "height": args.height,
                          "frames": len(times), "scheduler": args.scheduler}))
    return 0


def describe(scene) -> dict:
    """What ``info`` prints: objects, lights, camera, settings and live effects."""
    def shape_info(shape):
        info = {"shape": shape.kind, "position": [round(x, 6) for x in shape.matrix[:3, 3].tolist()],
                "groups": list(shape.groups)}
        if shape.mesh_file:
            info["file"] = shape.mesh_file
        if shape.name:
            info["name"] = shape.name
        return info

    def obj_info(obj):
        return fold_tree(obj, shape_info, lambda node, left, right: {
            "boolean": node.op, "groups": list(node.groups), "children": [left, right]})

    compiled = compile_scene(scene)
    camera = scene.camera
    rows = scene.objects.columns if isinstance(scene.objects, ShapeTable) else None
    with collector_paused():  # (10^5 new dicts would run it over every Shape many times)
        objects = [obj_info(o) for o in scene.objects] if rows is None else _rows_info(rows)
    return {
        "objects": objects,
        "lights": [_light_info(light) for light in scene.lights],
        "camera": None if camera is None else {"eye": list(camera.eye), "look": list(camera.look),
                                               "up": list(camera.up), "viewAngle": camera.view_angle},
        "effects": sorted(compiled.effects),
        "warnings": list(scene.warnings),
    }


#: The Light fields ``info`` shows for each kind beyond SDL's point light (tracer.model.Light).
_LIGHT_FIELDS = {"sphere": ("radius", "samples"), "spot": ("direction", "spot_size", "spot_blend", "radius", "samples"),
                 "sun": ("direction", "angle", "samples"), "area": ("direction", "axis", "shape", "size", "samples")}


def _light_info(light) -> dict:
    """A light as ``info`` lists it: SDL's point light as before (position, colour), with its name when it has
    one; the other kinds with their kind and fields."""
    out = {"position": list(light.position), "color": list(light.color)}
    if light.name is not None:
        out["name"] = light.name
    if light.kind != "point":
        out["kind"] = light.kind
        for name in _LIGHT_FIELDS[light.kind]:
            value = getattr(light, name)
            out[name] = list(value) if isinstance(value, tuple) else value
    return out


def _numbers_text(values) -> str:
    return ", ".join(f"{x:g}" for x in values)


def _rows_info(rows) -> list[dict]:
    """describe()'s objects for a ShapeTable's columns (tracer.model.ShapeColumns), the same as for its
    Shapes without making them (a big file's shapes stay columns): each row is a shape with no groups and
    no mesh file, at the last column of its affine."""
    keywords = [entry.keyword for entry in REGISTRY]
    positions = _round_decimals(rows.affines[:, 3::4], 6).tolist()
    objects = [{"shape": keywords[kind], "position": position, "groups": []}
               for kind, position in zip(rows.kinds.tolist(), positions)]
    for row, name in (rows.names or {}).items():
        if name:
            objects[row]["name"] = name
    return objects


def _round_decimals(values: np.ndarray, digits: int) -> np.ndarray:
    """Python's round(x, digits) of each value, exactly.  round() rounds the exact binary value to the
    nearest decimal (half to even), then takes the double nearest that decimal; rint(x * 10^digits) /
    10^digits does the same unless x * 10^digits, rounded, lands within a few ulps of a half (where the
    rounding of the product may pick the other neighbour) or is too big for its integer to be exact: those
    few values are left to round()."""
    scale = 10.0 ** digits
    scaled = values * scale
    out = np.rint(scaled) / scale
    with np.errstate(invalid="ignore"):  # (inf and NaN are doubtful, and round() keeps them)
        from_half = np.abs(np.abs(scaled) % 1.0 - 0.5)
        doubtful = ~(from_half > 4.0 * np.spacing(np.abs(scaled))) | ~(np.abs(scaled) < 2.0 ** 50)
    for index in zip(*np.nonzero(doubtful)):
        out[index] = round(float(values[index]), digits)
    return out


def _info(args) -> int:
    import itertools

    info = describe(_load(args))
    if args.json:
        import json

        try:
            print(json.dumps(info, indent=2))
        except RecursionError:  # json's encoder recurses per level of nesting
            raise TracerError(f"{args.scene}: booleans nested too deeply to write as JSON "
                              f"(use info without --json)") from None
        return 0

    def lines(obj, indent):
        todo = [(obj, indent)]  # without recursion: booleans may nest deeper than Python's stack
        while todo:
            obj, indent = todo.pop()
            pad = "  " * indent
            group = f"  [{'/'.join(obj['groups'])}]" if obj["groups"] else ""
            if "boolean" in obj:
                yield f"{pad}{obj['boolean']}{group}"
                todo += [(child, indent + 1) for child in reversed(obj["children"])]
            else:
                extra = f" {obj['file']}" if "file" in obj else ""
                extra += f" {obj['name']!r}" if "name" in obj else ""
                yield f"{pad}{obj['shape']}{extra} at ({', '.join(f'{x:g}' for x in obj['position'])}){group}"

    print(f"objects: {len(info['objects'])}")
    object_lines = (line for obj in info["objects"] for line in lines(obj, 1))
    while chunk := list(itertools.islice(object_lines, 4096)):
        print("\n".join(chunk))  # (a print() per line took a third of the time for 10^5 objects)
    print(f"lights: {len(info['lights'])}")
    for light in info["lights"]:
        kind = light.get("kind", "point")
        where = (f"towards ({_numbers_text(light['direction'])})" if kind == "sun"
                 else f"at ({_numbers_text(light['position'])})")
        print(f"  {'' if kind == 'point' else kind + ' '}{where} colour ({_numbers_text(light['color'])})"
              + (f" {light['name']!r}" if "name" in light else ""))
    cam = info["camera"]
    print("camera: " + ("default (frames the scene)" if cam is None else
                        f"eye {tuple(cam['eye'])} look {tuple(cam['look'])} angle {cam['viewAngle']:g}"))
    print("live effects: " + (", ".join(info["effects"]) or "none"))
    return 0


def _bench(args) -> int:
    from pathlib import Path

    # deferred: the accuracy bench (and scikit-image, SciPy, matplotlib) is loaded by its command only
    from .accuracy import BenchConfig, measure, plot_targets, write_report

    check_size(args.width, args.height)
    if min(args.width, args.height) < 7:  # scikit-image's SSIM window
        raise TracerError(f"the accuracy bench needs images of at least 7 x 7 pixels, not {args.width} x {args.height}")
    if args.seeds < 3:
        raise TracerError(f"--seeds must be at least 3 (a spread needs them), not {args.seeds}")
    if args.reference_samples < 2:
        raise TracerError(f"--reference-samples must be at least 2, not {args.reference_samples}")
    config = BenchConfig(width=args.width, height=args.height, reference_samples=args.reference_samples,
                         seeds=args.seeds, backend=args.backend,
                         savings_size=(max(args.width, 320), max(args.height, 240)))
    out = Path(args.output)
    scenes = [(path, Path(path).stem, load(path, strict=not args.lenient)) for path in args.scenes]

    def progress(line):
        print(line, flush=True)

    if args.scheduler is None:
        summaries = [measure(scene, name, out, config, progress=progress) for _, name, scene in scenes]
    else:
        from . import distributed as dist  # deferred: (as in _render_job)

        dist.parse_address(args.scheduler)
        dist.require_dask()
        config = replace(config, threads=dist.local_threads(args.scheduler))
        bundles = [dist.SceneBundle.of(path, scene, args.lenient) for path, _, scene in scenes]
        with dist.connect(args.scheduler) as client:
            summaries = [measure(scene, name, out, config, progress=progress,
                                 run_tasks=dist.SceneTasks(client, bundle))
                         for (_, name, scene), bundle in zip(scenes, bundles)]
    plot_targets(summaries, out / "target_error.png")
    write_report(summaries, out / "report.md")
    return 0


def _output_closed() -> bool:
    """Whether standard output is a pipe whose reader has gone (then the broken pipe was the output's, not a
    connection's or a file's): polling such a pipe reports an error.  If so, output is sent to the null
    device from here on, so that Python's own flush at exit does not print a second complaint."""
    import select
    try:
        fd = sys.stdout.fileno()
        poller = select.poll()  # (POSIX; elsewhere AttributeError: then it is not known to be closed)
        poller.register(fd, select.POLLOUT)
        closed = any(events & select.POLLERR for _, events in poller.poll(0))
    except (AttributeError, OSError, ValueError):
        return False
    if closed:
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, fd)
        os.close(devnull)
    return closed


def _final_output(args) -> Optional[str]:
    """The file whose completion ends the command's work (after it, a signal changes nothing)."""
    if args.command == "convert":
        return args.destination
    if args.command == "render" and args.frames is None:
        return args.output
    return None


class _NamedOutput:
    """Standard output whose write errors (a full disk, ``> /dev/full``) name it: left alone, they would be
    reported as the scene's (an OSError without a file name), or by Python's complaint at exit."""

    NAME = "standard output"

    def __init__(self, stream):
        self._stream = stream

    def write(self, text):
        return self._named(self._stream.write, text)

    def flush(self):
        return self._named(self._stream.flush)

    def _named(self, call, *args):
        try:
            return call(*args)
        except BrokenPipeError:  # (main tells a reader that went away from a real error)
            raise
        except OSError as err:
            raise type(err)(err.errno, err.strerror or str(err), self.NAME) from None

    def __getattr__(self, name):
        return getattr(self._stream, name)


@contextlib.contextmanager
def _stdout_named():
    """sys.stdout is a :class:`_NamedOutput` meanwhile, written out before the block ends."""
    stream = sys.stdout
    if stream is None:
        yield
        return
    sys.stdout = _NamedOutput(stream)
    try:
        yield
        sys.stdout.flush()
    finally:
        sys.stdout = stream


def _dash_names_attached(argv: Sequence[str]) -> list[str]:
    """``-o -x.png`` as ``--output=-x.png``: argparse takes a word after an option that starts with "-" for
    another option (and stops with its usage), but a file name may start with one (fuzz seed 2817008540).
    Only a word with a "." (an output's extension) is taken for a name: ``-o --width`` stays an error."""
    argv = list(argv)
    for k in range(len(argv) - 2, -1, -1):
        if argv[k] in ("-o", "--output") and argv[k + 1].startswith("-") and "." in argv[k + 1]:
            argv[k:k + 2] = [f"--output={argv[k + 1]}"]
    return argv


def main(argv: Optional[Sequence[str]] = None) -> int:
    args = build_parser().parse_args(_dash_names_attached(sys.argv[1:] if argv is None else argv))
    subject = getattr(args, "scene", None) or getattr(args, "source", None)
    try:
        with signals.working(_final_output(args)), np.errstate(all="ignore"), warnings_as_lines(sys.stderr), \
                one_blas_thread(), _stdout_named():
            load_core(getattr(args, "backend", "auto"))  # (its signal handler and watchdog: tracer.signals)
            return {"render": _render, "info": _info, "bench": _bench, "convert": _convert}[args.command](args)
    except signals.Interrupted as err:
        print("\ninterrupted", file=sys.stderr)
        signals.end_interrupted_program(err.status)
        return err.status
    except RenderCancelled:  # (a TracerError: caught first)
        if signals.heard():  # the C core stopped for a signal, before Python's handler could say so
            print("\ninterrupted", file=sys.stderr)
            signals.end_interrupted_program(128 + signals.heard())
            return 128 + signals.heard()
        print("error: cancelled", file=sys.stderr)
        return EXIT_INTERRUPTED
    except BrokenPipeError as err:  # (an OSError: caught before the input's errors)
        if _output_closed():
            return EXIT_OUTPUT_CLOSED  # the reader wanted no more: nothing is wrong with the input
        message = error_message(err, subject)
        print(f"error: {message}", file=sys.stderr)
        return EXIT_USAGE
    except Exception as err:  # noqa: BLE001 — translated if it is the input's fault, else raised again
        message = error_message(err, subject)
        if message is None:
            raise
        print(f"error: {message}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("\ninterrupted", file=sys.stderr)
        return EXIT_INTERRUPTED
