"""The accuracy benchmark measures what it says (errors with spreads, times with IQRs, slopes, Pareto
fronts), and sampling to an error target stops where its estimate says and keeps its promise."""
from __future__ import annotations

import csv
import json
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

import tracer
from helpers import Camera, Light, rotation, scene_of, shape, translation
from tracer.accuracy import (TRADE_GROUPS, BenchConfig, default_settings, errors, fitted_slopes, measure, pareto_front,
                             plot_targets, reference_image, write_report)
from tracer.cli import main
from tracer.render import render
import tracer.target as target_sampling
from tracer.target import FIRST_BATCH, ErrorModel, centre_error, plan_halves, sample_to_error, standard_error

ROOT = Path(__file__).resolve().parent.parent
TINY = BenchConfig(width=24, height=18, reference_samples=64, seeds=3, sample_counts=(4, 16), targets=(0.05,),
                   savings_size=(24, 18), savings_runs=3)


def _scene():
    return scene_of(shape("plane", rotation(-90, 1, 0, 0), diffuse=(0.5, 0.5, 0.5)),
                    shape("sphere", translation(0, 1, 0), diffuse=(0.9, 0.2, 0.2), reflectivity=0.6),
                    shape("torus", translation(1.5, 0.3, 1) @ rotation(-90, 1, 0, 0), diffuse=(0.2, 0.8, 0.3)),
                    lights=[Light((3, 5, 4), (1, 1, 1))], camera=Camera((0, 2, 6), (0, 0.8, 0), (0, 1, 0), 45))


def test_accuracy_bench_writes_rows_with_spreads_slopes_and_fronts(tmp_path):
    summary = measure(_scene(), "tiny", tmp_path, TINY, progress=lambda _: None)
    with open(tmp_path / "tiny.csv") as handle:
        table = list(csv.DictReader(handle))
    rows = summary["rows"]
    assert [r["setting"] for r in table] == [r["setting"] for r in rows]
    by = {r["setting"]: r for r in rows}
    assert {"B=16", "1 ray/pixel", "regular 16", "jittered 4", "depth 0", "newton 0", "ulps 1e+08",
            "all rays traced"} <= set(by)
    assert all(r["runs"] == 3 for r in rows)
    # Seeds move jittered samples, not the regular grid: a spread only where there is randomness.
    assert by["jittered 16"]["rmse_std"] > 1e-6 and by["regular 16"]["rmse_std"] < 1e-12
    assert by["B=16"]["rmse_mean"] > by["B=4"]["rmse_mean"] > by["1 ray/pixel"]["rmse_mean"]
    assert by["regular 16"]["rmse_mean"] < by["1 ray/pixel"]["rmse_mean"]
    assert by["regular 16"]["rays"] > 10 * by["1 ray/pixel"]["rays"]
    assert by["regular 16"]["rays_camera"] == 16 * 24 * 18
    # Depth rows: their bias against depth 8 shrinks with depth and is 0 at 8.
    assert by["depth 0"]["depth_bias"] > by["depth 2"]["depth_bias"] >= by["depth 8"]["depth_bias"] == 0
    depth = _scene().settings.max_recursion_depth
    assert summary["depth_bias"]["depth"] == depth and summary["reference"]["depth"] == depth
    # Times: a median and an IQR, split into compiling and tracing.
    for r in rows:
        assert r["seconds_iqr"] >= 0 and r["compile_median"] > 0 and r["trace_median"] > 0
    # The cheapest and the most accurate trade-off settings are on the fronts.
    trade = [r for r in rows if r["group"] in TRADE_GROUPS]
    assert min(trade, key=lambda r: r["rays"])["pareto_rays"]
    assert min(trade, key=lambda r: r["cpu_median"])["pareto_seconds"]  # the time front is on CPU seconds
    best = min(trade, key=lambda r: r["rmse_mean"])
    assert best["pareto_rays"] and best["pareto_seconds"]
    assert not by["depth 0"]["pareto_rays"]  # only trade-off rows are ranked
    assert set(summary["slopes"]) == {"regular", "jittered", "adaptive"}
    assert summary["targets"][0]["measured_rmse"] > 0
    # The cost to reach the target: the target's own renders, and for uniform and adaptive sampling the
    # fewest rays per pixel whose mean RMSE over the seeds reaches it.
    cost = {c["method"]: c for c in summary["cost"]}
    assert set(cost) == {"target", "uniform jittered", "adaptive"}
    assert cost["target"]["runs"] == TINY.seeds and cost["target"]["camera_mean"] > 0
    uniform = cost["uniform jittered"]
    assert uniform["rmse_mean"] <= 0.05 and uniform["camera_mean"] == uniform["samples"] * 24 * 18
    timed = summary["savings"]["timed"]
    assert timed["rays_all"] > timed["rays_all"] - timed["rays_saved"] > 0 or timed["rays_saved"] == 0
    assert timed["max_change_8bit"] <= 0.5 and timed["seconds_all"] > 0 and timed["iqr_with"] >= 0
    assert json.loads((tmp_path / "tiny.json").read_text())["reference"]["samples"] == 64
    with Image.open(tmp_path / "tiny.png") as plot:
        assert plot.size[0] > 1000
    plot_targets([summary], tmp_path / "target_error.png")
    write_report([summary], tmp_path / "report.md")
    report = (tmp_path / "report.md").read_text()
    assert "| jittered 16 |" in report and "Slopes of log RMSE" in report and "| 0.05 |" in report
    assert "| 0.05 | uniform jittered |" in report and "Cost to reach each target" in report
    assert (tmp_path / "target_error.png").stat().st_size > 1000


def test_pareto_front_keeps_exactly_the_unbeaten_points():
    cost = [1, 2, 3, 4, 5]
    error = [5, 3, 4, 1, 1]
    assert pareto_front(cost, error).tolist() == [True, True, False, True, False]


def test_fitted_slope_recovers_a_power_law():
    rows = [{"group": "samples (jittered)", "samples": n, "rmse_mean": 0.3 * n ** -0.75} for n in (4, 16, 64, 256)]
    rows.append({"group": "samples (jittered)", "samples": 1, "rmse_mean": 1.0})  # N = 1 is not fitted
    fit = fitted_slopes(rows)["jittered"]
    assert fit["slope"] == pytest.approx(-0.75) and fit["stderr"] == pytest.approx(0, abs=1e-9)


def test_reference_error_estimate_shrinks_with_samples():
    scene = _scene()
    _, small, _ = reference_image(scene, BenchConfig(width=24, height=18, reference_samples=8))
    image, large, _ = reference_image(scene, BenchConfig(width=24, height=18, reference_samples=128))
    assert 0 < large < small
    assert image.shape == (18, 24, 3)


def test_irrelevant_settings_are_not_swept():
    labels = {s.label for s in default_settings(3, frozenset({"shadows"}))}
    assert not any(l.startswith(("depth", "newton")) for l in labels)


def test_error_metrics():
    a = np.zeros((8, 8, 3))
    assert errors(a, a)["rmse"] == 0 and errors(a, a)["ssim"] == pytest.approx(1.0)
    b = a + 0.1
    assert errors(b, a)["rmse"] == pytest.approx(0.1) and errors(b, a)["psnr"] == pytest.approx(20.0)


# ------------------------------------------------------------------------------------------- error targets

def test_standard_error_of_known_samples():
    samples = np.array([[0.0, 0, 0], [1, 0, 0], [2, 0, 0], [3, 0, 0]])
    got = standard_error(samples.sum(axis=0)[None], (samples ** 2).sum(axis=0)[None], np.array([4]))
    assert got[0] == pytest.approx(np.std([0, 1, 2, 3], ddof=1) / 2)


def test_sampling_stops_when_the_estimate_reaches_the_target():
    """Noise of known sigma: the standard error sigma / sqrt(n) falls below E at the first doubling of
    FIRST_BATCH past (sigma / E)^2 rays; the noise-free half of the image stops after the first batch,
    except its column next to the noisy half (a neighbour of uncertain pixels goes on with them)."""
    sigma, target, width, height = 0.1, 0.01, 6, 4
    rng = np.random.default_rng(5)

    def camera_rays(origins, directions):
        noisy = directions[:, 0] >= width / 2  # the right half is noisy
        return 0.5 + np.where(noisy, 1.0, 0.0)[:, None] * rng.normal(0, sigma, (len(origins), 3))

    def rays_for(rows, cols, dy, dx):
        return np.zeros((rows.size, 3)), np.c_[cols + dx, rows + dy, np.zeros(rows.size)]

    film, estimate = sample_to_error(camera_rays, rays_for, width, height, target, per_pixel=True)
    assert estimate.kind == "pixel"
    needed = FIRST_BATCH
    while sigma / np.sqrt(needed) > target * 0.8:  # the estimate scatters about sigma / sqrt(n)
        needed *= 2
    assert set(np.unique(estimate.samples[:, :2])) == {FIRST_BATCH}
    assert estimate.samples[:, 2:].min() >= needed // 2 and estimate.worst <= target
    assert np.abs(film - 0.5).max() < 5 * target
    assert estimate.rms == pytest.approx(np.sqrt(np.mean(estimate.per_pixel ** 2)))


def test_sampling_to_a_target_gives_the_same_answer_in_any_batch_size(monkeypatch):
    """The rays of a round go to the tracer in batches, and estimates and the film are made in pieces, to
    bound memory: neither may change a value (with at most 7 rays a call, each call traces one pixel)."""
    scene = tracer.load(ROOT / "scenes" / "glass.sdl")
    whole = render(scene, 24, 18, target_error=0.02, seed=3)
    monkeypatch.setattr(target_sampling, "MAX_RAYS_PER_CALL", 7)
    pieces = render(scene, 24, 18, target_error=0.02, seed=3)
    assert np.array_equal(whole.image, pieces.image)
    assert np.array_equal(whole.error_estimate.per_pixel, pieces.error_estimate.per_pixel)
    assert np.array_equal(whole.error_estimate.samples, pieces.error_estimate.samples)
    assert whole.error_estimate.samples.max() > 4  # refined pixels: more than the centre and a pilot


def test_centre_error_of_a_step_and_of_a_ramp():
    """A step of height h: both pixels beside it get h² / 12 (the centre ray's mean squared error when the
    step crosses the pixel at a random place); a linear ramp, which the centre ray gets right, gets 0."""
    step = np.zeros((5, 8, 3))
    step[:, 4:] = 0.6
    errors_of_step = centre_error(step)
    assert errors_of_step[:, 3:5] == pytest.approx(np.full((5, 2), 0.36 / 12))
    assert not errors_of_step[:, :3].any() and not errors_of_step[:, 5:].any()
    ramp = np.broadcast_to((np.arange(8) * 0.1)[None, :, None], (5, 8, 3))
    assert np.allclose(centre_error(ramp), 0.0)


def test_plan_meets_its_budget_with_fewer_rays_for_a_looser_one():
    rng = np.random.default_rng(2)
    errors = rng.exponential(1e-3, 500) * (rng.random(500) < 0.3)
    rays = {}
    for budget in (0.02, 0.005, 0.001):
        halves = plan_halves(errors, ErrorModel(), budget)
        refined = halves > 0
        predicted = np.sum(np.where(refined, errors / np.maximum(2.0 * halves, 1) ** target_sampling.ALPHA, errors))
        assert predicted <= budget
        assert not halves[errors == 0].any()  # no ray where the centre ray is exact
        rays[budget] = halves.sum()
    assert rays[0.02] < rays[0.005] < rays[0.001]


def _disc(width, height):
    """camera_rays and rays_for of a white disc on black over a width x height film (ray direction = film
    position), and each pixel's exact colour (the disc's area in it, from a 64 x 64 grid of points)."""
    centre, radius = np.array([width * 0.45, height * 0.55]), min(width, height) * 0.3

    def inside(x, y):
        return (x - centre[0]) ** 2 + (y - centre[1]) ** 2 < radius ** 2

    def camera_rays(origins, directions):
        return np.repeat(inside(directions[:, 0], directions[:, 1]).astype(float)[:, None], 3, axis=1)

    def rays_for(rows, cols, dy=0.5, dx=0.5):
        rows, cols = np.asarray(rows, float), np.asarray(cols, float)
        return np.zeros((rows.size, 3)), np.c_[cols + dx, rows + dy, np.zeros(rows.size)]

    grid = (np.arange(64) + 0.5) / 64
    rows, cols = np.meshgrid(np.arange(height), np.arange(width), indexing="ij")
    exact = inside(cols[..., None, None] + grid[None, None, None, :], rows[..., None, None] + grid[None, None, :, None])
    return camera_rays, rays_for, np.repeat(exact.mean(axis=(2, 3))[..., None], 3, axis=2)


@pytest.mark.parametrize("target", [0.02, 0.01])
def test_image_target_samples_only_the_edge_and_estimates_its_error(target):
    """The flat inside and outside of a disc take one ray a pixel (but the random pilot's pixels, which
    check that); the rays go to the pixels its edge crosses; the image's error against the exact coverage is at most the target and within [0.67, 1.5]
    of the estimate."""
    width, height = 48, 36
    camera_rays, rays_for, exact = _disc(width, height)
    film, estimate = sample_to_error(camera_rays, rays_for, width, height, target, seed=1)
    measured = np.sqrt(np.mean((np.clip(film, 0, 1) - exact) ** 2))
    assert estimate.kind == "image" and measured <= target
    assert 0.67 <= measured / estimate.rms <= 1.5
    edge = (exact[..., 0] > 0) & (exact[..., 0] < 1)
    far = ~ndimage_dilation(edge, 2)
    far_rays = estimate.samples[::-1][far]  # (samples: row 0 at the top; the film: at the bottom)
    pilot_rays = 1 + 2 * target_sampling.PILOT_HALF
    assert set(np.unique(far_rays)) <= {1, pilot_rays}
    assert np.mean(far_rays == pilot_rays) < 2 * target_sampling.PILOT_FRACTION
    assert estimate.samples[::-1][edge].mean() > 4


def ndimage_dilation(mask, steps):
    from scipy.ndimage import binary_dilation

    return binary_dilation(mask, iterations=steps)


@pytest.mark.parametrize("name", ["lecture", "glass"])
def test_target_error_is_met_with_fewer_rays_than_uniform_sampling(name):
    """At the accuracy bench's size, against a 512-ray reference: the target's image is within it, its
    estimate within [0.67, 1.5] of the measured error, and it traces at most half the camera rays of the
    fewest jittered rays per pixel that reach the same error (edges, where the rays go, are a smaller share
    of a bigger image: at 48 x 36 it is about 0.6)."""
    scene = tracer.load(ROOT / "scenes" / f"{name}.sdl")
    width, height, target = 96, 72, 0.01
    reference = np.mean([np.clip(render(scene, width, height, samples=256, seed=100 + k).image, 0, 1)
                         for k in range(2)], axis=0)
    result = render(scene, width, height, target_error=target, seed=3)
    measured = errors(result.image, reference)["rmse"]
    assert measured <= target and 0.67 <= measured / result.error_estimate.rms <= 1.5
    uniform = next(n for n in range(1, 65) if np.mean([errors(render(scene, width, height, samples=n,
                                                                      seed=s).image, reference)["rmse"]
                                                         for s in range(3)]) <= target)
    assert result.rays.camera <= 0.5 * uniform * width * height


def test_cli_target_error_reports_the_estimate(tmp_path, capsys):
    out = str(tmp_path / "l.png")
    assert main(["render", str(ROOT / "scenes" / "lecture.sdl"), "-o", out, "--width", "24", "--height", "18",
                 "--target-error", "0.02", "--stats"]) == 0
    captured = capsys.readouterr()
    stats = json.loads(captured.out)
    assert stats["error"]["target"] == 0.02 and stats["error"]["estimated_rmse"] <= 0.02
    assert stats["error"]["kind"] == "image" and "for the image's RMSE" in captured.err
    assert main(["render", str(ROOT / "scenes" / "lecture.sdl"), "-o", out, "--width", "24", "--height", "18",
                 "--target-error", "0.05", "--per-pixel", "--stats"]) == 0
    captured = capsys.readouterr()
    per_pixel = json.loads(captured.out)["error"]
    assert per_pixel["kind"] == "pixel" and per_pixel["worst_pixel"] <= 0.05 and "for every pixel" in captured.err
    assert main(["render", str(ROOT / "scenes" / "lecture.sdl"), "-o", out, "--width", "8", "--height", "6",
                 "--per-pixel"]) == 0
    assert "warning: --per-pixel only changes --target-error" in capsys.readouterr().err
    assert main(["render", str(ROOT / "scenes" / "lecture.sdl"), "-o", out, "--target-error", "nan"]) == 2
    assert "error: the target error" in capsys.readouterr().err
    assert main(["render", str(ROOT / "scenes" / "lecture.sdl"), "-o", out, "--target-error", "0.01",
                 "--scheduler", "local:1"]) == 2
    assert "error: --target-error cannot be combined with --scheduler" in capsys.readouterr().err


def test_cli_bench_writes_the_report_and_refuses_too_few_seeds(tmp_path, capsys):
    lecture = str(ROOT / "scenes" / "lecture.sdl")
    assert main(["bench", "accuracy", lecture, "-o", str(tmp_path), "--width", "12", "--height", "9",
                 "--reference-samples", "16", "--seeds", "3"]) == 0
    assert {"lecture.csv", "lecture.json", "lecture.png", "target_error.png", "report.md"} <= \
        {p.name for p in tmp_path.iterdir()}
    assert main(["bench", "accuracy", lecture, "-o", str(tmp_path), "--seeds", "2"]) == 2
    assert "error: --seeds must be at least 3" in capsys.readouterr().err
    assert main(["bench", "accuracy", lecture, "-o", str(tmp_path), "--width", "6", "--height", "6"]) == 2
    assert "error: the accuracy bench needs images of at least 7 x 7" in capsys.readouterr().err
