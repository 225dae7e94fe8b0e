"""scripts/render_sdl.py, the README's headless render, in the bpy module (and in `blender -b` when there
is one): an image of the requested size comes out; a missing scene is one line and exit status 2."""
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
