"""Choosing the backend: "auto" never falls back to NumPy silently, the C core says what it refused, and the
CLI prints both as one line (and exits 130 on a cancel)."""
from __future__ import annotations

import ctypes
import warnings

import numpy as np
import pytest

import tracer
from tracer import cli, native
from tracer.native import flatten
from tracer.backend import MAX_CSG_DEPTH, make_tracer
from tracer.compile import compile_scene
from tracer.errors import FallbackWarning, RenderCancelled, TracerError

requires_core = pytest.mark.skipif(native.load_error is not None,
                                   reason=f"C core not available: {native.load_error}")
SCENE = "light 1 2 3 1 1 1  sphere"


def _compiled():
    return compile_scene(tracer.parse_sdl(SCENE))


@requires_core
def test_auto_takes_the_c_core_without_a_warning():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert make_tracer(_compiled(), "auto").name == "c"


def test_auto_without_the_core_warns_with_the_reason(monkeypatch):
    monkeypatch.setattr(native, "_lib", None)
    monkeypatch.setattr(native, "load_error", "no C compiler found (install gcc or set CC)")
    with pytest.warns(FallbackWarning, match="no C compiler found"):
        assert make_tracer(_compiled(), "auto").name == "numpy"
    with pytest.raises(TracerError, match="no C compiler found"):
        make_tracer(_compiled(), "c")


@requires_core
def test_a_scene_the_core_refuses_warns_with_the_reason():
    compiled = _compiled()
    compiled.effects = compiled.effects | {"something new"}
    with pytest.warns(FallbackWarning, match="something new"):
        assert make_tracer(compiled, "auto").name == "numpy"


def _nested_unions(levels: int) -> str:
    """A scene whose one object is ``levels`` unions nested down the left, the first on line 2."""
    return "light 1 2 3 1 1 1\n" + "union\n" * levels + "sphere " * (levels + 1)


@pytest.mark.parametrize("backend", ["auto", "c", "numpy"])
def test_booleans_nested_past_the_limit_are_refused_by_every_backend(backend):
    with np.errstate(all="ignore"):  # (each level's bounding sphere is sqrt(3) times its child's: it overflows)
        deepest = compile_scene(tracer.parse_sdl(_nested_unions(MAX_CSG_DEPTH)))
        too_deep = compile_scene(tracer.parse_sdl(_nested_unions(MAX_CSG_DEPTH + 1)))
    with pytest.raises(TracerError, match=rf":2:1: union: booleans nested {MAX_CSG_DEPTH + 1} deep; "
                                          rf"the tracer follows at most {MAX_CSG_DEPTH}"):
        make_tracer(too_deep, backend)
    if backend == "numpy" or native.load_error is None:
        with warnings.catch_warnings():
            warnings.simplefilter("error")  # the deepest accepted tree is no fallback either
            make_tracer(deepest, backend)


@requires_core
@pytest.mark.parametrize("corrupt, fragment", [
    (lambda d: setattr(d, "n_materials", 0), "primitive 0 has material 0 of 0"),
    (lambda d: d.prim_kind.__setitem__(0, 99), "primitive 0 has unknown shape kind 99"),
    (lambda d: d.object_ref.__setitem__(0, 5), "object 0 refers to nothing (5)"),
])
def test_rt_create_names_what_it_refused(corrupt, fragment):
    flat = flatten.FlatScene(_compiled())
    corrupt(flat.desc)
    message = ctypes.create_string_buffer(256)
    assert not native._lib.rt_create(ctypes.byref(flat.desc), message, len(message))
    assert message.value.decode() == fragment


@requires_core
def test_a_refused_description_reaches_the_user(monkeypatch):
    class Corrupt(flatten.FlatScene):
        def __init__(self, compiled):
            super().__init__(compiled)
            self.desc.n_materials = 0

    monkeypatch.setattr(flatten, "FlatScene", Corrupt)
    with pytest.raises(TracerError, match="refused the scene description: primitive 0 has material 0 of 0"):
        make_tracer(_compiled(), "c")
    with pytest.warns(FallbackWarning, match="primitive 0 has material"):
        assert make_tracer(_compiled(), "auto").name == "numpy"


def _cli(tmp_path, capsys, *extra):
    path = tmp_path / "s.sdl"
    path.write_text(SCENE)
    code = cli.main(["render", str(path), "-o", str(tmp_path / "s.png"), "--width", "8", "--height", "6",
                     "--quiet", *extra])
    return code, capsys.readouterr().err


def test_cli_prints_the_fallback_as_one_warning_line(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(native, "_lib", None)
    monkeypatch.setattr(native, "load_error", "compiling the C core failed: boom")
    code, err = _cli(tmp_path, capsys)
    assert code == 0
    assert err.splitlines() == ["warning: the C core is not available: compiling the C core failed: boom; "
                                "using the slower NumPy path"]


def test_cli_cancel_exits_130(tmp_path, capsys, monkeypatch):
    def cancelled(*args, **kwargs):
        raise RenderCancelled("render cancelled")

    monkeypatch.setattr(cli, "render", cancelled)
    code, err = _cli(tmp_path, capsys)
    assert code == cli.EXIT_INTERRUPTED == 130
    assert err.strip() == "error: cancelled"
    assert not (tmp_path / "s.png").exists()


@requires_core
def test_a_prebuilt_core_that_does_not_load_gives_way_to_the_development_build(tmp_path, monkeypatch):
    built = native._builder.build()  # (current already: no compiling here)
    bogus = tmp_path / "_core.so"
    bogus.write_bytes(b"not a library, but marked RT_SOURCE_HASH=prebuilt;")
    monkeypatch.delenv(native.LIBRARY_OVERRIDE, raising=False)
    monkeypatch.setattr(native._builder, "prebuilt_library", lambda: bogus)
    monkeypatch.setattr(native._builder, "build", lambda: built)
    assert native._load()._name == str(built)

    def no_compiler():
        raise native.BuildError("no C compiler found (install gcc or set CC)")

    monkeypatch.setattr(native._builder, "build", no_compiler)
    with pytest.raises(native.BuildError, match=r"prebuilt C core .* did not load .*no C compiler found"):
        native._load()


@requires_core
def test_sdl_tracer_library_names_the_library_to_load(monkeypatch):
    path = native._builder.build()
    monkeypatch.setenv(native.LIBRARY_OVERRIDE, str(path))
    monkeypatch.setattr(native._builder, "build", lambda: pytest.fail("looked for another library"))
    assert native._load()._name == str(path)


@requires_core
@pytest.mark.parametrize("text", [
    # every ray along the image's diagonal meets the tetrahedron exactly on the edge its two upper faces share
    "camera 0 0 5  0 0 0  0 1 0  40\nlight 2 3 4 1 1 1\ntetrahedron\n",
    "camera 0 0 5  0 0 0  0 1 0  30\nlight 2 3 4 1 1 1\nrotate 90 0 0 1 tetrahedron\n",
])
def test_c_and_numpy_agree_where_the_last_bit_decides(text):
    """Where a hit lies exactly on an edge two faces share, which face it enters by depends on the last bit:
    both backends transform rays and meet face planes with the same operations in the same order
    (numerics.affine_points, dot3; NumPy's matrix products went through BLAS), and take the first face of a
    tie (52 and 193/255 apart before)."""
    scene = tracer.parse_sdl(text)
    c = tracer.render(scene, 100, 100, backend="c").image
    n = tracer.render(tracer.parse_sdl(text), 100, 100, backend="numpy").image
    worst = np.abs(np.clip(c, 0, 1) - np.clip(n, 0, 1)).max(axis=2) * 255
    assert worst.max() <= 1.0, f"{int((worst > 1).sum())} pixels differ, up to {worst.max():.0f}/255"


@requires_core
@pytest.mark.parametrize("move", ["9e15 0 0", "0 0 9e15", "9e15 0 9e15"])
def test_c_and_numpy_agree_with_the_floor_moved_far_along_itself(move):
    """The bundled glass scene with its floor moved 9e15 along its own plane: generic ray origins 9e15 out,
    where an ulp is 1 (6 pixels up to 9/255 apart before)."""
    from pathlib import Path

    path = Path(__file__).resolve().parents[1] / "scenes" / "glass.sdl"
    text = path.read_text().replace("rotate -90 1 0 0  plane", f"translate {move} rotate -90 1 0 0  plane")
    assert text != path.read_text()
    c = tracer.render(tracer.parse_sdl(text, base_dir=path.parent), 64, 48, backend="c").image
    n = tracer.render(tracer.parse_sdl(text, base_dir=path.parent), 64, 48, backend="numpy").image
    worst = np.abs(np.clip(c, 0, 1) - np.clip(n, 0, 1)).max(axis=2) * 255
    assert worst.max() <= 1.0, f"{int((worst > 1).sum())} pixels differ, up to {worst.max():.0f}/255"
