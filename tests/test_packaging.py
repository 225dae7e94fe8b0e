"""The wheel (make wheel; CI): ``pip wheel .`` gives a platform wheel whose prebuilt C core loads and renders
with backend "c" in a fresh environment with no C compiler on PATH, and ``pip uninstall`` leaves nothing.

Marked ``packaging`` (building the wheel takes a minute), so plain ``pytest`` leaves it out."""
from __future__ import annotations

import os
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
pytestmark = pytest.mark.packaging

CHECK = """
import shutil, sys
import tracer, tracer.native as native
assert shutil.which("cc") is None and shutil.which("gcc") is None, "a compiler is on PATH"
assert tracer.__file__.startswith(sys.argv[1]), tracer.__file__
assert native.load_error is None, native.load_error
assert native._lib._name.startswith(sys.argv[1]), native._lib._name
result = tracer.render(tracer.parse_sdl("light 1 2 3 1 1 1 sphere"), 16, 12, backend="c")
assert result.backend == "c" and result.image.max() > 0
print("rendered with", native._lib._name)
"""


@pytest.fixture(scope="module")
def wheel(tmp_path_factory) -> Path:
    """$SDL_TRACER_WHEEL (make wheel has just built it), else a wheel built here from the checkout."""
    given = os.environ.get("SDL_TRACER_WHEEL")
    if given:
        return Path(given)
    out = tmp_path_factory.mktemp("wheel")
    subprocess.run([sys.executable, "-m", "pip", "wheel", "-q", "--no-deps", "-w", str(out), str(ROOT)],
                   check=True, timeout=900)
    return next(out.glob("sdl_raytracer-*.whl"))


def test_the_wheel_is_a_platform_wheel_with_the_prebuilt_core(wheel):
    assert "-py3-none-" in wheel.name and not wheel.name.endswith("-any.whl")
    library = "tracer/native/_core.dll" if sys.platform == "win32" else "tracer/native/_core.so"
    with zipfile.ZipFile(wheel) as zf:
        assert b"RT_SOURCE_HASH=prebuilt;" in zf.read(library)
        assert "tracer/native/contract.h" in zf.namelist()


@pytest.mark.skipif(sys.platform == "win32", reason="the PATH without a compiler is built for POSIX here")
def test_the_wheel_renders_with_the_c_core_without_a_compiler_and_uninstalls_cleanly(wheel, tmp_path):
    env_dir = tmp_path / "fresh"
    subprocess.run([sys.executable, "-m", "venv", "--without-pip", str(env_dir)], check=True)
    python = env_dir / "bin" / "python"
    site = subprocess.run([str(python), "-c", "import sysconfig; print(sysconfig.get_paths()['purelib'])"],
                          capture_output=True, text=True, check=True).stdout.strip()
    pip = [sys.executable, "-m", "pip", "--python", str(python)]
    subprocess.run([*pip, "install", "-q", "--no-deps", str(wheel)], check=True, timeout=300)
    # PATH: the fresh environment's bin only (python, no compiler); NumPy and Pillow come from this environment.
    env = {"PATH": str(python.parent), "HOME": str(tmp_path), "PYTHONPATH": sysconfig.get_paths()["purelib"]}
    run = subprocess.run([str(python), "-c", CHECK, site], capture_output=True, text=True, env=env, cwd=tmp_path,
                         timeout=300)
    assert run.returncode == 0, run.stderr
    assert "rendered with" in run.stdout
    subprocess.run([*pip, "uninstall", "-q", "-y", "sdl-raytracer"], check=True, timeout=300)
    left = [p.name for p in Path(site).iterdir() if "tracer" in p.name or "sdl" in p.name.lower()]
    assert left == []
    assert not (tmp_path / ".cache").exists()  # nothing was compiled
