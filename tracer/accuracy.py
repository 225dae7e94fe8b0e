"""``python -m tracer bench accuracy``: what accuracy costs in time.

For each scene: render a dense reference (many jittered samples, deep recursion), then one setting at a
time — block size, samples and sampling mode, recursion depth, solver tolerances — and measure seconds,
rays and the error against the reference (RMSE, and PSNR / SSIM from scikit-image).  Writes
``DIR/<scene>.csv`` and a plot of error against time, ``DIR/<scene>.png``.
"""
from __future__ import annotations

import contextlib
import csv
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Iterator

import numpy as np

from . import numerics
from .model import Scene
from .render import render

FIELDS = ("group", "setting", "backend", "seconds", "rays", "rmse", "psnr", "ssim")


@dataclass(frozen=True)
class Setting:
    group: str
    label: str
    block_size: int = 1
    samples: int = 1
    mode: str = "jittered"
    depth: int | None = None  # None: the scene's own maxRecursionDepth
    #: numerics.Tolerances.hit_ulps: scales the hit-error bounds behind ray offsets and CSG merging
    hit_ulps: float | None = None
    newton_steps: int | None = None  # torus root polishing


def default_settings(scene_depth: int, effects: frozenset = frozenset({"reflection", "shape:torus"})) -> list[Setting]:
    """The sweep; settings that cannot change a scene's image (recursion depth without mirrors or glass,
    torus polishing without a torus) are left out for that scene."""
    out = [Setting("block size", f"B={b}", block_size=b) for b in (16, 8, 4, 2)]
    out.append(Setting("baseline", "1 ray/pixel"))
    out += [Setting(f"samples ({mode})", f"{mode} {n}", samples=n, mode=mode)
            for mode in ("regular", "jittered", "adaptive") for n in (4, 16)]
    if effects & {"reflection", "refraction"}:
        out += [Setting("recursion depth", f"depth {d}", depth=d) for d in sorted({0, 1, 2, scene_depth, 6})]
    out += [Setting("hit error ulps", f"ulps {e:g}", hit_ulps=e) for e in (1, 4, 64, 1e4, 1e8)]
    if "shape:torus" in effects:
        out += [Setting("torus Newton steps", f"newton {n}", newton_steps=n) for n in (0, 1)]
    return out


@contextlib.contextmanager
def solver_tolerances(setting: Setting) -> Iterator[None]:
    """Temporarily use a setting's tolerances: numerics.TOLERANCES, which compile_scene copies into the
    scenes it compiles (and flatten hands to the C core)."""
    saved = numerics.TOLERANCES
    try:
        if setting.hit_ulps is not None:
            numerics.TOLERANCES = replace(numerics.TOLERANCES, hit_ulps=setting.hit_ulps)
        if setting.newton_steps is not None:
            numerics.TOLERANCES = replace(numerics.TOLERANCES, torus_newton_steps=setting.newton_steps)
        yield
    finally:
        numerics.TOLERANCES = saved


def _with_depth(scene: Scene, depth: int | None) -> Scene:
    if depth is None:
        return scene
    return replace(scene, settings=replace(scene.settings, max_recursion_depth=depth))


def errors(image: np.ndarray, reference: np.ndarray) -> dict[str, float]:
    from skimage.metrics import peak_signal_noise_ratio, structural_similarity

    a = np.clip(image, 0, 1).astype(np.float64)
    b = np.clip(reference, 0, 1).astype(np.float64)
    rmse = float(np.sqrt(np.mean((a - b) ** 2)))
    psnr = float("inf") if rmse == 0 else float(peak_signal_noise_ratio(b, a, data_range=1.0))
    ssim = float(structural_similarity(b, a, channel_axis=2, data_range=1.0))
    return {"rmse": rmse, "psnr": psnr, "ssim": ssim}


def measure(scene: Scene, name: str, out_dir: Path, width: int = 160, height: int = 120,
            reference_samples: int = 64, backend: str = "auto", repeats: int = 3, progress=print) -> list[dict]:
    """One row per setting.  Each setting is rendered ``repeats`` times and the fastest run is reported (the
    others measure the machine's noise, not the setting); the error is the same every time, as sampling is
    seeded."""
    out_dir.mkdir(parents=True, exist_ok=True)
    depth = scene.settings.max_recursion_depth
    reference_scene = _with_depth(scene, max(depth, 8))
    progress(f"{name}: reference, {reference_samples} jittered samples per pixel, depth {max(depth, 8)}")
    reference = render(reference_scene, width, height, samples=reference_samples, seed=12345, backend=backend).image
    rows = []
    from .compile import live_effects

    # One scene per recursion depth, so that each is compiled once (compile_scene keeps the result on it)
    # and the settings' times are the tracing's.
    by_depth: dict = {}
    for setting in default_settings(depth, live_effects(scene)):
        seconds = float("inf")
        setting_scene = by_depth.setdefault(setting.depth, _with_depth(scene, setting.depth))
        with solver_tolerances(setting):
            for _ in range(max(1, repeats)):
                started = time.perf_counter()
                result = render(setting_scene, width, height, block_size=setting.block_size,
                                samples=setting.samples, sampling_mode=setting.mode, backend=backend)
                seconds = min(seconds, time.perf_counter() - started)
        row = {"group": setting.group, "setting": setting.label, "backend": result.backend,
               "seconds": round(seconds, 4),
               "rays": int(sum(result.rays.as_dict().values())), **errors(result.image, reference)}
        rows.append(row)
        progress(f"  {setting.label:<22} {seconds:7.3f} s  {row['rays']:>9} rays  rmse {row['rmse']:.4f}  "
                 f"ssim {row['ssim']:.4f}")
    _write_csv(rows, out_dir / f"{name}.csv")
    _plot(rows, name, out_dir / f"{name}.png")
    return rows


def _write_csv(rows: list[dict], path: Path) -> None:
    tmp = path.with_suffix(".csv.tmp")
    with open(tmp, "w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=FIELDS)
        writer.writeheader()
        writer.writerows(rows)
    tmp.replace(path)


def _plot(rows: list[dict], name: str, path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7.5, 5))
    groups = list(dict.fromkeys(r["group"] for r in rows))
    markers = "osD^v<>Pp*"
    for i, group in enumerate(groups):
        pts = [r for r in rows if r["group"] == group]
        ax.plot([r["seconds"] for r in pts], [max(r["rmse"], 1e-6) for r in pts], marker=markers[i % len(markers)],
                linestyle="-" if len(pts) > 1 else "none", label=group)
        for r in pts:
            ax.annotate(r["setting"].split()[-1], (r["seconds"], max(r["rmse"], 1e-6)), fontsize=7,
                        xytext=(3, 3), textcoords="offset points")
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds")
    ax.set_ylabel("RMSE against the reference")
    ax.set_title(f"What accuracy costs: {name}")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    tmp = path.with_suffix(".tmp.png")
    fig.savefig(tmp, dpi=110)
    plt.close(fig)
    tmp.replace(path)
