"""What users install: the wheel and the Blender extension zips.

* ``pip wheel .`` gives a platform wheel whose prebuilt C core loads and renders with backend "c" in a fresh
  environment with no C compiler on PATH, and ``pip uninstall`` leaves nothing;
* the linux-x64 extension zip renders with its prebuilt core in Blender (the bpy module) with no compiler on
  PATH; the windows-x64 core passes its smoke test under Wine;
* zips and their members have mode 0644.

The tests that build something are marked ``packaging`` (a minute or two): ``make wheel`` and CI run them,
plain ``pytest`` leaves them out."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import sysconfig
import zipfile
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "scripts"))
import build_extension  # noqa: E402

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


@pytest.mark.packaging
def test_the_wheel_is_a_platform_wheel_with_the_prebuilt_core(wheel):
    assert "-py3-none-" in wheel.name and not wheel.name.endswith("-any.whl")
    library = "tracer/native/_core.dll" if sys.platform == "win32" else "tracer/native/_core.so"
    with zipfile.ZipFile(wheel) as zf:
        assert b"RT_SOURCE_HASH=prebuilt;" in zf.read(library)
        assert "tracer/native/contract.h" in zf.namelist()


@pytest.mark.packaging
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
    assert not (tmp_path / ".cache" / "sdl-tracer").exists()  # nothing was compiled


def test_zips_and_their_files_have_mode_0644(tmp_path):
    old = os.umask(0o077)
    try:
        zip_path = build_extension.build(tmp_path / "ext.zip")
    finally:
        os.umask(old)
    assert zip_path.stat().st_mode & 0o777 == 0o644
    with zipfile.ZipFile(zip_path) as zf:
        modes = {(info.external_attr >> 16) & 0o777 for info in zf.infolist()}
    assert modes == {0o644}


INSTALL_ZIP = ROOT / "tests" / "blender_scripts" / "install_zip.py"


@pytest.mark.skipif(shutil.which("cc") is None, reason="no C compiler on PATH")
def test_the_smoke_harness_builds_against_this_contract_and_passes_with_the_checkouts_core(tmp_path):
    """scripts/smoke_core.c is compiled with -Werror against the generated contract.h (in seconds, unlike the
    packaging tests below), so a contract change that leaves it behind fails here, not in make extension."""
    import tracer.native as native

    if native.load_error is not None:
        pytest.skip(f"the C core is not built here: {native.load_error}")
    (tmp_path / "extension-linux-x64").mkdir()  # where smoke_test puts its harness
    assert build_extension.smoke_test("linux-x64", Path(native._lib._name), tmp_path) == "passed"


@pytest.mark.packaging
@pytest.mark.skipif(build_extension.can_build("linux-x64") is not None,
                    reason=f"cannot build the linux-x64 core here: {build_extension.can_build('linux-x64')}")
def test_linux_zip_renders_with_its_prebuilt_core_in_blender_without_a_compiler(tmp_path):
    library = build_extension.build_core("linux-x64", tmp_path / "build")
    assert build_extension.smoke_test("linux-x64", library, tmp_path / "build") == "passed"
    zip_path = build_extension.build(tmp_path / "linux.zip", platform="linux-x64", libraries=[library])
    with zipfile.ZipFile(zip_path) as zf:
        assert 'platforms = ["linux-x64"]' in zf.read("blender_manifest.toml").decode()
    no_compiler = tmp_path / "bin"
    no_compiler.mkdir()
    env = dict(os.environ, PATH=str(no_compiler), HOME=str(tmp_path), BLENDER_USER_EXTENSIONS=str(tmp_path / "ext"),
               BLENDER_USER_CONFIG=str(tmp_path / "cfg"), BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"),
               PYTHONPATH="")
    env.pop("CC", None)
    env.pop("SDL_TRACER_LIBRARY", None)
    proc = subprocess.run([sys.executable, str(INSTALL_ZIP), str(zip_path), str(ROOT / "scenes" / "csg.sdl"),
                           str(tmp_path / "render.png")], capture_output=True, text=True, env=env, timeout=300,
                          cwd=tmp_path)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout[-3000:] + proc.stderr[-3000:]
    result = json.loads(lines[-1][len("RESULT "):])
    assert result["load_error"] is None and result["stats"]["backend"] == "c"
    assert result["library"].startswith(str(tmp_path / "ext"))  # the zip's own core, not a compiled one
    assert not (tmp_path / ".cache" / "sdl-tracer").exists()


@pytest.mark.packaging
@pytest.mark.skipif(build_extension.can_build("windows-x64") is not None,
                    reason=f"cannot build the windows-x64 core here: {build_extension.can_build('windows-x64')}")
def test_windows_core_cross_compiles_and_passes_its_smoke_test(tmp_path):
    library = build_extension.build_core("windows-x64", tmp_path / "build")
    assert library.name == "_core.dll"
    outcome = build_extension.smoke_test("windows-x64", library, tmp_path / "build")
    if shutil.which("wine") or shutil.which("wine64"):
        assert outcome == "passed under Wine"
    zip_path = build_extension.build(tmp_path / "windows.zip", platform="windows-x64", libraries=[library])
    with zipfile.ZipFile(zip_path) as zf:
        assert "tracer/native/_core.dll" in zf.namelist()
        assert 'platforms = ["windows-x64"]' in zf.read("blender_manifest.toml").decode()
