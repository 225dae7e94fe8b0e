"""Every input that once crashed, hung or misreported, run through the command line as a user would.

Each scene in tests/fuzz/regressions/ (``*.sdl``, ``*.usda``; what they reference lies in ``data/``) starts
with comment lines saying what it once did (``class:``), optional extra options (``args:``) or a command other
than render (``command: convert``) and, where one answer is right, what must happen now (``expect: image``,
``expect: image warning`` — an image and at least one ``warning:`` line —, or ``expect: error WORD`` — the
error line contains WORD).  Without ``expect`` either kept promise is fine: an image, or one ``error:`` line
naming the file.  ``compare: backends`` marks a scene the C core and the NumPy path once rendered differently:
both must render it, within 1/255 of each other.
"""
from __future__ import annotations

import os
import shlex
import signal
import stat
import subprocess
import sys
import time
from pathlib import Path

import pytest

from harness import REPO, SANITIZED, run_cli

REGRESSIONS = Path(__file__).parent / "regressions"
CASES = sorted(p for p in REGRESSIONS.iterdir() if p.suffix in (".sdl", ".usda"))


def directives(path: Path) -> dict:
    found = {}
    for raw in path.read_bytes().splitlines()[:6]:
        line = raw.decode("utf-8", "replace").lstrip("!# ")
        key, sep, value = line.partition(":")
        if sep and key in ("class", "args", "expect", "command", "compare"):
            found[key] = value.strip()
    return found


@pytest.mark.parametrize("case", CASES, ids=[p.name for p in CASES])
def test_regression_case_keeps_the_promise(case, tmp_path):
    info = directives(case)
    if SANITIZED and (case.suffix == ".usda" or info.get("command") == "convert"):
        pytest.skip("under make sanitize: usd-core's C++ exceptions abort with ASan's runtime preloaded")
    assert "class" in info, f"{case.name} does not say which crash it covers"
    if info.get("command") == "convert":
        output = tmp_path / ("out.sdl" if case.suffix == ".usda" else "out.usda")
        command = ["convert", case, output]
    else:
        output = tmp_path / "out.png"
        command = ["render", case, "-o", output, "--width", 32, "--height", 24, "-q"]
    outcome = run_cli(command + shlex.split(info.get("args", "")), output=output,
                      names=[case.name, "regressions/", "--"])
    assert outcome.ok, outcome.describe()
    expect = info.get("expect", "").split()
    if expect:
        assert outcome.verdict == expect[0], outcome.describe()
    if expect[1:] == ["warning"]:
        assert "warning:" in outcome.stderr, outcome.describe()
    elif expect[1:]:
        assert expect[1] in outcome.stderr, outcome.describe()
    if outcome.verdict == "error":
        assert not output.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")], "a temporary file was left behind"


BACKEND_CASES = [p for p in CASES if directives(p).get("compare") == "backends"]


@pytest.mark.parametrize("case", BACKEND_CASES, ids=[p.name for p in BACKEND_CASES])
def test_regression_case_renders_alike_in_c_and_numpy(case, tmp_path):
    import numpy as np
    from PIL import Image

    images = []
    for backend in ("c", "numpy"):
        output = tmp_path / f"{backend}.png"
        outcome = run_cli(["render", case, "-o", output, "--width", 32, "--height", 24, "-q", "--backend", backend],
                          output=output, names=[case.name])
        assert outcome.verdict == "image", outcome.describe()
        images.append(np.asarray(Image.open(output).convert("RGB"), dtype=np.int16))
    worst = np.abs(images[0] - images[1]).max(axis=2)  # (1/255: fuzz.py's SAME_IMAGE)
    assert worst.max() <= 1, f"C and NumPy differ by up to {worst.max()}/255 at pixels {np.argwhere(worst > 1).tolist()}"


SPHERE = "camera 0 0 6  0 0 0  0 1 0  40\nlight 2 3 4  1 1 1\nsphere\n"


def _scene(tmp_path, text=SPHERE, name="scene.sdl") -> Path:
    path = tmp_path / name
    path.write_text(text)
    return path


def test_dev_zero_as_scene_is_refused(tmp_path):
    outcome = run_cli(["render", "/dev/zero", "-o", tmp_path / "o.png"], names=["/dev/zero"])
    assert outcome.verdict == "error", outcome.describe()
    assert "regular file" in outcome.stderr


def test_fifo_as_scene_or_pixmap_is_refused(tmp_path):
    fifo = tmp_path / "pipe.sdl"
    os.mkfifo(fifo)
    outcome = run_cli(["render", fifo, "-o", tmp_path / "o.png"], names=["pipe.sdl"])
    assert outcome.verdict == "error", outcome.describe()
    picture = tmp_path / "pipe.png"
    os.mkfifo(picture)
    scene = _scene(tmp_path, SPHERE + "makePixmap 1 pipe.png\npush texture 1 sphere pop\n")
    outcome = run_cli(["render", scene, "-o", tmp_path / "o.png", "--width", 8, "--height", 8],
                      names=["pipe.png"])
    assert outcome.verdict == "error", outcome.describe()


def test_unwritable_output_names_the_users_file_not_the_temporary(tmp_path):
    folder = tmp_path / "locked"
    folder.mkdir()
    folder.chmod(stat.S_IRUSR | stat.S_IXUSR)
    # root may write into any folder, but not create files in /sys
    target = folder / "out.png" if not os.access(folder, os.W_OK) else Path("/sys/out.png")
    try:
        outcome = run_cli(["render", _scene(tmp_path), "-o", target, "--width", 8, "--height", 8],
                          names=[str(target)])
    finally:
        folder.chmod(stat.S_IRWXU)
    assert outcome.verdict == "error", outcome.describe()
    assert "Permission denied" in outcome.stderr and ".tmp" not in outcome.stderr


def test_file_size_limit_gives_a_message_naming_the_output(tmp_path):
    # Under `ulimit -f` a write past the limit fails with EFBIG (SIGXFSZ is ignored by Python).
    out = tmp_path / "out.png"
    limit = subprocess.run(
        ["bash", "-c", f"ulimit -f 1; exec {shlex.quote(sys.executable)} -m tracer render "
                       f"{shlex.quote(str(_scene(tmp_path)))} -o {shlex.quote(str(out))} --width 400 --height 300 -q"],
        capture_output=True, text=True, cwd=REPO, timeout=120,
        env={**os.environ, "PYTHONPATH": str(REPO), "SDL_TRACER_THREADS": "2"})
    assert limit.returncode == 2, limit.stderr
    lines = limit.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: ") and "out.png" in lines[0], limit.stderr
    assert "Traceback" not in limit.stderr and ".tmp" not in limit.stderr
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_sigterm_cleans_up_like_sigint(tmp_path):
    out = tmp_path / "out.png"
    scene = _scene(tmp_path, "camera 0 0 6  0 0 0  0 1 0  40\nlight 2 3 4 1 1 1\nmaxRecursionDepth 20\n"
                             "reflectivity 0.9 minReflectivity 0\n" +
                   "".join(f"push translate {x * 0.3 - 3:g} 0 0 scale 0.2 0.2 0.2 sphere pop\n" for x in range(20)))
    proc = subprocess.Popen([sys.executable, "-m", "tracer", "render", str(scene), "-o", str(out),
                             "--width", "1600", "--height", "1200", "--backend", "numpy", "-q"],
                            stderr=subprocess.PIPE, text=True, cwd=REPO,
                            env={**os.environ, "PYTHONPATH": str(REPO)})
    time.sleep(4)
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 128 + signal.SIGTERM or proc.returncode == 130, err
    assert "Traceback" not in err
    assert not out.exists()
    assert not [p for p in tmp_path.iterdir() if p.name.endswith(".tmp")]


def test_a_write_error_on_standard_output_names_it_not_the_scene(tmp_path):
    scene = _scene(tmp_path)
    with open("/dev/full", "w") as full:
        run = subprocess.run([sys.executable, "-m", "tracer", "info", str(scene)], stdout=full, stderr=subprocess.PIPE,
                             text=True, cwd=REPO, env={**os.environ, "PYTHONPATH": str(REPO)}, timeout=120)
    assert run.returncode == 2
    assert run.stderr.strip().splitlines() == ["error: standard output: no space left on the device"], run.stderr


@pytest.mark.skipif(SANITIZED, reason="under make sanitize: usd-core's C++ exceptions abort with ASan's runtime")
@pytest.mark.parametrize("destination", ["out.usda", "out.sdl"])
def test_convert_past_the_file_size_limit_names_the_destination(tmp_path, destination):
    source = _scene(tmp_path, "".join(f"push translate {k} 0 0 sphere pop\n" for k in range(300)))
    out = tmp_path / destination
    run = subprocess.run(
        ["bash", "-c", f"ulimit -f 4; exec {shlex.quote(sys.executable)} -m tracer convert "
                       f"{shlex.quote(str(source))} {shlex.quote(str(out))}"],
        capture_output=True, text=True, cwd=REPO, timeout=120, env={**os.environ, "PYTHONPATH": str(REPO)})
    assert run.returncode == 2, run.stderr
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {out}:"), run.stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["scene.sdl"]


@pytest.mark.parametrize("name", ["-.png", "--x.png", "-o.png"])
def test_an_output_name_that_starts_with_a_dash_is_a_file_name(tmp_path, name):
    """Fuzz seed 2817008540 (generators.output_name): ``-o -.png`` was taken by argparse for an option and
    ended with its usage text, while any name the file system takes is a name a user may give."""
    scene = _scene(tmp_path)
    outcome = run_cli(["render", scene, "-o", name, "--width", 8, "--height", 6, "-q", "--target-error", "0.01"],
                      output=tmp_path / name, cwd=tmp_path)
    assert outcome.verdict == "image", outcome.describe()
    assert sorted(p.name for p in tmp_path.iterdir()) == sorted([scene.name, name])


def test_an_output_name_with_a_leading_space_is_shown_quoted(tmp_path):
    """Fuzz seed 2853008671 (generators.output_name): a name past the file system's limit that began with a
    space was shown as ``error:  name…``, where the space cannot be seen: such a name is shown in quotes."""
    name = " " + "a" * 300 + ".tif"
    outcome = run_cli(["render", _scene(tmp_path), "-o", name, "--width", 8, "--height", 6, "-q"],
                      names=[f"' {'a' * 40}"], cwd=tmp_path)
    assert outcome.verdict == "error", outcome.describe()
    assert "File name too long" in outcome.stderr
