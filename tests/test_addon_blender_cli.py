"""The add-on under a real ``blender -b`` (here Debian's Blender 3.4, through its legacy add-on path):
from the checkout, and installed from the zip that scripts/build_extension.py builds.  Skipped when no
``blender`` is on PATH.  The checks themselves are in blender_scripts/smoke.py."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent  # (no bpy needed here: these tests run Blender itself)

sys.path.insert(0, str(ROOT / "scripts"))
import build_extension  # noqa: E402
from blender_binary import BLENDER, blender_numpy_path  # noqa: E402

pytestmark = pytest.mark.skipif(BLENDER is None, reason="no blender on PATH")
SMOKE = ROOT / "tests" / "blender_scripts" / "smoke.py"


def _run(tmp_path, mode: str) -> dict:
    out = tmp_path / "out"
    out.mkdir()
    env = dict(os.environ, BLENDER_USER_SCRIPTS=str(tmp_path / "user_scripts"),
               BLENDER_USER_CONFIG=str(tmp_path / "user_config"))
    extra = blender_numpy_path(BLENDER, tmp_path)
    env["PYTHONPATH"] = extra
    cmd = [BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(SMOKE), "--",
           mode, str(ROOT), str(out)]
    proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=300, cwd=tmp_path)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout[-4000:] + proc.stderr[-4000:]
    return json.loads(lines[-1][len("RESULT "):])


def test_blender_cli_from_checkout(tmp_path):
    result = _run(tmp_path, "dev")
    assert result["tracer"] == "tracer"
    assert set(result["scenes"]) == {p.name for p in (ROOT / "scenes").glob("*.sdl")}
    assert result["max_difference"] < 1e-3 and result["rays"]["camera"] == 64 * 48


def test_blender_cli_installed_from_zip(tmp_path):
    zip_path = build_extension.build(tmp_path / "sdl_raytracer-legacy.zip", legacy=True)
    result = _run(tmp_path, f"zip:{zip_path}")
    assert result["tracer"] == "sdl_raytracer.tracer"  # its own vendored copy, not the checkout's
    assert result["max_difference"] < 1e-3
