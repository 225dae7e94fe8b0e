"""The command line as a user meets it: images out, one-line errors, exit status 2, no tracebacks."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

ROOT = Path(__file__).parent.parent


def run(*args, cwd=None):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "tracer", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, env=env, timeout=300)


def test_render_writes_image_and_stats(tmp_path):
    out = tmp_path / "lecture.png"
    proc = run("render", ROOT / "scenes" / "lecture.sdl", "-o", out, "--width", 64, "--height", 48, "--stats")
    assert proc.returncode == 0, proc.stderr
    stats = json.loads(proc.stdout)
    assert stats["rays"]["camera"] == 64 * 48
    assert set(stats["rays"]) == {"camera", "shadow", "reflection", "refraction"}
    assert stats["rays"]["reflection"] == 0 and stats["rays"]["shadow"] > 0
    assert stats["backend"] in ("c", "numpy") and stats["seconds"] > 0
    with Image.open(out) as image:
        assert image.size == (64, 48)
    assert [p.name for p in tmp_path.iterdir()] == ["lecture.png"]  # no temporary left behind


def test_block_size_option(tmp_path):
    out = tmp_path / "blocky.png"
    proc = run("render", ROOT / "scenes" / "csg.sdl", "-o", out, "--width", 32, "--height", 24,
               "--block-size", 8, "--stats")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["rays"]["camera"] == 4 * 3


def _assert_one_line_error(proc, *fragments):
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "Traceback" not in proc.stderr
    for fragment in fragments:
        assert fragment in lines[0]


def test_broken_file_names_file_line_and_token(tmp_path):
    scene = tmp_path / "broken.sdl"
    scene.write_text("light 1 2 3 1 1 1\nsphere\ntranslate 1 2 sphere\n")
    proc = run("render", scene, "-o", tmp_path / "x.png")
    _assert_one_line_error(proc, f"{scene}:3:", "'sphere'")
    assert not (tmp_path / "x.png").exists()


MESSY = "light 1 2 3 1 1 1\nsphre\npop\nmesh missing.3vn\nsphere\n"


def test_messy_file_stops_by_default_and_renders_with_lenient(tmp_path):
    scene = tmp_path / "messy.sdl"
    scene.write_text(MESSY)
    _assert_one_line_error(run("render", scene, "-o", tmp_path / "x.png"), "messy.sdl:2:1", "sphere")
    proc = run("render", scene, "-o", tmp_path / "x.png", "--lenient", "--width", 16, "--height", 12)
    assert proc.returncode == 0
    warnings = [l for l in proc.stderr.splitlines() if l.startswith("warning: ")]
    assert len(warnings) == 3
    assert any("messy.sdl:2:1" in w for w in warnings)
    assert any("messy.sdl:3:1" in w and "pop" in w for w in warnings)
    assert any("messy.sdl:4" in w and "missing.3vn" in w for w in warnings)
    assert (tmp_path / "x.png").exists()


@pytest.mark.parametrize("args, fragment", [
    (("render", "no-such-scene.sdl", "-o", "x.png"), "no-such-scene.sdl"),
    (("render", "scenes/lecture.sdl", "-o", "/no/such/folder/x.png"), "/no/such/folder"),
    (("render", "scenes/lecture.sdl", "-o", "x.png", "--width", "100000"), "width"),
    (("render", "scenes/lecture.sdl", "-o", "x.unknown"), ".unknown"),
    (("render", "scenes/lecture.sdl", "-o", "x.png", "--block-size", "0"), "block size"),
])
def test_bad_requests_get_one_line(args, fragment):
    _assert_one_line_error(run(*args), fragment)


def test_info_lists_objects_lights_and_effects():
    proc = run("info", ROOT / "scenes" / "glass.sdl")
    assert proc.returncode == 0, proc.stderr
    assert "objects: 7" in proc.stdout and "lights: 2" in proc.stdout
    effects = proc.stdout.split("live effects:")[1]
    for effect in ("shadows", "reflection", "refraction", "csg"):
        assert effect in effects
    data = json.loads(run("info", ROOT / "scenes" / "jack.sdl", "--json").stdout)
    assert data["camera"]["viewAngle"] == 40
    assert "reflection" not in data["effects"] and "shadows" in data["effects"]
    assert sum(1 for o in data["objects"] if "jack" in o.get("groups", [])) == 20
