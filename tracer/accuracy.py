"""``python -m tracer bench accuracy``: what accuracy costs, with error bars.

For each scene:

* a **reference**: ``reference_samples`` jittered rays per pixel (at least 2,048 in ``make accuracy``), in
  parts of at most 1,024 with independent seeds, at the scene's own recursion depth — the depth every
  sampling row uses, so that no row is charged with the bias of a shallower recursion.  The spread of the
  parts gives the reference's own estimated RMSE;
* **settings**, one change at a time from the baseline (one ray through each pixel centre, block size 1,
  the scene's depth, default tolerances, default ray savings): block sizes, samples per sampling mode,
  recursion depth, solver tolerances, and every ray traced (no savings).  Each setting runs once per seed
  (``seeds`` >= 3; the runs of all settings are interleaved, so a change in the machine's load touches
  them all alike): the error is the mean and standard deviation over the seeds, the time the median and
  interquartile range — wall seconds, split into compiling the scene and tracing it, and CPU seconds of all
  the process's threads, which a busy machine disturbs far less; rays are counted per kind (a cost axis
  without timing noise);
* **depth bias**: each depth row's RMSE against the same rays at depth max(8, scene's) (pixel-centre rays, so
  sampling noise cancels exactly), and the scene's own depth as its own row;
* **slopes**: RMSE against samples per sampling mode, fitted on log-log axes (``scipy.stats.linregress``)
  over N >= 4;
* the **Pareto front** of the sampling and block-size rows, error against rays and against CPU seconds;
* **error targets**: ``--target-error E`` renders, their estimated against their measured error;
* **the cost to reach each E**: for the error target (one render per seed), and for uniform jittered and
  adaptive sampling the fewest rays per pixel (from COST_LADDER) whose mean RMSE over the seeds is at most
  E: camera rays, all rays and CPU seconds, mean and spread over the seeds.

Every render is a task ``fn(scene, *args)`` whose arguments carry all it depends on (the setting, the
seed, the configuration; a setting's solver tolerances are applied while its scene compiles, under a lock,
and the compiled scene keeps them), so the tasks run one after the other here or, with ``bench accuracy
--scheduler``, on a Dask cluster (:class:`tracer.distributed.SceneTasks`) with the same results; errors,
slopes and fronts are worked out here from the images that come back.

Metrics come from scikit-image (``mean_squared_error``, ``peak_signal_noise_ratio``,
``structural_similarity``) on colour clipped to [0, 1]; statistics from NumPy and SciPy.  Writes
``DIR/SCENE.csv``, ``DIR/SCENE.json``, ``DIR/SCENE.png`` (three panels), and, for all scenes together,
``DIR/target_error.png`` and ``DIR/report.md`` (the tables docs/accuracy.md quotes).
"""
from __future__ import annotations

import contextlib
import csv
import json
import math
import threading
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Callable, Iterator, Optional, Sequence

import numpy as np

from . import numerics
from .compile import CompiledScene, compile_scene, live_effects
from .model import Scene
from .render import RenderResult, render
from .savings import RaySavings
from .trace import RAY_KINDS

REFERENCE_PART = 1024  # tracer.sampling.MAX_SAMPLES: the reference is the mean of parts of this many rays
DEEP = 8  # the recursion depth the depth rows are compared with
FIELDS = ("group", "setting", "samples", "runs", "rays", *(f"rays_{k}" for k in RAY_KINDS), "rmse_mean", "rmse_std",
          "psnr_mean", "ssim_mean", "depth_bias", "seconds_median", "seconds_iqr", "cpu_median", "cpu_iqr",
          "compile_median",
          "trace_median", "pareto_rays", "pareto_seconds")
#: Edges of the bins of per-pixel error estimates in the target plot (at least 10 pixels per bin are shown).
TARGET_BINS = 1e-4 * 2.0 ** np.arange(11)
#: Rays per pixel tried, in turn, for the cheapest uniform jittered and adaptive setting reaching each target.
COST_LADDER = (1, 2, 3, 4, 5, 6, 8, 10, 12, 16, 20, 24, 32, 48, 64, 96, 128, 192, 256)
#: The rows that trade error for cost (the Pareto fronts are taken over them).
TRADE_GROUPS = ("block size", "baseline", "samples (regular)", "samples (jittered)", "samples (adaptive)")


@dataclass(frozen=True)
class Setting:
    group: str
    label: str
    block_size: int = 1
    samples: int = 1
    mode: str = "jittered"
    depth: Optional[int] = None  # None: the scene's own maxRecursionDepth
    #: numerics.Tolerances.hit_ulps: scales the hit-error bounds behind ray offsets and CSG merging
    hit_ulps: Optional[float] = None
    newton_steps: Optional[int] = None  # torus root polishing
    savings: Optional[RaySavings] = None  # None: the defaults


@dataclass(frozen=True)
class BenchConfig:
    """How big the measurement is.  ``make accuracy`` uses the defaults: 96 x 72 pixels keeps a 2,048-ray
    reference of four scenes near one minute of two cores, and every ratio the report draws is between
    settings at the same size."""

    width: int = 96
    height: int = 72
    reference_samples: int = 2048
    seeds: int = 5
    sample_counts: tuple[int, ...] = (4, 16, 64, 256)
    targets: tuple[float, ...] = (0.02, 0.01, 0.005)
    backend: str = "auto"
    #: the ray savings are timed at a size where tracing, not per-render overhead, takes the time, over
    #: more runs than the settings (a difference of 10-30 % has to stand out of this machine's noise)
    savings_size: tuple[int, int] = (320, 240)
    savings_runs: int = 15
    threads: Optional[int] = None  # the C core's threads per render (None: its default, every core)


#: ``run_tasks(calls, on_result)``: runs ``fn(scene, *args)`` for every ``(fn, args)`` of ``calls`` and returns
#: the results in the order of ``calls``, handing each to ``on_result(index, result)`` as it is done.
RunTasks = Callable[[Sequence[tuple[Callable, tuple]], Callable[[int, Any], None]], list]


def run_here(scene: Scene) -> RunTasks:
    """The tasks of a sweep run in this process, one after the other, in order."""
    def run_tasks(calls, on_result):
        results = []
        for index, (fn, args) in enumerate(calls):
            results.append(fn(scene, *args))
            on_result(index, results[-1])
        return results

    return run_tasks


def default_settings(scene_depth: int, effects: frozenset = frozenset({"reflection", "shape:torus"}),
                     sample_counts: tuple[int, ...] = BenchConfig.sample_counts) -> list[Setting]:
    """The sweep; settings that cannot change a scene's image (recursion depth without mirrors or glass,
    torus polishing without a torus, ray savings without secondary rays) are left out for that scene."""
    out = [Setting("block size", f"B={b}", block_size=b) for b in (16, 8, 4, 2)]
    out.append(Setting("baseline", "1 ray/pixel"))
    out += [Setting(f"samples ({mode})", f"{mode} {n}", samples=n, mode=mode)
            for mode in ("regular", "jittered", "adaptive") for n in sample_counts]
    deep = effects & {"reflection", "refraction"}
    if deep:
        out += [Setting("recursion depth", f"depth {d}", depth=d) for d in sorted({0, 1, 2, scene_depth, DEEP})]
    out += [Setting("hit error ulps", f"ulps {e:g}", hit_ulps=e) for e in (1, 4, 64, 1e4, 1e8)]
    if "shape:torus" in effects:
        out += [Setting("torus Newton steps", f"newton {n}", newton_steps=n) for n in (0, 1)]
    if deep or "shadows" in effects:
        out.append(Setting("ray savings", "all rays traced", savings=RaySavings.none()))
    return out


@contextlib.contextmanager
def solver_tolerances(setting: Setting) -> Iterator[None]:
    """Temporarily use a setting's tolerances: numerics.TOLERANCES, which compile_scene copies into the
    scenes it compiles (and flatten hands to the C core).  Process-wide: see :func:`compiled_for`."""
    saved = numerics.TOLERANCES
    try:
        if setting.hit_ulps is not None:
            numerics.TOLERANCES = replace(numerics.TOLERANCES, hit_ulps=setting.hit_ulps)
        if setting.newton_steps is not None:
            numerics.TOLERANCES = replace(numerics.TOLERANCES, torus_newton_steps=setting.newton_steps)
        yield
    finally:
        numerics.TOLERANCES = saved


#: One compile at a time per process while a setting's tolerances are in numerics.TOLERANCES: a worker may
#: run several tasks of a sweep, of different settings, in threads, and every task compiles through
#: compiled_for.
_compiling = threading.Lock()


def compiled_for(scene: Scene, setting: Optional[Setting] = None) -> CompiledScene:
    """The scene compiled with a setting's depth and tolerances (None: its own depth, the default
    tolerances).  The compiled scene carries its tolerances (its primitives and the C core read them from
    it), so tracing it needs no global state."""
    setting = setting or Setting("baseline", "as read")
    with _compiling, solver_tolerances(setting):
        return compile_scene(_with_depth(scene, setting.depth))


def _with_depth(scene: Scene, depth: Optional[int]) -> Scene:
    if depth is None:
        return scene
    return replace(scene, settings=replace(scene.settings, max_recursion_depth=depth))


def errors(image: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    """RMSE, PSNR and SSIM (scikit-image) of colour clipped to [0, 1]."""
    from skimage.metrics import mean_squared_error, peak_signal_noise_ratio, structural_similarity

    a = np.clip(image, 0, 1).astype(np.float64)
    b = np.clip(reference, 0, 1).astype(np.float64)
    rmse = math.sqrt(mean_squared_error(b, a))
    psnr = math.inf if rmse == 0 else float(peak_signal_noise_ratio(b, a, data_range=1.0))
    ssim = float(structural_similarity(b, a, channel_axis=2, data_range=1.0))
    return {"rmse": rmse, "psnr": psnr, "ssim": ssim}


def reference_parts(config: BenchConfig, seed: int = 1_000_003) -> list[tuple[int, int]]:
    """(seed, rays per pixel) of each part of the reference: parts of at most REFERENCE_PART rays."""
    parts = max(2, math.ceil(config.reference_samples / REFERENCE_PART))
    return [(seed + k, max(1, config.reference_samples // parts)) for k in range(parts)]


def reference_part(scene: Scene, config: BenchConfig, seed: int, samples: int) -> tuple[np.ndarray, float]:
    """A task: one part of the reference, clipped to [0, 1], and the seconds it took."""
    started = time.perf_counter()
    image = render(compiled_for(scene), config.width, config.height, samples=samples, seed=seed,
                   backend=config.backend, threads=config.threads).image
    return np.clip(image, 0, 1).astype(np.float64), time.perf_counter() - started


def combine_reference(parts: Sequence[tuple[np.ndarray, float]]) -> tuple[np.ndarray, float, float]:
    """(image, its estimated RMSE, seconds): the mean of the parts; the estimate is the standard error of that
    mean from the parts' spread."""
    images = np.stack([image for image, _ in parts])
    estimate = math.sqrt(float(np.mean(images.var(axis=0, ddof=1) / len(parts))))
    return images.mean(axis=0), estimate, sum(seconds for _, seconds in parts)


def reference_image(scene: Scene, config: BenchConfig, seed: int = 1_000_003) -> tuple[np.ndarray, float, float]:
    """(image, its estimated RMSE, seconds): the mean of independently seeded parts of at most
    REFERENCE_PART rays per pixel."""
    return combine_reference([reference_part(scene, config, *part) for part in reference_parts(config, seed)])


def run_setting(scene: Scene, setting: Setting, seed: int, config: BenchConfig) -> dict:
    """A task: one render of a setting.  Its image (float32, as rendered), rays, and the wall seconds of
    compiling and of tracing, and the CPU seconds of all the process's threads."""
    started, cpu_started = time.perf_counter(), time.process_time()
    compiled = compiled_for(scene, setting)
    compiled_at = time.perf_counter()
    result = render(compiled, config.width, config.height, block_size=setting.block_size,
                    samples=setting.samples, sampling_mode=setting.mode, seed=seed, backend=config.backend,
                    savings=setting.savings, threads=config.threads)
    done, cpu = time.perf_counter(), time.process_time() - cpu_started
    return {"image": result.image, "compile": compiled_at - started, "trace": done - compiled_at, "cpu": cpu,
            "rays": result.rays.as_dict(), "skipped": result.rays.skipped(), "backend": result.backend}


def pareto_front(cost: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Boolean mask of the points no other point beats in both cost and error (ties kept)."""
    cost, error = np.asarray(cost, float), np.asarray(error, float)
    beaten = (cost[None, :] <= cost[:, None]) & (error[None, :] <= error[:, None]) & \
             ((cost[None, :] < cost[:, None]) | (error[None, :] < error[:, None]))
    return ~beaten.any(axis=1)


def fitted_slopes(rows: list[dict]) -> dict[str, dict]:
    """Per sampling mode: the slope of log RMSE against log samples (N >= 4), with its standard error."""
    from scipy.stats import linregress

    out = {}
    for mode in ("regular", "jittered", "adaptive"):
        pts = [r for r in rows if r["group"] == f"samples ({mode})" and r["samples"] >= 4 and r["rmse_mean"] > 0]
        if len(pts) >= 2:
            fit = linregress(np.log([r["samples"] for r in pts]), np.log([r["rmse_mean"] for r in pts]))
            out[mode] = {"slope": float(fit.slope), "stderr": float(fit.stderr), "intercept": float(fit.intercept),
                         "samples": [r["samples"] for r in pts]}
    return out


def _summarise(setting: Setting, runs: list[dict]) -> dict:
    rmse = np.array([r["rmse"] for r in runs])
    seconds = np.array([r["compile"] + r["trace"] for r in runs])
    q1, median, q3 = np.percentile(seconds, [25, 50, 75])
    c1, cpu, c3 = np.percentile([r["cpu"] for r in runs], [25, 50, 75])
    rays = {k: float(np.mean([r["rays"][k] for r in runs])) for k in RAY_KINDS}
    return {"group": setting.group, "setting": setting.label, "samples": setting.samples, "runs": len(runs),
            "rays": round(sum(rays.values())), **{f"rays_{k}": round(v) for k, v in rays.items()},
            "rmse_mean": float(rmse.mean()), "rmse_std": float(rmse.std(ddof=1)) if len(runs) > 1 else 0.0,
            "psnr_mean": float(np.mean([r["psnr"] for r in runs])),
            "ssim_mean": float(np.mean([r["ssim"] for r in runs])),
            "depth_bias": runs[0].get("depth_bias", ""),
            "seconds_median": float(median), "seconds_iqr": float(q3 - q1),
            "cpu_median": float(cpu), "cpu_iqr": float(c3 - c1),
            "compile_median": float(np.median([r["compile"] for r in runs])),
            "trace_median": float(np.median([r["trace"] for r in runs])),
            "pareto_rays": False, "pareto_seconds": False,
            "skipped": {k: float(np.mean([r["skipped"][k] for r in runs])) for k in runs[0]["skipped"]}}


def target_render(scene: Scene, config: BenchConfig, target: float, seed: int = 7) -> dict:
    """A task: a render to an error target, and the CPU seconds of all the process's threads it took."""
    cpu_started = time.process_time()
    result = render(compiled_for(scene), config.width, config.height, target_error=target, seed=seed,
                    backend=config.backend, threads=config.threads)
    return {"result": result, "cpu": time.process_time() - cpu_started}


def target_row(result: RenderResult, target: float, reference: np.ndarray) -> dict:
    """A render to an error target: its estimate against the error measured against the reference, for the
    image and per pixel (pixels binned by their estimate)."""
    estimate = result.error_estimate
    # Per pixel, the RMS over the channels, as the estimate's unit is one channel's error.
    per_pixel = np.sqrt(np.mean((np.clip(result.image, 0, 1) - reference) ** 2, axis=2))
    # Bins of the estimate, by factors of two from 1e-4 (below it, pixels are flat: a variance near 0).
    which = np.digitize(estimate.per_pixel, TARGET_BINS)
    bins = [(float(np.sqrt(np.mean(estimate.per_pixel[which == b] ** 2))),
             float(np.sqrt(np.mean(per_pixel[which == b] ** 2))))
            for b in range(1, len(TARGET_BINS)) if np.count_nonzero(which == b) >= 10]
    return {"target": target, "estimated_rmse": estimate.rms, "measured_rmse": errors(result.image, reference)["rmse"],
            "worst_estimate": estimate.worst, "measured_p99": float(np.percentile(per_pixel, 99)),
            "samples_mean": estimate.samples_mean, "pixels_at_limit": estimate.pixels_at_limit,
            "rays": int(sum(result.rays.as_dict().values())), "seconds": result.seconds, "bins": bins}


def _cost(method: str, target: float, samples: Optional[int], runs: list[dict]) -> dict:
    """One row of the cost to reach ``target``: a method's camera rays, all rays, CPU seconds and RMSE, mean
    and standard deviation over its runs (one per seed)."""
    def spread(key: str) -> tuple[float, float]:
        values = np.array([r[key] for r in runs], dtype=float)
        return float(values.mean()), float(values.std(ddof=1)) if len(values) > 1 else 0.0

    row = {"target": target, "method": method, "samples": samples, "runs": len(runs)}
    for key in ("camera", "rays", "cpu", "rmse"):
        row[f"{key}_mean"], row[f"{key}_sd"] = spread(key)
    if runs and "estimated" in runs[0]:  # an error target: how far its estimates were from the truth
        ratios = [r["rmse"] / r["estimated"] for r in runs if r["estimated"] > 0]
        row["measured_over_estimated"] = [min(ratios), max(ratios)] if ratios else None
    return row


def cost_to_reach(scene: Scene, config: BenchConfig, reference: np.ndarray, run_tasks: RunTasks,
                  target_runs: dict[float, list[dict]], progress=print) -> list[dict]:
    """Per target E: the error target's cost (``target_runs``: its runs, one per seed), and the cheapest
    uniform jittered and adaptive settings of COST_LADDER whose mean RMSE reaches E, each step of the ladder
    one batch of renders (one per seed), until every target is reached or the ladder ends."""
    rows = []
    for target in config.targets:
        rows.append(_cost("target", target, None, target_runs[target]))
    for mode in ("jittered", "adaptive"):
        left = sorted(config.targets, reverse=True)
        for samples in COST_LADDER:
            if not left:
                break
            setting = Setting("cost", f"{mode} {samples}", samples=samples, mode=mode)
            records = run_tasks([(run_setting, (setting, seed, config)) for seed in range(config.seeds)],
                                lambda index, result: None)
            runs = [{"camera": r["rays"]["camera"], "rays": sum(r["rays"].values()), "cpu": r["cpu"],
                     "rmse": errors(r["image"], reference)["rmse"]} for r in records]
            rmse = float(np.mean([r["rmse"] for r in runs]))
            while left and rmse <= left[0]:
                rows.append(_cost(f"uniform {mode}" if mode == "jittered" else mode, left.pop(0), samples, runs))
        for target in left:  # not reached on the ladder
            rows.append({"target": target, "method": f"uniform {mode}" if mode == "jittered" else mode,
                         "samples": None, "runs": 0})
    for row in rows:
        if row["runs"]:
            progress(f"  cost to reach {row['target']:g}: {row['method']:<16} "
                     + (f"N={row['samples']:<4} " if row["samples"] else "       ")
                     + f"{row['camera_mean']:>10,.0f} camera rays (sd {row['camera_sd']:,.0f}), "
                       f"RMSE {row['rmse_mean']:.5f}, CPU {row['cpu_mean']:.3f} s")
        else:
            progress(f"  cost to reach {row['target']:g}: {row['method']:<16} not reached by {COST_LADDER[-1]} rays")
    return rows


def measure_savings(scene: Scene, config: BenchConfig) -> dict:
    """What the ray savings save at a size where tracing, not overhead, takes the time: rays (exact) and
    seconds (median and IQR of ``config.savings_runs`` runs each way, interleaved), and the largest pixel
    change."""
    width, height = config.savings_size
    compiled = compiled_for(scene)
    seconds: dict[str, list[float]] = {"all": [], "saved": []}
    cpu: dict[str, list[float]] = {"all": [], "saved": []}
    images, rays = {}, {}
    for _ in range(config.savings_runs):
        for key, savings in (("all", RaySavings.none()), ("saved", None)):
            cpu_started = time.process_time()
            result = render(compiled, width, height, backend=config.backend, savings=savings,
                            threads=config.threads)
            cpu[key].append(time.process_time() - cpu_started)
            seconds[key].append(result.seconds)
            images[key], rays[key] = np.clip(result.image, 0, 1), sum(result.rays.as_dict().values())
    quartiles = {k: np.percentile(v, [25, 50, 75]) for k, v in seconds.items()}
    cpu_quartiles = {k: np.percentile(v, [25, 50, 75]) for k, v in cpu.items()}
    return {"width": width, "height": height, "rays_all": rays["all"], "rays_saved": rays["all"] - rays["saved"],
            "seconds_all": float(quartiles["all"][1]), "seconds_with": float(quartiles["saved"][1]),
            "iqr_all": float(quartiles["all"][2] - quartiles["all"][0]),
            "iqr_with": float(quartiles["saved"][2] - quartiles["saved"][0]), "runs": config.savings_runs,
            "cpu_all": float(cpu_quartiles["all"][1]), "cpu_with": float(cpu_quartiles["saved"][1]),
            "cpu_iqr_all": float(cpu_quartiles["all"][2] - cpu_quartiles["all"][0]),
            "cpu_iqr_with": float(cpu_quartiles["saved"][2] - cpu_quartiles["saved"][0]),
            "max_change_8bit": float(np.abs(images["all"] - images["saved"]).max() * 255)}


class _SweepProgress:
    """The sweep's progress lines, as whole steps finish (the reference, each round of settings), in order
    whatever the order the tasks finish in."""

    def __init__(self, progress, parts: int, settings: int, rounds: int):
        self.progress, self.settings = progress, settings
        self.parts: list = [None] * parts
        self.left = [settings] * rounds
        self.reported = -1  # -1: not even the reference; k: rounds reported

    def arrived(self, index: int, result) -> None:
        if index < len(self.parts):
            self.parts[index] = result
        elif index - len(self.parts) < self.settings * len(self.left):
            self.left[(index - len(self.parts)) // self.settings] -= 1
        if self.reported < 0 and all(part is not None for part in self.parts):
            _, error, seconds = combine_reference(self.parts)
            self.progress(f"  reference: estimated RMSE {error:.2e} ({seconds:.1f} s)")
            self.reported = 0
        while 0 <= self.reported < len(self.left) and self.left[self.reported] == 0:
            self.reported += 1
            self.progress(f"  round {self.reported}/{len(self.left)} done")


def measure(scene: Scene, name: str, out_dir: Path, config: BenchConfig = BenchConfig(), progress=print,
            run_tasks: Optional[RunTasks] = None) -> dict:
    """Everything for one scene; writes DIR/NAME.csv, .json and .png and returns the summary.  ``run_tasks``
    runs the renders (default :func:`run_here`; tracer.distributed.SceneTasks on a cluster)."""
    out_dir.mkdir(parents=True, exist_ok=True)
    depth = scene.settings.max_recursion_depth
    progress(f"{name}: reference, {config.reference_samples} jittered rays per pixel at depth {depth}, "
             f"{config.width} x {config.height}")
    effects = live_effects(scene)
    settings = default_settings(depth, effects, config.sample_counts)
    timed_savings = any(s.group == "ray savings" for s in settings)
    # Every render of the sweep, in the order a single process runs them: the reference, the settings round
    # by round (interleaved: a change in the machine's load touches them all alike), the error targets, the
    # timed ray savings.
    parts = reference_parts(config)
    calls = [(reference_part, (config, *part)) for part in parts]
    calls += [(run_setting, (setting, seed, config)) for seed in range(config.seeds) for setting in settings]
    calls += [(target_render, (config, target, seed)) for target in config.targets for seed in range(config.seeds)]
    calls += [(measure_savings, (config,))] if timed_savings else []
    first_run, first_target = len(parts), len(parts) + config.seeds * len(settings)
    progress_lines = _SweepProgress(progress, len(parts), len(settings), config.seeds)
    results = (run_tasks or run_here(scene))(calls, progress_lines.arrived)
    reference, reference_error, reference_seconds = combine_reference(results[:len(parts)])
    runs: dict[Setting, list[dict]] = {s: [] for s in settings}
    deep_images: dict[int, np.ndarray] = {}
    for k, record in enumerate(results[first_run:first_target]):
        setting = settings[k % len(settings)]
        run = {**errors(record["image"], reference), **{key: record[key] for key in
                                                        ("compile", "trace", "cpu", "rays", "skipped")}}
        if setting.group == "recursion depth":  # pixel-centre rays: the same at every depth
            deep_images.setdefault(setting.depth, np.clip(record["image"], 0, 1))
        runs[setting].append(run)
    backend = results[first_run]["backend"]
    rows = [_summarise(s, runs[s]) for s in settings]
    bias = None
    if deep_images:
        for row, setting in zip(rows, settings):
            if setting.group == "recursion depth":
                row["depth_bias"] = errors(deep_images[setting.depth], deep_images[DEEP])["rmse"]
        bias = errors(deep_images[depth], deep_images[DEEP])["rmse"]
    trade = [r for r in rows if r["group"] in TRADE_GROUPS]
    for axis, key in (("rays", "pareto_rays"), ("cpu_median", "pareto_seconds")):
        front = pareto_front([r[axis] for r in trade], [r["rmse_mean"] for r in trade])
        for r, on in zip(trade, front):
            r[key] = bool(on)
    slopes = fitted_slopes(rows)
    target_results = results[first_target:first_target + len(config.targets) * config.seeds]
    target_runs = {target: [{"camera": t["result"].rays.camera, "rays": sum(t["result"].rays.as_dict().values()),
                             "cpu": t["cpu"], "rmse": errors(t["result"].image, reference)["rmse"],
                             "estimated": t["result"].error_estimate.rms}
                            for t in target_results[k * config.seeds:(k + 1) * config.seeds]]
                   for k, target in enumerate(config.targets)}
    targets = [target_row(target_results[k * config.seeds]["result"], target, reference)
               for k, target in enumerate(config.targets)]
    cost = cost_to_reach(scene, config, reference, run_tasks or run_here(scene), target_runs, progress)
    baseline = next(r for r in rows if r["group"] == "baseline")
    every = next((r for r in rows if r["group"] == "ray savings"), None)
    summary = {
        "scene": name, "width": config.width, "height": config.height, "seeds": config.seeds,
        "backend": backend,
        "reference": {"samples": config.reference_samples, "depth": depth, "estimated_rmse": reference_error,
                      "seconds": reference_seconds,
                      "smallest_reported_rmse": min(r["rmse_mean"] for r in rows if r["rmse_mean"] > 0)},
        "depth_bias": None if bias is None else {"depth": depth, "against": DEEP, "rmse": bias},
        "slopes": slopes, "targets": targets, "cost": cost, "rows": rows,
        "savings": None if every is None else {
            "rays_all": every["rays"], "rays_saved": every["rays"] - baseline["rays"],
            "skipped": baseline["skipped"], "timed": results[-1]},
    }
    for r in rows:
        progress(f"  {r['setting']:<20} rmse {r['rmse_mean']:.5f} ± {r['rmse_std']:.5f}  {r['rays']:>10} rays  "
                 f"{r['seconds_median']:.3f} s (IQR {r['seconds_iqr']:.3f}), CPU {r['cpu_median']:.3f} s"
                 + ("  pareto" if r["pareto_rays"] or r["pareto_seconds"] else ""))
    for mode, fit in slopes.items():
        progress(f"  slope {mode}: {fit['slope']:+.3f} ± {fit['stderr']:.3f}")
    if bias is not None:
        progress(f"  depth bias (depth {depth} against {DEEP}): RMSE {bias:.5f}")
    if summary["savings"]:
        t = summary["savings"]["timed"]
        progress(f"  savings at {t['width']} x {t['height']}: {t['rays_saved']} of {t['rays_all']} rays, "
                 f"{t['seconds_with']:.3f} s against {t['seconds_all']:.3f} s (CPU {t['cpu_with']:.3f} against "
                 f"{t['cpu_all']:.3f}), max change {t['max_change_8bit']:.2f}/255")
    for t in targets:
        progress(f"  target {t['target']:g}: estimated {t['estimated_rmse']:.5f}, measured {t['measured_rmse']:.5f}")
    _write_csv(rows, out_dir / f"{name}.csv")
    _write_json(summary, out_dir / f"{name}.json")
    _plot_scene(summary, out_dir / f"{name}.png")
    return summary


def _atomic_path(path: Path) -> Path:
    return path.with_name(f".{path.name}.tmp")


def _write_csv(rows: list[dict], path: Path) -> None:
    tmp = _atomic_path(path)
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=FIELDS, extrasaction="ignore")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: (f"{v:.6g}" if isinstance(v, float) else v) for k, v in r.items()})
    tmp.replace(path)


def _write_json(data: dict, path: Path) -> None:
    tmp = _atomic_path(path)
    tmp.write_text(json.dumps(data, indent=1, default=float))
    tmp.replace(path)


def _pyplot():
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def _save(fig, path: Path) -> None:
    tmp = path.with_name(f".{path.stem}.tmp.png")
    fig.savefig(tmp, dpi=100)
    tmp.replace(path)


def _plot_scene(summary: dict, path: Path) -> None:
    plt = _pyplot()
    rows = [r for r in summary["rows"] if r["group"] in TRADE_GROUPS]
    fig, axes = plt.subplots(1, 3, figsize=(16, 5))
    markers = dict(zip(TRADE_GROUPS, "oDs^v"))
    colors = {group: f"C{k}" for k, group in enumerate(TRADE_GROUPS)}  # the same in all three panels
    for ax, axis, key, spread in ((axes[0], "rays", "pareto_rays", None),
                                  (axes[1], "cpu_median", "pareto_seconds", "cpu_iqr")):
        for group in TRADE_GROUPS:
            pts = [r for r in rows if r["group"] == group]
            if not pts:
                continue
            ax.errorbar([r[axis] for r in pts], [r["rmse_mean"] for r in pts], yerr=[r["rmse_std"] for r in pts],
                        xerr=None if spread is None else [r[spread] / 2 for r in pts], marker=markers[group],
                        color=colors[group], linestyle="none", capsize=2, label=group)
        front = sorted((r for r in rows if r[key]), key=lambda r: r[axis])
        ax.step([r[axis] for r in front], [r["rmse_mean"] for r in front], where="post", color="k", alpha=0.5,
                label="Pareto front")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("rays" if axis == "rays" else "CPU seconds, all threads (median; bars: IQR)")
        ax.set_ylabel("RMSE (mean over seeds; bars: ±1 sd)")
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    ax = axes[2]
    for mode, fit in summary["slopes"].items():
        pts = [r for r in summary["rows"] if r["group"] == f"samples ({mode})"]
        n = np.array([r["samples"] for r in pts], float)
        color = colors[f"samples ({mode})"]
        ax.errorbar(n, [r["rmse_mean"] for r in pts], yerr=[r["rmse_std"] for r in pts], marker="o", capsize=2,
                    color=color, linestyle="none", label=f"{mode}: slope {fit['slope']:+.2f} ± {fit['stderr']:.2f}")
        ax.plot(n, np.exp(fit["intercept"]) * n ** fit["slope"], color=color, alpha=0.6)
    ref = summary["reference"]
    ax.axhline(ref["estimated_rmse"], color="grey", linestyle=":", label="reference's own estimated RMSE")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("samples per pixel")
    ax.set_ylabel("RMSE")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=7)
    fig.suptitle(f"{summary['scene']}: {summary['width']} x {summary['height']}, {summary['seeds']} seeds, "
                 f"reference {ref['samples']} rays/pixel")
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def plot_targets(summaries: list[dict], path: Path) -> None:
    """Estimated against measured error of the error-target renders: whole images, and pixels binned."""
    plt = _pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(11, 5))
    everything = []
    for s in summaries:
        pts = s["targets"]
        if not pts:
            continue
        line = axes[0].plot([t["estimated_rmse"] for t in pts], [t["measured_rmse"] for t in pts], "o-",
                            label=s["scene"])[0]
        axes[0].plot([t["target"] for t in pts], [t["measured_rmse"] for t in pts], "x", color=line.get_color())
        for t in (t for t in pts if t["bins"]):
            est, got = zip(*t["bins"])
            axes[1].plot(est, got, ".-", color=line.get_color(), alpha=0.6)
            everything += list(est) + list(got) + [t["target"]]
        everything += [t["estimated_rmse"] for t in pts] + [t["measured_rmse"] for t in pts]
    lo, hi = TARGET_BINS[0] / 2, max([TARGET_BINS[-1], *everything]) * 2
    for ax, title in ((axes[0], "whole image (o: estimate, x: target E)"), (axes[1], "pixels binned by estimate")):
        ax.plot([lo, hi], [lo, hi], "k--", alpha=0.5, label="measured = estimated")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlim(lo, hi)
        ax.set_ylim(lo, hi)
        ax.set_xlabel("estimated RMSE")
        ax.set_ylabel("measured RMSE (against the reference)")
        ax.set_title(title, fontsize=9)
        ax.grid(True, which="both", alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    _save(fig, path)
    plt.close(fig)


def _fmt(x: float, digits: int = 4) -> str:
    if abs(x) < 1e-12:  # the spread of a deterministic setting (rounding leaves ~1e-19)
        return "0"
    return f"{x:.{digits}f}" if x >= 10 ** -(digits - 1) else f"{x:.2e}"


def write_report(summaries: list[dict], path: Path) -> None:
    """The tables docs/accuracy.md quotes, as Markdown."""
    lines = []
    for s in summaries:
        ref = s["reference"]
        lines += [f"## {s['scene']}", "",
                  f"{s['width']} x {s['height']}, backend {s['backend']}, {s['seeds']} seeds per setting. Reference: "
                  f"{ref['samples']} rays/pixel at depth {ref['depth']}, its own estimated RMSE "
                  f"{ref['estimated_rmse']:.2e} ({ref['seconds']:.1f} s); smallest RMSE reported "
                  f"{ref['smallest_reported_rmse']:.2e}.", "",
                  "| setting | RMSE mean ± sd | rays | seconds median (IQR) | CPU s median (IQR) | compile / trace ms "
                  "| Pareto |",
                  "|---|---|---|---|---|---|---|"]
        for r in s["rows"]:
            pareto = "/".join(k for k, on in (("rays", r["pareto_rays"]), ("time", r["pareto_seconds"])) if on)
            bias = f" (depth bias {_fmt(r['depth_bias'])})" if r["depth_bias"] != "" else ""
            lines.append(f"| {r['setting']}{bias} | {_fmt(r['rmse_mean'])} ± {_fmt(r['rmse_std'])} | {r['rays']:,} | "
                         f"{r['seconds_median']:.3f} ({r['seconds_iqr']:.3f}) | {r['cpu_median']:.3f} "
                         f"({r['cpu_iqr']:.3f}) | {1000 * r['compile_median']:.1f} / "
                         f"{1000 * r['trace_median']:.1f} | {pareto} |")
        lines.append("")
        base = next(r for r in s["rows"] if r["group"] == "baseline")
        lines.append("Rays of the baseline per kind: " + ", ".join(f"{k} {base[f'rays_{k}']:,}" for k in RAY_KINDS)
                     + "; skipped: " + ", ".join(f"{k} {v:,.0f}" for k, v in base["skipped"].items()) + ".")
        if s["slopes"]:
            lines.append("Slopes of log RMSE against log samples (N ≥ 4): " + ", ".join(
                f"{m} {f['slope']:+.3f} ± {f['stderr']:.3f}" for m, f in s["slopes"].items()) + ".")
        if s["depth_bias"]:
            b = s["depth_bias"]
            lines.append(f"Depth bias: depth {b['depth']} against depth {b['against']}, RMSE {b['rmse']:.5f}.")
        if s["savings"]:
            v = s["savings"]
            t = v["timed"]
            lines.append(f"Ray savings: {v['rays_saved']:,} of {v['rays_all']:,} rays "
                         f"({100 * v['rays_saved'] / v['rays_all']:.1f} %) at this size; at {t['width']} x "
                         f"{t['height']}: {t['rays_saved']:,} of {t['rays_all']:,} rays; medians of {t['runs']} runs: "
                         f"{t['seconds_with']:.3f} s "
                         f"(IQR {t['iqr_with']:.3f}) against {t['seconds_all']:.3f} s (IQR {t['iqr_all']:.3f}) "
                         f"with every ray; CPU seconds (all threads) {t['cpu_with']:.3f} (IQR {t['cpu_iqr_with']:.3f}) "
                         f"against {t['cpu_all']:.3f} (IQR {t['cpu_iqr_all']:.3f}); largest pixel change "
                         f"{t['max_change_8bit']:.2f}/255.")
        if s["targets"]:
            lines += ["", "| target E | estimated RMSE | measured RMSE | 99th pct. pixel | rays/pixel | pixels at limit |",
                      "|---|---|---|---|---|---|"]
            lines += [f"| {t['target']:g} | {_fmt(t['estimated_rmse'])} | {_fmt(t['measured_rmse'])} | "
                      f"{_fmt(t['measured_p99'])} | {t['samples_mean']:.1f} | {t['pixels_at_limit']} |"
                      for t in s["targets"]]
        if s.get("cost"):
            lines += ["", "Cost to reach each target E (mean ± sd over the seeds; uniform and adaptive: the fewest "
                      "rays per pixel N whose mean RMSE is at most E):", "",
                      "| E | method | N | camera rays | all rays | CPU s | RMSE | camera rays / uniform's |",
                      "|---|---|---|---|---|---|---|---|"]
            for c in s["cost"]:
                if not c["runs"]:
                    lines.append(f"| {c['target']:g} | {c['method']} | > {COST_LADDER[-1]} | | | | | |")
                    continue
                uniform = next((u for u in s["cost"] if u["target"] == c["target"] and u["runs"]
                                and u["method"] == "uniform jittered"), None)
                ratio = f"{c['camera_mean'] / uniform['camera_mean']:.2f}" if uniform else ""
                lines.append(f"| {c['target']:g} | {c['method']} | {c['samples'] or ''} | "
                             f"{c['camera_mean']:,.0f} ± {c['camera_sd']:,.0f} | {c['rays_mean']:,.0f} ± "
                             f"{c['rays_sd']:,.0f} | {c['cpu_mean']:.3f} ± {c['cpu_sd']:.3f} | "
                             f"{_fmt(c['rmse_mean'])} ± {_fmt(c['rmse_sd'])} | {ratio} |")
            spans = [(c["target"], c["measured_over_estimated"]) for c in s["cost"]
                     if c.get("measured_over_estimated")]
            if spans:
                lines.append("")
                lines.append("Measured over estimated RMSE of the error target, lowest and highest over the seeds: "
                             + ", ".join(f"E = {e:g}: {lo:.2f}–{hi:.2f}" for e, (lo, hi) in spans) + ".")
        lines.append("")
    tmp = _atomic_path(path)
    tmp.write_text("\n".join(lines))
    tmp.replace(path)
