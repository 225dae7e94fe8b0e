"""A seeded slice of the fuzz run (``make fuzz`` runs 10^4 inputs), and the library-aware properties it
relies on: every way a picture or a scene can be bad ends in a TracerError, never in a library's exception."""
from __future__ import annotations

import errno
import io
import json
import random
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from fuzz import case_for
from generators import GENERATED, NEEDS_USD, differential_sdl, generated_case, readers
from harness import SANITIZED
from mutate import KINDS, make_case, mutate_bytes, mutate_png, seeds
from tracer.errors import TracerError
from tracer.reporting import error_message, user_path
from tracer.textures.images import MAX_TEXELS, load_image

FUZZ = Path(__file__).with_name("fuzz.py")


def test_a_seeded_slice_of_the_fuzz_run_keeps_the_promise():
    # 300 inputs of every kind: no traceback, signal, hang, memory over 2 GB or stray line; C = NumPy on the
    # valid scenes among them that are compared.
    run = subprocess.run([sys.executable, str(FUZZ), "--count", "300", "--seed", "2026", "--jobs", "2",
                          "--compare-every", "5"], capture_output=True, text=True, timeout=1200)
    summary = json.loads(run.stdout)
    assert summary["inputs"] == 300
    assert summary["failures"] == {}, summary["failed_inputs"]
    assert summary["mismatches"] == []
    assert summary["verdicts"].get("image", 0) > 50 and summary["verdicts"].get("error", 0) > 50
    assert summary["compared"] > 0
    assert run.returncode == 0


def test_cases_are_reproduced_from_their_seed():
    first, again = make_case(4711), make_case(4711)
    assert (first.kind, first.files, first.options, first.command) == \
        (again.kind, again.files, again.options, again.command)
    assert {make_case(seed).kind for seed in range(200)} == set(KINDS)
    usd = not SANITIZED  # (usd-core cannot be loaded under the sanitizers)
    made, remade = generated_case(4711, usd), generated_case(4711, usd)
    assert made == remade
    assert {generated_case(seed, usd).kind for seed in range(200)} == \
        {kind for kind in GENERATED if usd or kind not in NEEDS_USD}
    # about half of a run's inputs are generated, and a mutation's seed makes the mutation it always made
    drawn = [case_for(seed, usd) for seed in range(400)]
    assert 150 < sum(case.kind in GENERATED for case in drawn) < 250
    assert all(case.files == make_case(seed, usd).files for seed, case in enumerate(drawn) if case.kind in KINDS)


def test_the_differential_run_reads_with_both_readers_and_tells_them_apart(tmp_path, monkeypatch):
    """The generated texts are long enough for the C reader, which reads most of them to the end; both readers
    then give the same scene.  A reader that differs is caught."""
    import random
    from dataclasses import replace

    from tracer.sdl import fastread, parser

    read = 0
    for seed in range(12):
        path = tmp_path / f"r{seed}.sdl"
        path.write_bytes(readers(random.Random(seed), "r").files["r.sdl"])
        assert len(path.read_text()) >= parser.FAST_MIN_CHARS
        read += isinstance(fastread.scan(path.read_text()), fastread.Columns)
        assert differential_sdl(str(path), seed % 2 == 0) == (0, "")
    assert read >= 6
    slow = parser.parse_sdl

    def off_by_an_ulp(text, *args, fast=True, **kwargs):  # a C reader that rounds one light differently
        scene = slow(text, *args, fast=fast, **kwargs)
        if fast and scene.lights:
            light = scene.lights[0]
            scene.lights[0] = replace(light, position=tuple(np.nextafter(light.position, np.inf).tolist()))
        return scene

    monkeypatch.setattr(parser, "parse_sdl", off_by_an_ulp)
    code, detail = differential_sdl(str(tmp_path / "r1.sdl"), False)
    assert code == 3 and "differ" in detail


def test_some_scenes_are_long_enough_for_the_c_reader_and_some_of_those_it_reads():
    """The command line offers a long text to the C reader first (tracer.sdl.parser.FAST_MIN_CHARS), so the
    fuzz run pads part of its scenes to that length: the C reader then reads hostile input too, through the
    real command, and has to read it exactly as the Python reader or leave it to that reader."""
    from tracer.sdl import fastread
    from tracer.sdl.parser import FAST_MIN_CHARS
    long_texts = [text for seed in range(1500) if (case := make_case(seed, usd=False)).kind == "sdl"
                  and len(text := case.files[case.main].decode("utf-8", "replace")) >= FAST_MIN_CHARS]
    assert len(long_texts) >= 20
    if fastread.available():
        read = [text for text in long_texts
                if not isinstance(fastread.scan(text), fastread.Declined)]
        assert read


@settings(max_examples=150, deadline=None)
@given(st.sampled_from(("png", "bmp", "jpeg", "ppm")), st.integers(0, 2**32))
def test_a_mutated_picture_loads_as_8_bit_or_is_a_tracer_error(tmp_path_factory, kind, seed):
    rng = random.Random(seed)
    original = rng.choice(seeds()[kind])
    data = mutate_png(rng, original) if kind == "png" else mutate_bytes(rng, original)
    path = tmp_path_factory.mktemp("img") / f"picture.{kind}"
    path.write_bytes(data)
    try:
        texels = load_image(path)
    except TracerError as err:
        assert "picture." in str(err)  # names the file
        return
    assert texels.dtype == np.uint8 and texels.ndim == 3 and texels.shape[2] == 3
    assert texels.shape[0] * texels.shape[1] <= MAX_TEXELS


def test_a_picture_is_refused_from_its_header_before_decoding(tmp_path):
    from PIL import Image

    path = tmp_path / "big.png"
    Image.new("1", (MAX_TEXELS // 4096 + 1, 4096)).save(path)  # a few KB on disk
    with pytest.raises(TracerError, match="too large for a texture"):
        load_image(path)


def test_the_translation_names_the_users_file():
    assert user_path("/out/.frame.png.0a1b2c3d-4711@a1b2c3.tmp") == "/out/frame.png"
    assert user_path("/out/frame.png") == "/out/frame.png"
    too_big = OSError(errno.EFBIG, "File too large", "/out/.frame.png.0a1b2c3d-4711@a1b2c3.tmp")
    assert error_message(too_big) == "/out/frame.png: file too large (the process' file size limit, ulimit -f, " \
                                     "was reached)"
    assert error_message(MemoryError(), "scene.sdl").startswith("scene.sdl: not enough memory")
    assert error_message(ValueError("a bug")) is None  # not the input's fault: left to show itself
    assert len(error_message(TracerError("x" * 10**6))) < 700


@pytest.mark.skipif(SANITIZED, reason="under make sanitize: no usd-core")
@pytest.mark.parametrize("name", ["out.usda", "out.sdl"])
def test_a_kill_after_the_whole_output_was_put_in_place_is_judged_kept(tmp_path, name):
    """Fuzz input 3001026276: SIGKILL reached a convert after it had put its whole out.usda in place (the same
    bytes as a convert left alone writes); the judge read it as a half-written image.  A whole USD or SDL
    output with a -9 status is a kept promise; a truncated one is not."""
    import signal

    from fuzz import _judge_signal
    from harness import Outcome
    from mutate import Case
    from tracer import cli

    source = tmp_path / "in.sdl"
    source.write_text("light 1 2 3 1 1 1\nsphere\npush translate 2 0 0 cube pop\n")
    assert cli.main(["convert", str(source), str(tmp_path / name)]) == 0
    case = Case("kill", {"in.sdl": source.read_bytes()}, command="convert")
    case.signal, case.output = (signal.SIGKILL, 0.1), name
    whole = Outcome("", -signal.SIGKILL, "", 0.2, 0)
    _judge_signal(case, whole, tmp_path)
    assert whole.ok, whole.detail
    data = (tmp_path / name).read_bytes()
    (tmp_path / name).write_bytes(data[: len(data) // 2])
    cut = Outcome("", -signal.SIGKILL, "", 0.2, 0)
    _judge_signal(case, cut, tmp_path)
    assert cut.verdict == "bad-exit", cut.detail
