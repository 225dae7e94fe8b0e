"""The add-on's bpy-free part (addon/pure/) and how the add-on reaches the tracer (addon/__init__.py).

* Every module of addon/pure/ imports, and a film traced by its block renderer is the tracer's own, in a
  process where Blender's modules (bpy, mathutils, gpu, ...) cannot be imported.
* In the checkout ``addon.tracer`` is the top-level ``tracer`` package itself, module for module (one copy:
  the tests compare the add-on's scenes with the tracer's classes).
"""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
PURE = ROOT / "addon" / "pure"
BLENDER_MODULES = ("bpy", "bpy_extras", "mathutils", "gpu", "gpu_extras", "bl_math", "bmesh", "aud", "idprop")

WITHOUT_BLENDER = r"""
import importlib, json, sys
blender = sys.argv[2].split(",")
for name in blender:
    sys.modules[name] = None  # "import bpy" now raises ImportError
sys.path.insert(0, sys.argv[1])
names = sys.argv[3].split(",")
for name in names:
    importlib.import_module("addon.pure." + name)

import numpy as np
import tracer
from addon.pure import blocks
from tracer.camera import CameraFrame
from tracer.compile import compile_scene
from tracer.tiles import camera_rays_for

compiled = compile_scene(tracer.load(sys.argv[1] + "/scenes/shapes.sdl"))
frame = CameraFrame.from_camera(compiled.scene.camera, 24 / 18)
film = blocks.BlockRenderer(compiled, camera_rays_for(frame, 24, 18), 24, 18, block_size=4, progressive=True,
                            tile=8, samples=2, seed=3)
film.run()
expected = tracer.render(compiled, 24, 18, block_size=4, progressive=True, samples=2, seed=3).image
print("RESULT " + json.dumps({
    "same": bool(np.array_equal(film.color, expected[::-1])),
    "blender_loaded": sorted(name for name in blender if sys.modules.get(name) is not None),
}))
"""


def test_the_pure_part_imports_and_traces_without_blender():
    names = sorted(p.stem for p in PURE.glob("*.py") if p.stem != "__init__")
    assert {"blocks", "convert", "passes", "primitives", "raycam"} <= set(names)
    proc = subprocess.run([sys.executable, "-c", WITHOUT_BLENDER, str(ROOT), ",".join(BLENDER_MODULES),
                           ",".join(names)], capture_output=True, text=True, timeout=300, cwd=ROOT,
                          env={"PATH": "/usr/bin:/bin", "PYTHONPATH": ""})
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stderr[-3000:]
    result = json.loads(lines[-1][len("RESULT "):])
    assert result == {"same": True, "blender_loaded": []}


def test_no_module_of_the_pure_part_imports_blender():
    """Also by reading them: a ``bpy`` import inside a function would pass the import test above."""
    import ast

    for path in PURE.glob("*.py"):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0:
                names = [node.module or ""]
            else:
                continue
            assert not [n for n in names if n.split(".")[0] in BLENDER_MODULES], f"{path.name}:{node.lineno}"


def test_the_addon_and_the_tests_share_one_tracer():
    import addon  # noqa: F401  (installs the alias)
    import tracer.model
    import tracer.sdl.parser
    from addon.tracer import model
    from addon.tracer.sdl import parser
    from addon.tracer.sdl.parser import load

    assert model is tracer.model and parser is tracer.sdl.parser and load is tracer.sdl.parser.load
    assert model.__spec__.name == "tracer.model"  # (the alias leaves the module's own spec alone)
    assert (ROOT / "addon" / "tracer").resolve() == (ROOT / "tracer").resolve()  # what editors follow
