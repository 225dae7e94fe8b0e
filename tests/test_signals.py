"""SIGINT, SIGTERM and SIGKILL at random moments of a run, imports included: the run ends within half a second
with the status a shell reports for the signal, and the user's folder holds their old output and nothing
else (tracer.signals, tracer.atomic, tracer/native/interrupt.h).  And the same promise in-process: a cancel
is heard inside the C core's ray tree, not only between tiles."""
from __future__ import annotations

import os
import random
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from tracer.errors import RenderCancelled
from tracer.model import Camera, Light, Material, Scene, Settings, Shape
from tracer.render import render
from tracer.transforms import scaling

ROOT = Path(__file__).resolve().parents[1]
#: How soon after a signal a run must have ended (the C watchdog acts after 0.3 s; exiting takes the rest).
HEARD_WITHIN = 0.5
OLD = b"the old output"
#: The earliest moment a signal is sent: before it Python itself is starting, not the tracer (a SIGINT then
#: is CPython's own KeyboardInterrupt).
EARLIEST = 0.1


def _env():
    return {**os.environ, "PYTHONPATH": str(ROOT), "SDL_TRACER_THREADS": "2"}


def _glass_scene(folder: Path) -> Path:
    """A scene whose render at 160 x 120 takes a second or two: nested glass, the ray tree cut by its budget."""
    path = folder / "glass.sdl"
    path.write_text("camera 0 0 6  0 0 0  0 1 0  40\nlight 2 3 4  1 1 1\n"
                    "maxRecursionDepth 64 minReflectivity 0 minTransparency 0\n"
                    "transparency 0.9 reflectivity 0.9 speedOfLight 0.7\nsphere\npush scale 0.5 0.5 0.5 sphere pop\n")
    return path


@pytest.fixture(scope="module")
def stage(tmp_path_factory) -> Path:
    """The glass scene as a USD stage: its runs import usd-core too."""
    from tracer.sdl.parser import load
    from tracer.usd import save_usd

    folder = tmp_path_factory.mktemp("stage")
    path = folder / "glass.usda"
    save_usd(load(_glass_scene(folder)), path)
    return path


def _run_and_signal(scene: Path, output: Path, signum: int, after: float, size: tuple[int, int] = (160, 120)):
    proc = subprocess.Popen([sys.executable, "-m", "tracer", "render", str(scene), "-o", str(output), "--width",
                             str(size[0]), "--height", str(size[1]), "-q"], stderr=subprocess.PIPE, cwd=ROOT,
                            env=_env())
    time.sleep(after)
    sent = time.monotonic()
    proc.send_signal(signum)
    _, err = proc.communicate(timeout=60)
    return proc.returncode, time.monotonic() - sent, err.decode("utf-8", "replace")


def _in_python_itself(err: str) -> bool:
    """Whether a run's traceback is CPython's own, from a SIGINT that came while the interpreter was starting,
    before the package's first line (no frame of the tracer in it): no program can hear a signal then."""
    return "Traceback" in err and "KeyboardInterrupt" in err and f"{os.sep}tracer{os.sep}" not in err


def _machine_latency() -> float:
    """How long this machine takes, now, from a SIGTERM to the end of a busy Python process that ends on it
    in a Python handler (as the tracer does: it must be given a core, run the handler and tear down): the
    share of a run's ending that is the machine's load, not the tracer.  (A timed bound on a shared machine
    must leave this out, or it measures the neighbours; a process dying of the default action is never
    scheduled at all, so it would measure nothing.)"""
    proc = subprocess.Popen([sys.executable, "-c", "import signal, sys\n"
                             "signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))\n"
                             "sys.stdout.write('up\\n'); sys.stdout.flush()\n"
                             "while True: sum(range(1000))\n"], stdout=subprocess.PIPE)
    proc.stdout.readline()
    sent = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    proc.wait(timeout=60)
    return time.monotonic() - sent


def _python_start() -> float:
    """How long this machine takes, now, to start a Python process that loads runpy (what ``python -m`` does
    before the package's first line) and ends."""
    started = time.monotonic()
    subprocess.run([sys.executable, "-c", "import runpy"], check=True, env=_env())
    return time.monotonic() - started


def _duration(scene: Path, folder: Path) -> float:
    started = time.monotonic()
    subprocess.run([sys.executable, "-m", "tracer", "render", str(scene), "-o", str(folder / "full.png"), "--width",
                    "160", "--height", "120", "-q"], check=True, cwd=ROOT, env=_env(), capture_output=True)
    return time.monotonic() - started


@pytest.mark.parametrize("kind", ["sdl", "usd"])
def test_sigint_and_sigterm_at_random_moments_end_the_run_at_once_and_keep_the_old_output(tmp_path, stage, kind):
    scene = _glass_scene(tmp_path) if kind == "sdl" else stage
    span = _duration(scene, tmp_path)
    (tmp_path / "full.png").unlink()
    rng = random.Random(2026 + len(kind))
    folder = tmp_path / "out"
    folder.mkdir()
    output = folder / "image.png"
    for k in range(8):
        output.write_bytes(OLD)
        signum = (signal.SIGINT, signal.SIGTERM)[k % 2]
        status, took, err = _run_and_signal(scene, output, signum, rng.uniform(EARLIEST, span))
        leftovers = sorted(p.name for p in folder.iterdir() if p.name != "image.png")
        assert leftovers == [], leftovers
        if _in_python_itself(err):  # (a loaded machine can take more than EARLIEST to start Python)
            continue
        assert "Traceback" not in err, err
        if status == 0:  # it had finished: the new image, whole
            assert output.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
            continue
        assert status in (128 + signum, -signum), (status, err)
        latency = _machine_latency()
        assert took <= HEARD_WITHIN + latency, \
            f"{signal.Signals(signum).name} heard after {took:.2f} s (the machine's own latency: {latency:.2f} s)"
        assert output.read_bytes() == OLD
        assert err.strip().splitlines()[-1:] == ["interrupted"], err


def test_signals_while_the_modules_load_end_the_run_at_once(tmp_path, stage):
    """The first second and a half of a USD render after Python has started, in steps of 0.1 s: the tracer,
    NumPy, Pillow, the C core and usd-core loading (a stretch random moments seldom hit).  Each signal ends the
    run within half a second with 130 or 143, one "interrupted" line and the old output as it was.  (Before
    the package's first line, a SIGINT is CPython's own KeyboardInterrupt: the moments start when a bare
    interpreter, measured each time, has started and loaded runpy, as ``python -m`` does.)"""
    folder = tmp_path / "out"
    folder.mkdir()
    output = folder / "image.png"
    skipped = finished = 0
    for k in range(15):
        output.write_bytes(OLD)
        signum = (signal.SIGINT, signal.SIGTERM)[k % 2]
        at = _python_start() + 0.1 * k
        # (480 x 360: the render outlasts the moments, ~0.8 s after the start at 160 x 120 on a quiet machine)
        status, took, err = _run_and_signal(stage, output, signum, at, size=(480, 360))
        assert sorted(p.name for p in folder.iterdir()) == ["image.png"]
        if status == 0:  # (a quicker machine had finished the render before this moment: the new image, whole)
            assert output.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n" and "Traceback" not in err, err
            finished += 1
            continue
        assert output.read_bytes() == OLD
        if _in_python_itself(err):  # (the machine took longer than measured to start Python this time)
            skipped += 1
            continue
        assert "Traceback" not in err, err
        assert status in (128 + signum, -signum), (k, status, err)
        latency = _machine_latency()
        assert took <= HEARD_WITHIN + latency, \
            f"{signal.Signals(signum).name} at {at:.2f} s heard after {took:.2f} s (machine: {latency:.2f} s)"
        if status == 128 + signum:
            assert err.strip().splitlines()[-1:] == ["interrupted"], err
    assert skipped <= 2 and 15 - finished - skipped >= 5, (finished, skipped)  # (most moments were heard)


def test_sigkill_at_random_moments_leaves_only_the_old_output(tmp_path):
    scene = _glass_scene(tmp_path)
    span = _duration(scene, tmp_path)
    (tmp_path / "full.png").unlink()
    rng = random.Random(9)
    folder = tmp_path / "out"
    folder.mkdir()
    output = folder / "image.png"
    for _ in range(6):
        output.write_bytes(OLD)
        _run_and_signal(scene, output, signal.SIGKILL, rng.uniform(0.0, span))
        assert sorted(p.name for p in folder.iterdir()) == ["image.png"]
        # (SIGKILL cannot be put off: one that comes after the image was committed finds it whole)
        data = output.read_bytes()
        assert data == OLD or (data.startswith(b"\x89PNG\r\n\x1a\n") and data.endswith(b"IEND\xaeB`\x82"))


def test_a_signal_while_usd_core_loads_is_acted_on_once_it_has_loaded(tmp_path):
    """usd-core's module loader swallows a KeyboardInterrupt and goes on: the signal is held until it is done."""
    code = ("import os, signal, sys\n"
            "from tracer import signals\n"
            "with signals.working():\n"
            "    try:\n"
            "        with signals.shielded():\n"
            "            os.kill(os.getpid(), signal.SIGTERM)\n"
            "            import math\n"
            "            print('still loading', flush=True)\n"
            "    except signals.Interrupted as err:\n"
            "        print('interrupted', err.status)\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=_env(), timeout=60)
    assert run.stdout.split("\n")[:2] == ["still loading", "interrupted 143"], run.stderr


def _nested_glass(reflect: float = 0.95, eye: float = 6.0) -> Scene:
    glass = Material(reflectivity=reflect, transparency=reflect, speed_of_light=0.7)
    settings = Settings(max_recursion_depth=64, min_reflectivity=0.0, min_transparency=0.0)
    return Scene(objects=[Shape("sphere", material=glass), Shape("sphere", scaling(0.5, 0.5, 0.5), material=glass)],
                 lights=[Light((2.0, 3.0, 4.0), (1.0, 1.0, 1.0))],
                 camera=Camera((0, 0, eye), (0, 0, 0), (0, 1, 0), 40), settings=settings)


@pytest.mark.parametrize("backend", ["c", "numpy"])
def test_a_cancel_is_heard_inside_a_batch_of_rays(backend):
    """One tile of camera rays that all meet the glass, each with a tree of up to 4,096 rays, is seconds of
    work in one batch: the cancel, asked while it is traced, stops it within a fraction of a second of work
    (CPU seconds of this process: on a shared machine wall seconds would measure the neighbours too)."""
    said = []

    def cancel():  # (its first call is the render's own, before the tile; the next ones come during it)
        said.append(time.process_time())
        return len(said) > 1

    size = 64 if backend == "c" else 24
    scene = _nested_glass(eye=2.5)  # (the glass fills the view)
    with pytest.raises(RenderCancelled):
        render(scene, size, size, tile=size, backend=backend, cancel=cancel, threads=1)
    assert len(said) == 2 and time.process_time() - said[1] <= HEARD_WITHIN
    # The scene renders again as if nothing had happened (the stop flag is not left set).
    again = render(scene, 6, 4, backend=backend)
    reference = render(_nested_glass(eye=2.5), 6, 4, backend="numpy" if backend == "c" else "c")
    assert np.abs(again.image - reference.image).max() <= 1 / 255


def test_a_signal_while_a_librarys_messages_are_held_back_still_says_interrupted(tmp_path):
    """usd-core's and libtiff's messages are caught by pointing file descriptor 2 at a temporary file
    (tracer.diagnostics.held_stderr).  A signal that comes meanwhile, while the main thread is stuck in C code
    (here a long key derivation), is acted on by the C core's watchdog: its "interrupted" line goes to the program's
    standard error, not into the held-back file that nobody reads once the process has ended.  (The signal
    comes from another thread: sent from the main thread, Python would act on it before the C call began.)"""
    sent = tmp_path / "sent"
    code = ("import hashlib, os, signal, threading, time\n"
            "from tracer import signals, diagnostics\n"
            "from tracer.backend import load_core\n"
            "signals.install_at_start()\n"
            "with signals.working():\n"
            "    load_core('c')\n"
            "    with diagnostics.held_stderr():\n"
            "        def send():\n"
            f"            open({str(sent)!r}, 'w').write(repr(time.monotonic()))\n"
            "            os.kill(os.getpid(), signal.SIGTERM)\n"
            "        threading.Timer(0.2, send).start()\n"
            "        hashlib.pbkdf2_hmac('sha256', b'x', b'y', 3 * 10**7)\n"
            "print('went on')\n")
    run = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, cwd=ROOT, env=_env(), timeout=60)
    ended = time.monotonic()
    assert run.returncode == 128 + signal.SIGTERM and run.stdout == "", (run.returncode, run.stdout, run.stderr)
    assert run.stderr.strip().splitlines()[-1:] == ["interrupted"], run.stderr
    assert ended - float(sent.read_text()) < 3  # (the watchdog's 0.3 s, not the key's 10 s of CPU or more)


def test_a_run_holding_a_large_scene_ends_within_half_a_second(tmp_path):
    """Ending a process that holds 20,000 shapes and usd-core the way Python does (freeing each object, tearing
    the libraries down) took 0.5 to 0.8 s after the "interrupted" line: an interrupted program ends at once
    (tracer.signals.end_interrupted_program).  Signals at random moments of converting the scene to .usdc."""
    scene = tmp_path / "many.sdl"
    scene.write_text("camera 0 0 30  0 0 0  0 1 0  40\nlight 2 3 4  1 1 1\n" + "".join(
        f"push translate {k % 200 - 100} {k // 200 - 50} 0 scale 0.3 0.3 0.3 sphere pop\n" for k in range(20_000)))
    output = tmp_path / "many.usdc"
    rng = random.Random(28)
    interrupted = 0
    for k in range(4):
        output.write_bytes(OLD)
        signum = (signal.SIGINT, signal.SIGTERM)[k % 2]
        proc = subprocess.Popen([sys.executable, "-m", "tracer", "convert", str(scene), str(output)],
                                stderr=subprocess.PIPE, cwd=ROOT, env=_env())
        time.sleep(rng.uniform(3.0, 6.0))  # (the scene read, usd-core loaded: the stage is being made or written)
        sent = time.monotonic()
        proc.send_signal(signum)
        _, err = proc.communicate(timeout=120)
        took = time.monotonic() - sent
        if proc.returncode == 0:  # it had finished
            continue
        interrupted += 1
        assert proc.returncode == 128 + signum, (proc.returncode, err)
        latency = _machine_latency()
        assert took <= HEARD_WITHIN + latency, \
            f"{signal.Signals(signum).name} heard after {took:.2f} s (the machine's own latency: {latency:.2f} s)"
        assert output.read_bytes() == OLD and sorted(p.name for p in tmp_path.iterdir()) == ["many.sdl", "many.usdc"]
        assert err.decode().strip().splitlines()[-1:] == ["interrupted"], err
    assert interrupted >= 2
