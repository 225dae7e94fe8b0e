"""The accuracy benchmark measures what it says: errors shrink as settings get more accurate."""
from __future__ import annotations

import csv

import numpy as np
import pytest
from PIL import Image

from helpers import Camera, Light, rotation, scene_of, shape, translation
from tracer.accuracy import default_settings, errors, measure


def _scene():
    return scene_of(shape("plane", rotation(-90, 1, 0, 0), diffuse=(0.5, 0.5, 0.5)),
                    shape("sphere", translation(0, 1, 0), diffuse=(0.9, 0.2, 0.2), reflectivity=0.6),
                    shape("torus", translation(1.5, 0.3, 1) @ rotation(-90, 1, 0, 0), diffuse=(0.2, 0.8, 0.3)),
                    lights=[Light((3, 5, 4), (1, 1, 1))], camera=Camera((0, 2, 6), (0, 0.8, 0), (0, 1, 0), 45))


def test_accuracy_bench_writes_csv_and_plot(tmp_path):
    rows = measure(_scene(), "tiny", tmp_path, width=32, height=24, reference_samples=16, repeats=1,
                   progress=lambda _: None)
    with open(tmp_path / "tiny.csv") as handle:
        table = list(csv.DictReader(handle))
    assert [r["setting"] for r in table] == [r["setting"] for r in rows]
    by = {r["setting"]: r for r in rows}
    assert {"B=16", "1 ray/pixel", "regular 16", "depth 0", "newton 0", "ulps 1e+08"} <= set(by)
    assert by["B=16"]["rmse"] > by["B=4"]["rmse"] > by["1 ray/pixel"]["rmse"]
    assert by["regular 16"]["rmse"] < by["1 ray/pixel"]["rmse"]
    assert by["depth 0"]["rmse"] > by["1 ray/pixel"]["rmse"]  # the mirror sphere needs its reflections
    assert by["regular 16"]["rays"] > 10 * by["1 ray/pixel"]["rays"]
    with Image.open(tmp_path / "tiny.png") as plot:
        assert plot.size[0] > 300


def test_irrelevant_settings_are_not_swept():
    labels = {s.label for s in default_settings(3, frozenset({"shadows"}))}
    assert not any(l.startswith(("depth", "newton")) for l in labels)


def test_error_metrics():
    a = np.zeros((8, 8, 3))
    assert errors(a, a)["rmse"] == 0 and errors(a, a)["ssim"] == pytest.approx(1.0)
    b = a + 0.1
    assert errors(b, a)["rmse"] == pytest.approx(0.1) and errors(b, a)["psnr"] == pytest.approx(20.0)
