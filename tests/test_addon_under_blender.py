"""The bpy-module tests of view layers, passes and the Denoise node, material edits and the Properties
editor's panels, run again inside ``blender -b`` (Debian's Blender 3.4 here) by blender_scripts/run_tests.py."""
from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
from pathlib import Path

import pytest

from blender_binary import BLENDER

ROOT = Path(__file__).resolve().parent.parent
FILES = ["test_addon_passes.py", "test_addon_layers.py", "test_addon_materials.py", "test_addon_panels.py",
         "test_addon_updates.py", "test_addon_live.py"]


def _same_python() -> bool:
    probe = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-expr",
                            "import sys; print('PYVER', *sys.version_info[:2])"], capture_output=True, text=True,
                           timeout=120)
    return f"PYVER {sys.version_info[0]} {sys.version_info[1]}" in probe.stdout


@pytest.mark.skipif(BLENDER is None, reason="no blender on PATH")
def test_layers_passes_materials_and_panels_under_blender(tmp_path):
    if not _same_python():
        pytest.skip("Blender's Python is another version than this one: its packages cannot be shared")
    env = dict(os.environ, PYTHONPATH="", BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"),
               BLENDER_USER_CONFIG=str(tmp_path / "config"))
    proc = subprocess.run([BLENDER, "-b", "--factory-startup", "--python",
                           str(ROOT / "tests" / "blender_scripts" / "run_tests.py"), "--", str(ROOT),
                           sysconfig.get_paths()["purelib"], *(str(ROOT / "tests" / f) for f in FILES)],
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=600)
    assert "PYTEST-EXIT 0" in proc.stdout, proc.stdout[-6000:] + proc.stderr[-3000:]
    assert " passed" in proc.stdout and "skipped" not in proc.stdout
