"""The colour rule of docs/blender.md: after importing an SDL file, F12's image (as displayed and saved,
through the scene's view transform as the importer left it) equals the tracer's PNG within 2/255 at every
pixel (the engine traces the imported SDL camera, not Blender's float32 copy), under
``blender -b`` (Debian's Blender 3.4 here) and in the bpy module; a scene made in Blender keeps Blender's
colour management.  The Blender side is blender_scripts/colour_rule.py."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest
from PIL import Image

import tracer
from addon import importer
from blender_scripts.addon_env import fresh, import_sdl
from blender_binary import BLENDER, blender_numpy_path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "tests" / "blender_scripts" / "colour_rule.py"


def _check(proc, out: Path) -> None:
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout[-4000:] + proc.stderr[-4000:]
    result = json.loads(lines[-1][len("RESULT "):])
    assert result["native_before"] in ("Filmic", "AgX") and result["native_after"] == result["native_before"]
    # An import into a scene with objects keeps its view unless asked; KEEP keeps an empty scene's too.
    assert result["kept_by_default"] == result["native_before"] and result["asked_for"] == "Raw"
    assert result["kept_when_asked"] == result["empty_before"] != "Raw"
    for name in ("lecture", "textures"):
        expected_path = out / f"{name}-tracer.png"
        subprocess.run([sys.executable, "-m", "tracer", "render", str(ROOT / "scenes" / f"{name}.sdl"), "-o",
                        str(expected_path), "--width", "64", "--height", "48"], check=True, cwd=ROOT)
        with Image.open(expected_path) as png:
            expected = np.asarray(png.convert("RGB"), dtype=int)
        with Image.open(out / f"{name}-blender.png") as png:
            shown = np.asarray(png.convert("RGB"), dtype=int)
        difference = np.abs(shown - expected)
        # Every pixel, edges included: an imported camera traces the SDL file's own camera, not Blender's
        # float32 copy of it, whose rays cross edges that pass within ~1e-7 of a pixel's centre.
        assert difference.max() <= 2, (name, result["view"][name], np.argwhere(difference.max(axis=2) > 2).tolist())
        assert np.median(difference) == 0


@pytest.mark.skipif(BLENDER is None, reason="no blender on PATH")
def test_imported_scene_shows_the_tracers_png_under_blender(tmp_path):
    env = dict(os.environ, PYTHONPATH=blender_numpy_path(BLENDER, tmp_path))
    proc = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(SCRIPT),
                           "--", str(ROOT), str(tmp_path)], capture_output=True, text=True, env=env, cwd=tmp_path,
                          timeout=300)
    _check(proc, tmp_path)


def test_imported_scene_shows_the_tracers_png_in_the_bpy_module(tmp_path):
    proc = subprocess.run([sys.executable, str(SCRIPT), str(ROOT), str(tmp_path)], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=""), cwd=tmp_path, timeout=300)
    _check(proc, tmp_path)


def test_a_failed_import_gives_the_colour_management_back(monkeypatch):
    fresh()
    view = bpy.context.scene.view_settings
    view.view_transform, view.exposure = "Standard", 0.5

    def broken(matrix):
        raise RuntimeError("simulated failure")

    monkeypatch.setattr(importer, "flat", broken)  # fails after the view settings were set
    with pytest.raises(RuntimeError, match="simulated failure"):
        bpy.ops.import_scene.sdl(filepath=str(ROOT / "scenes" / "lecture.sdl"))
    assert (view.view_transform, view.exposure) == ("Standard", 0.5)
    monkeypatch.undo()
    import_sdl(ROOT / "scenes" / "lecture.sdl")
    assert (view.view_transform, view.look, view.exposure, view.gamma) == ("Raw", "None", 0.0, 1.0)
