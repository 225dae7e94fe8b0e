"""scripts/render_sdl.py, the README's headless render, in the bpy module (and in `blender -b` when there
is one): an image of the requested size comes out; a missing scene, a bad size, a file with a problem
(imported strictly, as the CLI does, unless --lenient) and a missing output folder are each one `error:`
line and exit status 2, with no image written."""
from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from blender_binary import BLENDER, blender_numpy_path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "scripts" / "render_sdl.py"


def _bpy_module(*args):
    env = dict(os.environ, PYTHONPATH="")  # the script finds the checkout's add-on itself
    return subprocess.run([sys.executable, str(SCRIPT), *map(str, args)], capture_output=True, text=True,
                          env=env, cwd=ROOT, timeout=300)


def test_renders_a_scene_in_the_bpy_module(tmp_path):
    out = tmp_path / "csg.png"
    proc = _bpy_module(ROOT / "scenes" / "csg.sdl", out, 64, 48)
    assert proc.returncode == 0, proc.stdout[-2000:] + proc.stderr[-2000:]
    with Image.open(out) as image:
        assert image.size == (64, 48)
        pixels = np.asarray(image.convert("RGB"), dtype=float)
    assert pixels.std() > 5  # a picture, not a flat background


def test_a_missing_scene_is_one_line(tmp_path):
    proc = _bpy_module(tmp_path / "nope.sdl", tmp_path / "x.png")
    assert proc.returncode == 2
    assert "Traceback" not in proc.stderr
    assert [line for line in proc.stderr.splitlines() if line.startswith("error:")] == \
        [f"error: {tmp_path / 'nope.sdl'}: no such file"]
    assert not (tmp_path / "x.png").exists()


def _under_blender(tmp_path, *args):
    env = dict(os.environ, PYTHONPATH=blender_numpy_path(BLENDER, tmp_path))
    return subprocess.run([BLENDER, "-b", "--factory-startup", "--python", str(SCRIPT), "--", *map(str, args)],
                          capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)


def _typo_scene(tmp_path) -> Path:
    scene = tmp_path / "typo.sdl"
    scene.write_text("light 3 4 5 1 1 1\nshpere\ntranslate 2 0 0 sphere\n")
    return scene


BAD_RUNS = {  # name: (arguments after the scene and output, the error line with {scene} and {out} filled in)
    "letters for a size": (["abc", "48"], "error: size abc 48: WIDTH and HEIGHT must be whole numbers"),
    "a zero width": (["0", "48"], "error: size 0 48: WIDTH and HEIGHT must be at least 1"),
    "a typo in the file": (["8", "6"], "error: {scene}:2:1: unknown keyword, did you mean 'sphere'? "
                                       "(found 'shpere')"),
    "a missing folder": (["8", "6"], "error: {out}: folder '{out.parent}' does not exist"),
}


def _bad_run_arguments(tmp_path, name):
    scene = _typo_scene(tmp_path) if name == "a typo in the file" else ROOT / "scenes" / "lecture.sdl"
    out = tmp_path / ("missing" if name == "a missing folder" else "") / "x.png"
    extra, line = BAD_RUNS[name]
    return [scene, out, *extra], line.format(scene=scene, out=out), out


def _assert_one_error_line(proc, line, out):
    assert proc.returncode == 2, proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "Traceback" not in proc.stdout + proc.stderr
    assert [text for text in proc.stderr.splitlines() if text.startswith("error:")] == [line]
    assert not out.exists()
    if out.parent.name == "missing":
        assert not out.parent.exists()  # not made on the way (the CLI refuses too)


@pytest.mark.parametrize("name", BAD_RUNS)
def test_bad_input_is_one_line_in_the_bpy_module(tmp_path, name):
    args, line, out = _bad_run_arguments(tmp_path, name)
    _assert_one_error_line(_bpy_module(*args), line, out)


def test_lenient_imports_what_can_be_read(tmp_path):
    out = tmp_path / "x.png"
    proc = _bpy_module(_typo_scene(tmp_path), out, 8, 6, "--lenient")
    assert proc.returncode == 0 and out.is_file(), proc.stdout[-2000:] + proc.stderr[-2000:]
    assert "unknown keyword, did you mean 'sphere'?" in proc.stdout + proc.stderr  # reported as a warning


@pytest.mark.skipif(BLENDER is None, reason="no blender on PATH")
@pytest.mark.parametrize("name", BAD_RUNS)
def test_bad_input_is_one_line_under_blender(tmp_path, name):
    args, line, out = _bad_run_arguments(tmp_path, name)
    _assert_one_error_line(_under_blender(tmp_path, *args), line, out)


@pytest.mark.skipif(BLENDER is None, reason="no blender on PATH")
def test_renders_a_scene_under_blender(tmp_path):
    out = tmp_path / "lecture.png"
    env = dict(os.environ, PYTHONPATH=blender_numpy_path(BLENDER, tmp_path))
    proc = subprocess.run([BLENDER, "-b", "--factory-startup", "--python", str(SCRIPT), "--",
                           *map(str, (ROOT / "scenes" / "lecture.sdl", out, 40, 30))], capture_output=True,
                          text=True, cwd=ROOT, env=env, timeout=300)
    assert proc.returncode == 0 and out.is_file(), proc.stdout[-2000:] + proc.stderr[-2000:]
    with Image.open(out) as image:
        assert image.size == (40, 30)


@pytest.mark.skipif(BLENDER is None, reason="no blender on PATH")
def test_blender_without_numpy_is_told_how_to_get_it(tmp_path):
    if blender_numpy_path(BLENDER, tmp_path) == "":
        pytest.skip("this blender's Python has NumPy: the missing-NumPy message cannot be provoked here")
    out = tmp_path / "x.png"
    proc = subprocess.run([BLENDER, "-b", "--factory-startup", "--python", str(SCRIPT), "--",
                           str(ROOT / "scenes" / "lecture.sdl"), str(out), "8", "6"], capture_output=True,
                          text=True, cwd=ROOT, env=dict(os.environ, PYTHONPATH=""), timeout=300)
    _assert_one_error_line(proc, "error: the add-on cannot load in this Python: No module named 'numpy' "
                                 "(on Debian/Ubuntu: apt-get install python3-numpy)", out)
