"""Blender materials and worlds read by the add-on (addon/shader_nodes.py, by the rules of
addon/pure/whitted.py): the same materials, made through the Principled input names of each Blender (3.x:
Transmission, Specular, Emission; 4.x/5.0: Transmission Weight, Specular IOR Level, Emission Color), give the
same tracer materials in the bpy module and under ``blender -b`` (Debian's Blender 3.4 here).  The Blender
side is blender_scripts/shader_fields.py."""
from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from blender_binary import BLENDER, blender_numpy_path

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "tests" / "blender_scripts" / "shader_fields.py"
PICTURE = ROOT / "scenes" / "images" / "bricks.png"
BLACK = [0.0, 0.0, 0.0]
#: What each material must give (fields not named may be anything).
EXPECTED = {
    "glass": {"fresnel": "dielectric", "reflectivity": 1.0, "transparency": 1.0, "speed_of_light": 1 / 1.45,
              "diffuse": BLACK, "specular": BLACK},
    "mirror": {"fresnel": "metal", "reflectivity": 1.0, "fresnel_tint": [0.9, 0.6, 0.2], "diffuse": BLACK,
               "specular": BLACK},
    "rough red": {"diffuse": [0.768, 0.048, 0.048], "ambient": [0.768, 0.048, 0.048], "specular_exponent": 30.0,
                  "specular": [0.16] * 3, "reflectivity": 0.5, "fresnel": "metal", "fresnel_tint": [0.04] * 3},
    "low specular": {"specular": [0.08] * 3, "diffuse": [0.8 * 0.98] * 3},  # a reflectance of 0.02 either way
    "emitting": {"emissive": [4.0, 2.0, 1.0], "diffuse": BLACK},
    "half alpha": {"transparency": 0.5, "speed_of_light": 1.0, "fresnel": "constant"},
    "diffuse node": {"diffuse": [0.2, 0.4, 0.6], "specular": BLACK, "reflectivity": 0.0},
    "glossy node": {"fresnel": "metal", "fresnel_tint": [0.9] * 3, "reflectivity": 1.0, "diffuse": BLACK},
    "glass node": {"fresnel": "dielectric", "transparency": 1.0, "diffuse": BLACK},
    "emission node": {"emissive": [3.0] * 3, "diffuse": BLACK, "specular": BLACK},
    "mix": {"diffuse": [0.75, 0.0, 0.0], "transparency": 0.25, "reflectivity": 0.25, "fresnel": "dielectric"},
    "textured": {"image": str(PICTURE), "srgb": True, "diffuse": [0.96] * 3},
    "no nodes": {"diffuse": [0.288, 0.576, 0.864], "reflectivity": 0.3},
}


def _check(proc) -> None:
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout[-4000:] + proc.stderr[-4000:]
    result = json.loads(lines[-1][len("RESULT "):])
    materials, worlds = result["materials"], result["worlds"]
    # Blender 5.0 makes every material and world with nodes (use_nodes stays on): no "no nodes" case there
    without_nodes = int(result["blender"].split(".")[0]) < 5
    assert ("no nodes" in materials) == without_nodes and ("no nodes" in worlds) == without_nodes
    for name, wanted in EXPECTED.items():
        if name not in materials:
            continue
        got = materials[name]
        assert got["warnings"] == [], (name, got["warnings"])
        for key, value in wanted.items():
            assert got[key] == (pytest.approx(value, abs=1e-5) if not isinstance(value, (str, bool)) else value), \
                (result["blender"], name, key, got[key])
    assert worlds["background node"]["background"] == pytest.approx([0.1, 0.2, 0.4])  # colour x strength
    assert worlds["background node"]["ambient"] == worlds["background node"]["background"]
    if without_nodes:
        assert worlds["no nodes"]["background"] == pytest.approx([0.1, 0.2, 0.3])


def test_materials_in_the_bpy_module(tmp_path):
    proc = subprocess.run([sys.executable, str(SCRIPT), str(ROOT), str(PICTURE)], capture_output=True, text=True,
                          env=dict(os.environ, PYTHONPATH=""), cwd=tmp_path, timeout=300)
    _check(proc)


@pytest.mark.skipif(BLENDER is None, reason="no blender on PATH")
def test_materials_under_blender(tmp_path):
    env = dict(os.environ, PYTHONPATH=blender_numpy_path(BLENDER, tmp_path))
    proc = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(SCRIPT),
                           "--", str(ROOT), str(PICTURE)], capture_output=True, text=True, env=env, cwd=tmp_path,
                          timeout=300)
    _check(proc)
