import os

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st

from tracer.errors import SDLError
from tracer.meshio import format_3vn, read_3vn, write_3vn, write_text_atomic
from tracer.model import MeshData

# A square pyramid: 5 vertices, 5 normals (one per face), a quad base and four triangles.
PYRAMID = """5 5 5
-1 -1 0
1 -1 0
1 1 0
-1 1 0
0 0 1
0 0 -1
0 -0.707 0.707
0.707 0 0.707
0 0.707 0.707
-0.707 0 0.707
4 3 2 1 0 0 0 0 0
3 0 1 4 1 1 1
3 1 2 4 2 2 2
3 2 3 4 3 3 3
3 3 0 4 4 4 4
"""


def write(tmp_path, text, name="m.3vn"):
    path = tmp_path / name
    path.write_text(text)
    return path


def test_reads_vertices_normals_and_faces(tmp_path):
    mesh = read_3vn(write(tmp_path, PYRAMID))
    assert mesh.vertices.shape == (5, 3) and mesh.vertices.dtype == np.float64
    assert mesh.vertices[4].tolist() == [0, 0, 1]
    assert mesh.normals[1].tolist() == [0, -0.707, 0.707]
    assert mesh.faces[0] == ((3, 2, 1, 0), (0, 0, 0, 0))
    assert mesh.faces[4] == ((3, 0, 4), (4, 4, 4))
    assert len(mesh.faces) == 5
    assert mesh.origin.endswith("m.3vn")
    tri_v, _ = mesh.triangles()
    assert len(tri_v) == 2 + 4  # the quad fans into two triangles


def test_line_breaks_carry_no_meaning(tmp_path):
    squashed = " ".join(PYRAMID.split())
    spread = "\n\n".join(PYRAMID.split()) + "\n\n\n"
    a = read_3vn(write(tmp_path, squashed, "a.3vn"))
    b = read_3vn(write(tmp_path, spread, "b.3vn"))
    c = read_3vn(write(tmp_path, PYRAMID.replace("\n", "\r\n").replace(" ", "\t"), "c.3vn"))
    for mesh in (b, c):
        assert np.array_equal(mesh.vertices, a.vertices)
        assert np.array_equal(mesh.normals, a.normals)
        assert mesh.faces == a.faces


def test_round_trip(tmp_path):
    mesh = read_3vn(write(tmp_path, PYRAMID))
    out = tmp_path / "out.3vn"
    write_3vn(mesh, out)
    again = read_3vn(out)
    assert np.array_equal(again.vertices, mesh.vertices)
    assert np.array_equal(again.normals, mesh.normals)
    assert again.faces == mesh.faces


finite = st.floats(min_value=-1e6, max_value=1e6, allow_nan=False)


@st.composite
def meshes(draw):
    nv = draw(st.integers(3, 8))
    nn = draw(st.integers(1, 4))
    vertices = np.array(draw(st.lists(finite, min_size=3 * nv, max_size=3 * nv))).reshape(nv, 3)
    normals = np.array(draw(st.lists(finite, min_size=3 * nn, max_size=3 * nn))).reshape(nn, 3)
    faces = []
    for _ in range(draw(st.integers(0, 5))):
        n = draw(st.integers(3, 6))
        faces.append((tuple(draw(st.lists(st.integers(0, nv - 1), min_size=n, max_size=n))),
                      tuple(draw(st.lists(st.integers(0, nn - 1), min_size=n, max_size=n)))))
    return MeshData(vertices, normals, faces)


@settings(max_examples=50, deadline=None)
@given(meshes())
def test_random_meshes_round_trip_exactly(tmp_path_factory, mesh):
    path = tmp_path_factory.mktemp("rt") / "r.3vn"
    write_3vn(mesh, path)
    again = read_3vn(path)
    assert np.array_equal(again.vertices, mesh.vertices)
    assert np.array_equal(again.normals, mesh.normals)
    assert again.faces == mesh.faces


def test_faces_without_normals_get_a_face_normal(tmp_path):
    square = MeshData(np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float), np.zeros((0, 3)),
                      [((0, 1, 2, 3), ())])
    path = tmp_path / "sq.3vn"
    write_3vn(square, path)
    again = read_3vn(path)
    assert again.faces == [((0, 1, 2, 3), (0, 0, 0, 0))]
    assert np.allclose(again.normals, [[0, 0, 1]])  # counter-clockwise seen from +z


def test_write_refuses_non_finite_numbers_and_leaves_nothing(tmp_path):
    bad = MeshData(np.array([[0, 0, np.nan], [1, 0, 0], [0, 1, 0]]), np.zeros((0, 3)), [((0, 1, 2), ())])
    with pytest.raises(ValueError):
        write_3vn(bad, tmp_path / "bad.3vn")
    assert os.listdir(tmp_path) == []


def test_atomic_write_keeps_old_file_when_writing_fails(tmp_path, monkeypatch):
    target = tmp_path / "keep.txt"
    target.write_text("old")

    def boom(*args):
        raise OSError("disk full")

    monkeypatch.setattr(os, "replace", boom)
    with pytest.raises(OSError):
        write_text_atomic(target, "new")
    assert target.read_text() == "old"
    assert os.listdir(tmp_path) == ["keep.txt"]


def test_format_is_counts_then_data():
    mesh = MeshData(np.array([[0, 0, 0], [1, 0, 0], [0, 1.5, 0]]), np.array([[0, 0, 1.0]]),
                    [((0, 1, 2), (0, 0, 0))])
    assert format_3vn(mesh).split("\n") == ["3 1 1", "0 0 0", "1 0 0", "0 1.5 0", "0 0 1", "3 0 1 2 0 0 0", ""]


# --- errors: each names the file and the line -----------------------------------------------------------

def error_for(tmp_path, text):
    path = write(tmp_path, text, "bad.3vn")
    with pytest.raises(SDLError) as info:
        read_3vn(path)
    return info.value


def test_bad_number_names_file_line_and_word(tmp_path):
    err = error_for(tmp_path, PYRAMID.replace("1 1 0", "1 oops 0"))
    assert err.file.endswith("bad.3vn") and err.line == 4 and err.token == "oops"
    assert "bad.3vn:4:" in str(err)


def test_nan_is_not_a_number(tmp_path):
    err = error_for(tmp_path, PYRAMID.replace("0 0 1\n", "0 0 nan\n", 1))
    assert err.line == 6 and err.token == "nan"


def test_vertex_index_out_of_range(tmp_path):
    err = error_for(tmp_path, PYRAMID.replace("3 1 2 4 2 2 2", "3 1 2 5 2 2 2"))
    assert err.line == 14 and err.token == "5" and "out of range" in err.message
    assert err.expected == "0..4"


def test_normal_index_out_of_range(tmp_path):
    err = error_for(tmp_path, PYRAMID.replace("3 2 3 4 3 3 3", "3 2 3 4 3 -1 3"))
    assert err.line == 15 and err.token == "-1"


def test_face_with_fewer_than_three_vertices(tmp_path):
    err = error_for(tmp_path, "3 1 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n2 0 1 0 0\n")
    assert err.line == 6 and "at least 3" in err.message


def test_truncated_file(tmp_path):
    err = error_for(tmp_path, PYRAMID[:PYRAMID.rindex("3 3 0 4")])
    assert "ends early" in err.message
    err = error_for(tmp_path, "5 5")
    assert "ends early" in err.message and err.line == 1


def test_truncated_last_face(tmp_path):
    err = error_for(tmp_path, "3 1 1\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n4 0 1 2 1\n0 0 0\n")
    # A quad promises four normal indices; only three are there.
    assert "ends early" in err.message and "normal index of face 0" in err.message
    assert err.line == 7  # the last line of the file


def test_extra_data_after_last_face(tmp_path):
    err = error_for(tmp_path, PYRAMID + "7\n")
    assert err.line == 17 and err.token == "7"


def test_counts_must_be_whole_numbers(tmp_path):
    err = error_for(tmp_path, "2.5 0 0")
    assert err.line == 1 and err.token == "2.5"
    err = error_for(tmp_path, "-1 0 0")
    assert err.token == "-1"


def test_empty_file(tmp_path):
    err = error_for(tmp_path, "")
    assert "ends early" in err.message


def test_indices_into_empty_normal_list(tmp_path):
    err = error_for(tmp_path, "3 0 1\n0 0 0\n1 0 0\n0 1 0\n3 0 1 2 0 0 0\n")
    assert err.line == 5 and "no normals" in err.message


def test_missing_file_is_an_sdl_error(tmp_path):
    with pytest.raises(SDLError) as info:
        read_3vn(tmp_path / "nope.3vn")
    assert "nope.3vn" in str(info.value)


# ---------------------------------------------------------------- the bulk reader against the word reader

from tracer import meshio  # noqa: E402

number_words = st.one_of(
    st.integers(-10**6, 10**6).map(str),
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(repr),
    st.floats(allow_nan=False, allow_infinity=False, width=64).map(lambda x: f"{x:.17e}"),
    st.floats(-1e3, 1e3).map(lambda x: f"{x:.3f}"),
    st.sampled_from(["0", "-0", "+5", ".5", "5.", "-.25e-3", "1E+2", "00012", "0.000", "123456789012345678901234",
                     "1e-400", "4.9e-324", "9007199254740993", "0.1000000000000000055511151231257827"]),
)


@settings(max_examples=60, deadline=None)
@given(st.lists(number_words, min_size=1, max_size=40), st.lists(st.sampled_from([" ", "\n", "\t", "\r\n", "  \x0b"]),
                                                                   min_size=40, max_size=40))
def test_bulk_numbers_are_pythons_floats(words, gaps):
    text = "".join(w + g for w, g in zip(words, gaps))
    values = meshio._bulk_numbers(text.encode())
    assert values is not None
    assert [v.hex() for v in values.tolist()] == [float(w).hex() for w in words]


@pytest.mark.parametrize("word", ["1e", "--1", "1.2.3", "e5", ".", "-", "+", "1e999", "nan", "inf", "0x10", "1-2",
                                  "3,5", "1e+", "\u00a05".encode("utf-8").decode("latin-1")])
def test_bulk_numbers_refuse_what_is_not_a_number(word):
    assert meshio._bulk_numbers(f"1 2 {word} 4\n".encode("latin-1")) is None


def test_numpy_scanner_agrees_with_the_c_one(monkeypatch):
    text = b"3 -0 .5 5. +7 1E+2 -.25e-3 0.1 123456789012345678901234 1e-400\n"
    expected = meshio._bulk_numbers(text)
    import tracer.native as native
    monkeypatch.setattr(native, "load_error", "pretend there is no C core")
    assert np.array_equal(meshio._bulk_numbers(text), expected)
    for bad in (b"1 2 1e 3", b"1 --2", b"1 1.2.3", b"1 nan", b"1 1e999"):
        assert meshio._bulk_numbers(bad) is None


def _read_both(path):
    """The bulk reader's mesh and the word reader's, for the same file."""
    fast = meshio._read_in_bulk(path.read_bytes(), str(path))
    slow = meshio._read_words(path.read_text(), str(path))
    return fast, slow


def test_bulk_reader_gives_the_word_readers_mesh(tmp_path):
    for text in (PYRAMID, PYRAMID.replace("\n", " "), "3 1 1\n0 0 0 1 0 0 0 1 0\n0 0 1\n3 0 1 2 0 0 0\n",
                 "0 0 0\n"):
        fast, slow = _read_both(write(tmp_path, text))
        assert fast is not None
        assert np.array_equal(fast.vertices, slow.vertices) and np.array_equal(fast.normals, slow.normals)
        assert list(fast.faces) == slow.faces
        for a, b in zip(fast.triangles(), slow.triangles()):
            assert np.array_equal(a, b)


def test_c_and_numpy_bulk_readers_read_the_same_mesh(tmp_path, monkeypatch):
    shared = "4 4 2\n0 0 0 1 0 0 0 1 0 0 0 1\n0 0 1 0 0 1 0 0 1 0 0 1\n3 0 1 2 0 1 2\n3.0 0 2 3 0 2 3\n"
    texts = (PYRAMID, "0 0 0\n", shared, PYRAMID.replace("4 3 2 1 0 0 0 0 0", "4 3 2 1 0 4 3 2 1"))
    if meshio._native() is None:
        pytest.skip("no C core")
    in_c = [meshio._read_in_bulk(write(tmp_path, text).read_bytes(), "m") for text in texts]
    monkeypatch.setattr(meshio, "_native", lambda: None)
    in_numpy = [meshio._read_in_bulk(write(tmp_path, text).read_bytes(), "m") for text in texts]
    for a, b in zip(in_c, in_numpy):
        assert a is not None and b is not None
        assert np.array_equal(a.vertices, b.vertices) and np.array_equal(a.normals, b.normals)
        assert a.faces == b.faces and a.faces.vertex_index.dtype == b.faces.vertex_index.dtype == np.int32
    # Normal k of vertex k: one index array, not two, from either reader.
    for mesh in (in_c[2], in_numpy[2]):
        assert mesh.faces.normal_index is mesh.faces.vertex_index
    assert in_c[0].faces.normal_index is not in_c[0].faces.vertex_index


@pytest.mark.parametrize("piece", [1, 5, 64])
def test_the_c_reader_reads_a_file_in_pieces_of_any_size(tmp_path, monkeypatch, piece):
    """Words cut by the pieces' ends are read whole; a bad word is found wherever the pieces end."""
    native = meshio._native()
    if native is None:
        pytest.skip("no C core")
    path = write(tmp_path, PYRAMID)
    whole = meshio._read_in_bulk(path.read_bytes(), "m")
    monkeypatch.setattr(native, "SCAN_PIECE", piece)
    with open(path, "rb") as handle:
        pieces = meshio._read_in_bulk(handle, "m")
    assert np.array_equal(pieces.vertices, whole.vertices) and np.array_equal(pieces.normals, whole.normals)
    assert pieces.faces == whole.faces
    for bad in (PYRAMID.replace("0.707 0 0.707", "0.707 0 0.7x07"), PYRAMID + "3\n", PYRAMID.replace("3 3 0 4 4 4 4", "3 3 0 4 4 4")):
        assert meshio._read_in_bulk(bad.encode(), "m") is None


@pytest.mark.parametrize("reader", ["c", "numpy"])
@pytest.mark.parametrize("text", [
    PYRAMID.replace("3 0 1 4 1 1 1", "3 0 1 9 1 1 1"),  # vertex index out of range
    PYRAMID.replace("3 0 1 4 1 1 1", "2 0 1 1 1"),  # a face of two corners
    PYRAMID.replace("3 0 1 4 1 1 1", "3 0 1.5 4 1 1 1"),  # an index that is not whole
    PYRAMID + "7\n",  # data after the last face
    PYRAMID.replace("5 5 5", "5 5 6"),  # a face missing
    PYRAMID.replace("5 5 5", "5 5 5.5"),
    PYRAMID.replace("5 5 5", "5 0 5"),  # normal indices into an empty list
    PYRAMID.replace("-1 -1 0", "-1 -1 x"),  # a word that is not a number
])
def test_bulk_reader_leaves_bad_files_to_the_word_reader(tmp_path, monkeypatch, reader, text):
    if reader == "numpy":
        monkeypatch.setattr(meshio, "_native", lambda: None)
    elif meshio._native() is None:
        pytest.skip("no C core")
    path = write(tmp_path, text)
    assert meshio._read_in_bulk(path.read_bytes(), str(path)) is None
    with pytest.raises(SDLError) as err:
        read_3vn(path)
    assert str(path) in str(err.value)


def test_a_byte_order_mark_is_dropped_and_errors_still_name_the_line(tmp_path):
    path = tmp_path / "bom.3vn"
    path.write_bytes(b"\xef\xbb\xbf" + PYRAMID.encode())
    assert len(read_3vn(path).faces) == 5
    path.write_bytes(b"\xef\xbb\xbf" + PYRAMID.replace("0 0 1\n", "0 0 x\n", 1).encode())
    with pytest.raises(SDLError) as err:
        read_3vn(path)
    assert ":6" in str(err.value)
