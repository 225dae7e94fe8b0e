"""The command line as a user meets it: images out, one-line errors, exit status 2, no tracebacks."""
from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from PIL import Image

ROOT = Path(__file__).parent.parent


def run(*args, cwd=None):
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    return subprocess.run([sys.executable, "-m", "tracer", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, env=env, timeout=300)


def test_render_writes_image_and_stats(tmp_path):
    out = tmp_path / "lecture.png"
    proc = run("render", ROOT / "scenes" / "lecture.sdl", "-o", out, "--width", 64, "--height", 48, "--stats")
    assert proc.returncode == 0, proc.stderr
    stats = json.loads(proc.stdout)
    assert stats["rays"]["camera"] == 64 * 48
    assert set(stats["rays"]) == {"camera", "shadow", "reflection", "refraction"}
    assert stats["rays"]["reflection"] == 0 and stats["rays"]["shadow"] > 0
    assert stats["backend"] in ("c", "numpy") and stats["seconds"] > 0
    with Image.open(out) as image:
        assert image.size == (64, 48)
    assert [p.name for p in tmp_path.iterdir()] == ["lecture.png"]  # no temporary left behind


def test_block_size_option(tmp_path):
    out = tmp_path / "blocky.png"
    proc = run("render", ROOT / "scenes" / "csg.sdl", "-o", out, "--width", 32, "--height", 24,
               "--block-size", 8, "--stats")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout)["rays"]["camera"] == 4 * 3


def _assert_one_line_error(proc, *fragments):
    assert proc.returncode == 2
    lines = proc.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "Traceback" not in proc.stderr
    for fragment in fragments:
        assert fragment in lines[0]


def test_broken_file_names_file_line_and_token(tmp_path):
    scene = tmp_path / "broken.sdl"
    scene.write_text("light 1 2 3 1 1 1\nsphere\ntranslate 1 2 sphere\n")
    proc = run("render", scene, "-o", tmp_path / "x.png")
    _assert_one_line_error(proc, f"{scene}:3:", "'sphere'")
    assert not (tmp_path / "x.png").exists()


MESSY = "light 1 2 3 1 1 1\nsphre\npop\nmesh missing.3vn\nsphere\n"


def test_messy_file_stops_by_default_and_renders_with_lenient(tmp_path):
    scene = tmp_path / "messy.sdl"
    scene.write_text(MESSY)
    _assert_one_line_error(run("render", scene, "-o", tmp_path / "x.png"), "messy.sdl:2:1", "sphere")
    proc = run("render", scene, "-o", tmp_path / "x.png", "--lenient", "--width", 16, "--height", 12)
    assert proc.returncode == 0
    warnings = [l for l in proc.stderr.splitlines() if l.startswith("warning: ")]
    assert len(warnings) == 3
    assert any("messy.sdl:2:1" in w for w in warnings)
    assert any("messy.sdl:3:1" in w and "pop" in w for w in warnings)
    assert any("messy.sdl:4" in w and "missing.3vn" in w for w in warnings)
    assert (tmp_path / "x.png").exists()


@pytest.mark.parametrize("args, fragment", [
    (("render", "no-such-scene.sdl", "-o", "x.png"), "no-such-scene.sdl"),
    (("render", "scenes/lecture.sdl", "-o", "/no/such/folder/x.png"), "/no/such/folder"),
    (("render", "scenes/lecture.sdl", "-o", "x.png", "--width", "100000"), "width"),
    (("render", "scenes/lecture.sdl", "-o", "x.unknown"), ".unknown"),
    (("render", "scenes/lecture.sdl", "-o", "x.png", "--block-size", "0"), "block size"),
    (("render", "scenes/lecture.sdl", "-o", "x.png", "--threads", "0"), "threads"),
    (("convert", "scenes/lecture.sdl", "/no/such/folder/x.sdl"), "/no/such/folder' does not exist"),
])
def test_bad_requests_get_one_line(args, fragment):
    _assert_one_line_error(run(*args), fragment)


def test_target_error_names_the_options_it_replaces(tmp_path):
    common = ("render", ROOT / "scenes" / "csg.sdl", "-o", tmp_path / "x.png", "--width", 8, "--height", 6, "-q",
              "--target-error", 0.05)
    proc = run(*common, "--samples", 9, "--sampling", "regular", "--block-size", 4, "--progressive")
    assert proc.returncode == 0, proc.stderr
    warnings = [line for line in proc.stderr.splitlines() if line.startswith("warning:")]
    assert warnings == ["warning: --target-error chooses the samples itself: --block-size, --progressive, "
                        "--samples, --sampling ignored"], proc.stderr
    proc = run(*common, "--samples", 4)  # only what was given is named
    assert proc.stderr.splitlines() == ["warning: --target-error chooses the samples itself: --samples ignored"]
    proc = run(*common)
    assert proc.returncode == 0 and "warning:" not in proc.stderr, proc.stderr


def test_the_adaptive_threshold_is_no_longer_used_and_says_so(tmp_path):
    """--threshold (adaptive sampling's neighbour difference, before it spent its samples by an error model)
    still parses, so that scripts run on, with a warning; the image is the one without it."""
    common = ("render", ROOT / "scenes" / "lecture.sdl", "--width", 16, "--height", 12, "-q", "--samples", 4,
              "--sampling", "adaptive")
    proc = run(*common, "-o", tmp_path / "with.png", "--threshold", "0.1")
    assert proc.returncode == 0, proc.stderr
    assert [line for line in proc.stderr.splitlines() if line.startswith("warning:")] == [
        "warning: --threshold is no longer used: adaptive sampling spends about --samples rays per pixel where "
        "its error model says they lower the image's error most (docs/accuracy.md)"]
    proc = run(*common, "-o", tmp_path / "without.png")
    assert proc.returncode == 0 and "warning:" not in proc.stderr, proc.stderr
    assert (tmp_path / "with.png").read_bytes() == (tmp_path / "without.png").read_bytes()


# Runs the CLI as an installation without Pillow would: importing PIL fails, and tracing (which must not
# start) exits with a message of its own.
_WITHOUT_PILLOW = """
import sys

class RefusePillow:
    def find_spec(self, name, path=None, target=None):
        if name == "PIL" or name.startswith("PIL."):
            raise ImportError(f"No module named {name!r}")
        return None

sys.meta_path.insert(0, RefusePillow())
if sys.argv[-1] == "--refuse-tracing":
    import tracer.render
    tracer.render.render = lambda *args, **kwargs: sys.exit("traced before checking for Pillow")
from tracer.cli import main
sys.exit(main(sys.argv[1:-1]))
"""


def test_missing_pillow_is_one_error_before_tracing_for_formats_that_need_it(tmp_path):
    out = tmp_path / "x.jpg"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-c", _WITHOUT_PILLOW, "render", str(ROOT / "scenes" / "lecture.sdl"),
                           "-o", str(out), "-q", "--refuse-tracing"],
                          capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    _assert_one_line_error(proc, str(out), "needs Pillow", "pip install Pillow")
    assert not out.exists()


def test_png_is_written_without_pillow(tmp_path):
    """tracer.png writes PNG files itself: the same file as with Pillow installed."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    args = ["render", str(ROOT / "scenes" / "lecture.sdl"), "--width", "40", "--height", "30", "-q"]
    without = subprocess.run([sys.executable, "-c", _WITHOUT_PILLOW, *args, "-o", str(tmp_path / "a.png"), "--"],
                             capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert without.returncode == 0, without.stderr
    assert run(*args, "-o", tmp_path / "b.png").returncode == 0
    assert (tmp_path / "a.png").read_bytes() == (tmp_path / "b.png").read_bytes()


def test_thread_count_does_not_change_the_image(tmp_path):
    images = []
    for threads in (1, 2, 3):
        out = tmp_path / f"t{threads}.png"
        proc = run("render", ROOT / "scenes" / "glass.sdl", "-o", out, "--width", 40, "--height", 30,
                   "--threads", threads, "-q")
        assert proc.returncode == 0, proc.stderr
        with Image.open(out) as image:
            images.append(image.tobytes())
    assert images[0] == images[1] == images[2]


def test_info_lists_objects_lights_and_effects():
    proc = run("info", ROOT / "scenes" / "glass.sdl")
    assert proc.returncode == 0, proc.stderr
    assert "objects: 7" in proc.stdout and "lights: 2" in proc.stdout
    effects = proc.stdout.split("live effects:")[1]
    for effect in ("shadows", "reflection", "refraction", "csg"):
        assert effect in effects
    data = json.loads(run("info", ROOT / "scenes" / "jack.sdl", "--json").stdout)
    assert data["camera"]["viewAngle"] == 40
    assert "reflection" not in data["effects"] and "shadows" in data["effects"]
    assert sum(1 for o in data["objects"] if "jack" in o.get("groups", [])) == 20



def test_info_shows_shape_names(tmp_path):
    scene = tmp_path / "named.sdl"
    scene.write_text("! name: Lamp post\nsphere\ncube\n", encoding="utf-8")
    proc = run("info", scene)
    assert proc.returncode == 0, proc.stderr
    assert "sphere 'Lamp post' at" in proc.stdout and "  cube at" in proc.stdout
    data = json.loads(run("info", scene, "--json").stdout)
    assert [o.get("name") for o in data["objects"]] == ["Lamp post", None]


def _info_output(capsys, monkeypatch, scene, *options):
    """What ``info`` prints for this Scene object (read from no file)."""
    from tracer import cli

    monkeypatch.setattr(cli, "_read_scene", lambda *args: scene)
    assert cli.main(["info", "scene.sdl", *options]) == 0
    return capsys.readouterr().out


def test_info_of_a_shape_table_prints_what_its_shapes_would(capsys, monkeypatch):
    """A big file's shapes stay columns (tracer.model.ShapeTable) and info reads those; the text and the JSON
    are the same, byte for byte, as for the Python reader's list of Shapes.  Positions include decimal ties
    at the sixth place (x.yyyyyy5), where rounding x * 10^6 in floating point can go the other way."""
    import numpy as np

    from tracer.model import ShapeTable
    from tracer.sdl.parser import parse_sdl

    rng = np.random.default_rng(7)
    kinds = ["sphere", "cube", "cylinder", "cone", "taperedCylinder 0.4", "tetrahedron", "teapot", "torus"]
    lines = ["light 3 4 5  1 1 1", "camera 0 2 9  0 0 0  0 1 0  40",
             "push rotate -90 1 0 0 translate 0 0 -1.0000005 plane pop"]
    for i in range(300):
        x, y, z = (rng.integers(-10**7, 10**7, 3) + rng.choice([0.5, 0.25, 0.0], 3)) / 10**6
        if i % 7 == 0:
            lines.append(f"! name: thing {i}")
        lines.append(f"diffuse {rng.uniform():.3f} 0.5 0.5 push translate {x!r} {y!r} {z!r} "
                     f"scale 2 0.5 1 {kinds[i % len(kinds)]} pop")
    text = "\n".join(lines) + "\n"
    columns, objects = parse_sdl(text, fast=True), parse_sdl(text, fast=False)
    assert isinstance(columns.objects, ShapeTable) and columns.objects.columns is not None
    assert not isinstance(objects.objects, ShapeTable)
    for options in (("--json",), ()):
        from_columns = _info_output(capsys, monkeypatch, columns, *options)
        assert columns.objects.columns is not None  # (no Shape was made)
        assert from_columns == _info_output(capsys, monkeypatch, objects, *options)
    assert "torus 'thing 7' at" in from_columns and "  tetrahedron at" in from_columns


# --- convert (SDL <-> USD; docs/usd.md) -------------------------------------------------------------------

def test_convert_sdl_to_usd_and_back_keeps_what_info_shows(tmp_path):
    for name in ("jack.usda", "jack.usdc", "jack.usd"):
        proc = run("convert", ROOT / "scenes" / "jack.sdl", tmp_path / name)
        assert proc.returncode == 0 and proc.stdout == "" and proc.stderr == "", proc.stderr
    proc = run("convert", tmp_path / "jack.usdc", tmp_path / "back.sdl")
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    before = json.loads(run("info", ROOT / "scenes" / "jack.sdl", "--json").stdout)
    for path in (tmp_path / "jack.usda", tmp_path / "back.sdl"):
        after = json.loads(run("info", path, "--json").stdout)
        assert after["camera"] == before["camera"] and after["effects"] == before["effects"]
        assert after["lights"] == before["lights"] and len(after["objects"]) == len(before["objects"])
    assert (tmp_path / "jack.usda").read_text().startswith("#usda 1.0")
    assert sorted(p.name for p in tmp_path.iterdir()) == ["back.sdl", "jack.usd", "jack.usda", "jack.usdc"]


UNSUPPORTED = '#usda 1.0\ndef Capsule "Pill"\n{\n}\ndef Sphere "Ball"\n{\n}\n'
FLAT = ('#usda 1.0\ndef Sphere "Flat"\n{\n    double3 xformOp:scale = (1, 0, 1)\n'
        '    uniform token[] xformOpOrder = ["xformOp:scale"]\n}\n')


@pytest.mark.parametrize("source, destination, fragments", [
    ("scenes/csg.sdl", "out.obj", ["out.obj", ".usda"]),  # a destination format we cannot tell
    ("no-such.usda", "out.sdl", ["no-such.usda", "no such file"]),
    ("bad.usda", "out.sdl", ["bad.usda:2:1"]),  # USD's parse error, with line and column
    ("pill.usda", "out.sdl", ["pill.usda", "</Pill>", "Capsule is not supported"]),
    ("flat.usda", "out.usdc", ["flat.usda", "</Flat>", "singular transform"]),
    ("scenes/csg.sdl", "no/such/folder/out.usda", ["no/such/folder"]),
])
def test_convert_errors_are_one_line_and_write_nothing(tmp_path, source, destination, fragments):
    (tmp_path / "bad.usda").write_text("#usda 1.0\nthis is not usd\n")
    (tmp_path / "pill.usda").write_text(UNSUPPORTED)
    (tmp_path / "flat.usda").write_text(FLAT)
    source = ROOT / source if source.startswith("scenes/") else tmp_path / source
    _assert_one_line_error(run("convert", source, tmp_path / destination), *fragments)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.usda", "flat.usda", "pill.usda"]


def test_convert_and_render_usd_leniently(tmp_path):
    (tmp_path / "pill.usda").write_text(UNSUPPORTED)
    proc = run("convert", tmp_path / "pill.usda", tmp_path / "ball.sdl", "--lenient")
    assert proc.returncode == 0
    assert proc.stderr.splitlines() == [f"warning: {tmp_path / 'pill.usda'}: </Pill>: Capsule is not supported: "
                                        "left out"]
    assert "sphere" in (tmp_path / "ball.sdl").read_text()
    _assert_one_line_error(run("render", tmp_path / "pill.usda", "-o", tmp_path / "x.png"), "</Pill>")
    proc = run("render", tmp_path / "pill.usda", "-o", tmp_path / "x.png", "--lenient", "--width", 8,
               "--height", 6, "-q")
    assert proc.returncode == 0 and len(proc.stderr.splitlines()) == 1
    assert (tmp_path / "x.png").exists()


#: What ``render`` to a .png must not load (tests below): OpenSSL's hashlib module, the code of the NumPy
#: subpackages the program defers (tracer/startup.py; their first modules), the secrets module, Pillow, the
#: parts of the tracer and the optional packages other commands use, the C compiler's tools (subprocess:
#: only a build of the C core runs one), difflib (suggestions for a mistyped keyword) and Python's threading
#: (the C core runs its own threads).
NOT_LOADED_BY_A_PNG_RENDER = ("_hashlib", "numpy.random.mtrand", "numpy.random._generator", "numpy.ma.core",
                              "numpy.polynomial.polynomial", "numpy.fft._pocketfft", "secrets", "PIL",
                              "tracer.distributed", "tracer.accuracy", "tracer.target", "tracer.sdl.writer",
                              "tracer.usd.reader", "tracer.usd.writer", "pxr", "dask", "distributed", "scipy",
                              "skimage", "matplotlib", "subprocess", "difflib", "threading")


def _loaded_modules(python_verbose_stderr: str) -> set:
    """The modules a ``python -v`` run loaded (a module marked absent in sys.modules is not listed)."""
    return set(re.findall(r"^import '([\w.]+)' #", python_verbose_stderr, re.M)) | \
        set(re.findall(r"^# extension module '([\w.]+)' loaded", python_verbose_stderr, re.M))


def test_a_png_render_loads_only_what_it_uses(tmp_path):
    """The imports are most of a small render's peak memory (docs/performance.md), so the floor is kept from
    creeping back: ``python -m tracer render`` to a .png loads none of NOT_LOADED_BY_A_PNG_RENDER."""
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.run([sys.executable, "-v", "-m", "tracer", "render", str(ROOT / "scenes" / "shapes.sdl"),
                           "-o", str(tmp_path / "x.png"), "--width", "16", "--height", "12", "-q"],
                          capture_output=True, text=True, cwd=ROOT, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr[-2000:]
    loaded = _loaded_modules(proc.stderr)
    assert {"numpy", "tracer.render", "tracer.png", "_blake2"} <= loaded  # (the listing sees what is loaded)
    assert sorted(m for m in loaded if m.split(".")[0] in NOT_LOADED_BY_A_PNG_RENDER
                  or any(m == name or m.startswith(name + ".") for name in NOT_LOADED_BY_A_PNG_RENDER)) == []


def test_importing_the_tracer_as_a_library_leaves_the_process_alone():
    """Only the command line leaves OpenSSL out and defers NumPy's parts (tracer/startup.py); a program
    importing the tracer keeps hashlib's OpenSSL functions and NumPy as it loads itself."""
    code = "import tracer, hashlib; print(hashlib.sha256 is not None and 'pbkdf2_hmac' in dir(hashlib))"
    proc = subprocess.run([sys.executable, "-v", "-c", code], capture_output=True, text=True, cwd=ROOT,
                          env={**os.environ, "PYTHONPATH": str(ROOT)}, timeout=300)
    assert proc.returncode == 0 and proc.stdout.strip() == "True", proc.stderr[-2000:]
    assert {"_hashlib", "numpy.random.mtrand", "numpy.ma.core"} <= _loaded_modules(proc.stderr)


_DEFERRED_THEN_USED = """
import importlib.util, sys
spec = importlib.util.spec_from_file_location("startup", sys.argv[1])  # (not through the package: it imports NumPy)
startup = importlib.util.module_from_spec(spec)
spec.loader.exec_module(startup)
if sys.argv[2] == "deferred":
    startup.prepare_the_program()
import numpy as np
import hashlib
print("numpy.random.mtrand" in sys.modules, "numpy.ma.core" in sys.modules)
print(np.random.default_rng(5).random(3).tolist(), np.random.RandomState(2).randint(0, 100, 3).tolist())
print(float(np.ma.masked_array([1.0, 2.0, 4.0], mask=[0, 1, 0]).sum()), np.fft.rfft([1.0, 2.0, 3.0]).tolist())
print(np.polynomial.Polynomial([1, 2, 3])(2.0), np.ctypeslib.as_array((np.ctypeslib.ctypes.c_double * 2)(1, 2)).tolist())
print(hashlib.blake2b(b"x", digest_size=8).hexdigest(), hashlib.sha256(b"x").hexdigest()[:16])
"""


def test_deferred_numpy_parts_load_when_first_used_and_give_the_same_results():
    results = {}
    for mode in ("deferred", "plain"):
        proc = subprocess.run([sys.executable, "-c", _DEFERRED_THEN_USED, str(ROOT / "tracer" / "startup.py"), mode],
                              capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        results[mode] = proc.stdout.splitlines()
    assert results["deferred"][0] == "False False" and results["plain"][0] == "True True"
    assert results["deferred"][1:] == results["plain"][1:]


_FREED_THEN_MEASURED = """
import importlib.util, re, sys
spec = importlib.util.spec_from_file_location("startup", sys.argv[1])
startup = importlib.util.module_from_spec(spec)
spec.loader.exec_module(startup)
if sys.argv[2] == "returned" and not startup.return_freed_memory():
    sys.exit(3)
import numpy as np
def resident():
    return int(re.search(r"VmRSS:\\s+(\\d+)", open("/proc/self/status").read()).group(1)) * 1024
first = np.ones(3 << 20)  # (24 MB, freed: glibc's default would now keep blocks below that on its heap)
del first
before = resident()
temporary = np.ones(2 << 20)  # 16 MB
del temporary
print(resident() - before)
"""


@pytest.mark.skipif(not sys.platform.startswith("linux") or not os.confstr("CS_GNU_LIBC_VERSION"),
                    reason="glibc's malloc only")
def test_the_program_returns_freed_temporaries_to_the_system():
    """The command line fixes the size from which glibc gives a block pages of its own (tracer/startup.py):
    a 16 MB array freed after a 24 MB one goes back to the system at once, where glibc's own rule (the
    plain process, which the test also runs, so that it shows the difference) keeps it resident."""
    kept = {}
    for mode in ("returned", "plain"):
        proc = subprocess.run([sys.executable, "-c", _FREED_THEN_MEASURED, str(ROOT / "tracer" / "startup.py"), mode],
                              capture_output=True, text=True, cwd=ROOT, timeout=300)
        assert proc.returncode == 0, proc.stderr[-2000:]
        kept[mode] = int(proc.stdout)
    assert kept["returned"] < 2 << 20 and kept["plain"] > 12 << 20, kept


@pytest.mark.parametrize("options", [[], ["--block-size", "8", "--progressive"], ["--samples", "4"],
                                     ["--samples", "4", "--sampling", "adaptive"]])
def test_the_png_written_band_by_band_is_the_rendered_image(tmp_path, options):
    """A .png render writes bands of rows as they are traced (no whole image kept): the file is the one
    save_image writes from the image render() returns, and no temporary is left."""
    import tracer
    from tracer.imageio import save_image

    out = tmp_path / "streamed.png"
    proc = run("render", ROOT / "scenes" / "lecture.sdl", "-o", out, "--width", 70, "--height", 150, "-q",
               *options)
    assert proc.returncode == 0, proc.stderr
    settings = dict(zip(options[::2], options[1::2]))
    kept = tracer.render(tracer.load(ROOT / "scenes" / "lecture.sdl"), 70, 150, eight_bit=True,
                         block_size=int(settings.get("--block-size", 1)), progressive="--progressive" in options,
                         samples=int(settings.get("--samples", 1)), sampling_mode=settings.get("--sampling", "jittered"))
    assert out.read_bytes() == save_image(kept.image, tmp_path / "kept.png").read_bytes()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["kept.png", "streamed.png"]


def test_a_render_that_fails_while_streaming_leaves_no_file(tmp_path):
    """A .png whose header is already written when tracing stops (here: cancelled) is removed, not left half
    written, and a file that was there before is kept."""
    out = tmp_path / "x.png"
    out.write_bytes(b"before")
    code = ("import sys\nimport tracer\nfrom tracer.errors import RenderCancelled\n"
            "module = sys.modules['tracer.render']\nreal = module.render\n"
            "def render(*args, on_rows, **kwargs):\n"
            "    def first_band_then_stop(rows):\n"
            "        on_rows(rows)\n"
            "        raise RenderCancelled('render cancelled')\n"
            "    return real(*args, on_rows=first_band_then_stop, **kwargs)\n"
            "module.render = render\n"
            "from tracer.cli import main\nsys.exit(main(sys.argv[1:]))\n")
    proc = subprocess.run([sys.executable, "-c", code, "render", str(ROOT / "scenes" / "lecture.sdl"), "-o", str(out),
                           "--width", "64", "--height", "200", "-q", "--tile", "16"],
                          capture_output=True, text=True, cwd=ROOT, env={**os.environ, "PYTHONPATH": str(ROOT)},
                          timeout=300)
    assert proc.returncode == 130 and "cancelled" in proc.stderr, proc.stderr
    assert [p.name for p in tmp_path.iterdir()] == ["x.png"] and out.read_bytes() == b"before"


@pytest.mark.skipif(os.name != "posix", reason="a closed pipe is told by polling it (POSIX)")
def test_info_whose_reader_stops_early_ends_quietly(tmp_path):
    """``info big.sdl | head``: the reader closing the pipe is not the scene's fault, so no error names the
    scene; the command ends as a Unix tool ended by SIGPIPE does (status 141) and prints nothing more."""
    scene = tmp_path / "many.sdl"
    scene.write_text("".join(f"push translate {k} 0 0 sphere pop\n" for k in range(20000)))  # (~700 KB of info)
    proc = subprocess.Popen([sys.executable, "-m", "tracer", "info", str(scene)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, cwd=ROOT)
    assert proc.stdout.readline().startswith(b"objects: 20000")
    proc.stdout.close()
    _, err = proc.communicate(timeout=120)
    assert proc.returncode == 141 and err.decode() == ""


def test_info_shows_light_kinds_and_names(tmp_path):
    scene = tmp_path / "lights.sdl"
    scene.write_text("! name: Key Light\nlight 1 2 3 1 1 1\nsunLight 0 -1 0 0.5 0.5 0.5 1 4\nsphere\n",
                     encoding="utf-8")
    proc = run("info", scene)
    assert proc.returncode == 0, proc.stderr
    assert "  at (1, 2, 3) colour (1, 1, 1) 'Key Light'" in proc.stdout
    assert "  sun towards (0, -1, 0) colour (0.5, 0.5, 0.5)" in proc.stdout
    assert "physical-lights" in proc.stdout.split("live effects:")[1]
    key, sun = json.loads(run("info", scene, "--json").stdout)["lights"]
    assert key == {"position": [1.0, 2.0, 3.0], "color": [1.0, 1.0, 1.0], "name": "Key Light"}
    assert (sun["kind"], sun["direction"], sun["angle"], sun["samples"]) == ("sun", [0.0, -1.0, 0.0], 1.0, 4)


def test_every_option_of_every_command_says_what_it_does():
    """`--help` of each command explains each option (--width and --height had no words, so their defaults and
    limit were nowhere in the help)."""
    import argparse

    from tracer.cli import build_parser

    def commands(parser):
        for action in parser._actions:
            if isinstance(action, argparse._SubParsersAction):
                for name, sub in action.choices.items():
                    yield name, sub
                    yield from commands(sub)

    silent = [f"{name} {action.option_strings[-1]}" for name, sub in commands(build_parser())
              for action in sub._actions if action.option_strings and not action.help]
    assert silent == []
