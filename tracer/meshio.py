"""Read and write the book's ``.3vn`` polygon mesh format.

Layout (docs/sdl.md): ``numVerts numNorms numFaces``, then numVerts vertices ``x y z``, numNorms normals
``nx ny nz``, then per face its vertex count n, n vertex indices and n normal indices, all 0-based.  Line
breaks carry no meaning: any white space separates numbers, so the reader works on a stream of numbers and
only keeps line numbers for its messages.
"""
from __future__ import annotations

import io
import os
import warnings
from pathlib import Path
from typing import BinaryIO, Iterator, Optional, Union

import numpy as np

from .atomic import writing
from .errors import SDLError, WriteError
from .model import FaceList, MeshData
from .sdl.lexer import to_float
from .userfiles import open_regular

PathLike = Union[str, "os.PathLike[str]"]


def read_3vn(path: PathLike) -> MeshData:
    """Read a ``.3vn`` file.  Any problem in its content raises SDLError naming the file and line.

    The numbers are read in bulk (see :func:`_read_in_bulk`); only when that finds something wrong does
    the word-by-word reader re-read the file, to name the problem and where it is."""
    name = os.fspath(path)
    try:
        with open_regular(path, "mesh file") as handle:
            mesh = _read_in_bulk(handle, name)
            if mesh is None:
                handle.seek(0)
                data = handle.read()
    except OSError as exc:
        raise SDLError(f"cannot read mesh file: {exc.strerror or exc}", file=name) from exc
    if mesh is None:
        # Course files are sometimes saved with odd encodings; a bad byte just becomes a bad number (as
        # userfiles.read_text decodes: a byte-order mark dropped).
        mesh = _read_words(data.decode("utf-8-sig", errors="replace"), name)
    problem = mesh.coordinate_problem()
    if problem is not None:
        raise SDLError(problem, file=name)
    return mesh


#: Counts beyond this are certainly corrupt, and would exhaust memory before the check.
_BIG = 2**31 - 1


def _read_in_bulk(source: Union[bytes, BinaryIO], name: str) -> Optional[MeshData]:
    """The mesh, if the file (its bytes, or a binary file at its start) is a well-formed ``.3vn`` of plain
    decimal numbers; None for anything else (which :func:`_read_words` then reports).  The C core reads the
    file a few megabytes at a time, straight into the mesh's arrays; without it, all of a file's numbers are
    read at once into one array and cut into vertices, normals and faces with array operations: no Python
    object per number either way."""
    handle = io.BytesIO(source) if isinstance(source, (bytes, bytearray)) else source
    native = _native()
    if native is not None:
        arrays = native.scan_3vn(handle)
        if arrays is None:
            return None
        vertices, normals, sizes, vertex_index, normal_index = arrays
        if np.array_equal(vertex_index, normal_index):  # normal k of vertex k: one array (see FaceList)
            normal_index = vertex_index
        return MeshData(vertices=vertices, normals=normals, faces=FaceList(sizes, vertex_index, normal_index),
                        origin=name)
    values = _bulk_numbers(handle.read())
    if values is None or len(values) < 3:
        return None
    head = values[:3]
    if not (np.all(head == np.trunc(head)) and np.all(head >= 0) and np.all(head <= _BIG)):
        return None
    num_verts, num_norms, num_faces = (int(x) for x in head)
    body = 3 + 3 * (num_verts + num_norms)
    if len(values) < body + 7 * num_faces:
        return None
    vertices = values[3:3 + 3 * num_verts].reshape(num_verts, 3).copy()
    normals = values[3 + 3 * num_verts:body].reshape(num_norms, 3).copy()
    faces = _bulk_faces(values[body:], num_faces, num_verts, num_norms)
    if faces is None:
        return None
    return MeshData(vertices=vertices, normals=normals, faces=faces, origin=name)


def _bulk_faces(words: np.ndarray, num_faces: int, num_verts: int, num_norms: int) -> Optional[FaceList]:
    """The face records (n, n vertex indices, n normal indices; nothing after the last), or None if they
    are not exactly that with whole numbers in range."""
    if num_faces == 0:
        return FaceList([], np.zeros(0, np.int32), np.zeros(0, np.int32)) if len(words) == 0 else None
    first = words[0]
    width = 1 + 2 * int(first) if first == int(first) and 3 <= first <= _BIG else 0
    if width and len(words) == num_faces * width and np.all(words[::width] == first):
        table = words.reshape(num_faces, width)  # every face has the same number of corners: one reshape
        n = width // 2
        sizes = np.full(num_faces, n, dtype=np.int64)
        vertex_index, normal_index = table[:, 1:1 + n].ravel(), table[:, 1 + n:].ravel()
    else:
        sizes = np.empty(num_faces, dtype=np.int64)
        starts = np.empty(num_faces, dtype=np.int64)
        pos = 0
        for f in range(num_faces):  # mixed polygons: each record's length depends on the one before
            if pos >= len(words):
                return None
            n = words[pos]
            if not (n == int(n) and 3 <= n and pos + 1 + 2 * n <= len(words)):
                return None
            sizes[f], starts[f] = n, pos + 1
            pos += 1 + 2 * int(n)
        if pos != len(words):
            return None
        corner = np.repeat(starts, sizes) + (np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes))
        vertex_index, normal_index = words[corner], words[corner + np.repeat(sizes, sizes)]
    for index, count in ((vertex_index, num_verts), (normal_index, num_norms)):
        if not (np.all(index == np.trunc(index)) and np.all(index >= 0) and np.all(index < count)):
            return None
    vertex_index, normal_index = vertex_index.astype(np.int32), normal_index.astype(np.int32)
    if np.array_equal(vertex_index, normal_index):  # normal k of vertex k, as most exporters write: one array
        normal_index = vertex_index
    return FaceList(sizes, vertex_index, normal_index)


def _bulk_numbers(data: bytes) -> Optional[np.ndarray]:
    """Every white-space separated number of the file, or None if it holds anything else (a word that
    NUMBER_RE does not take, a non-finite value, a byte outside ASCII).  The C core's scanner when it is
    built; else NumPy's, after checking that only number characters and white space occur, that it read to
    the end without a complaint and as many numbers as there are words."""
    native = _native()
    if native is not None:
        return native.scan_numbers(data)
    raw = np.frombuffer(data, dtype=np.uint8)
    allowed = np.zeros(256, dtype=bool)
    allowed[list(b"0123456789+-.eE \t\n\r\x0b\x0c")] = True
    if not allowed[raw].all():
        return None
    space = ~allowed[raw] | (raw == 32) | ((raw >= 9) & (raw <= 13))
    words = int(np.count_nonzero(~space[1:] & space[:-1])) + int(len(raw) > 0 and not space[0])
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")  # at a malformed word NumPy warns and stops
        values = np.fromstring(data, dtype=np.float64, sep=" ")
    return values if not caught and len(values) == words and np.isfinite(values).all() else None


def _native():
    """tracer.native when the C core is built, else None."""
    try:
        from . import native  # deferred: the C core is loaded (in a checkout: compiled) by the first mesh file
    except ImportError:
        return None
    return native if native.load_error is None else None


class _Numbers:
    """The white-space separated words of a file, read one at a time as numbers, with line numbers."""

    def __init__(self, text: str, file: str):
        self.file = file
        self.words: list[tuple[str, int]] = [
            (word, line) for line, text_line in enumerate(text.split("\n"), start=1) for word in text_line.split()]
        self.pos = 0
        self.last_line = max(1, text.count("\n") + (0 if text.endswith("\n") else 1))

    def error(self, message: str, line: int, token=None, expected=None) -> SDLError:
        return SDLError(message, file=self.file, line=line, token=token, expected=expected)

    def _next_word(self, what: str) -> tuple[str, int]:
        if self.pos >= len(self.words):
            raise self.error(f"file ends early: expected {what}", self.last_line)
        word = self.words[self.pos]
        self.pos += 1
        return word

    def real(self, what: str, index: int) -> float:
        word, line = self._next_word(f"{what} {index}")
        value = to_float(word)
        if value is None:
            raise self.error(f"expected a number for {what} {index}", line, token=word)
        return value

    def integer(self, what: str, low: int, high: int) -> int:
        """An integer in [low, high]; a number written as a float with no fraction ('3.0') is accepted."""
        word, line = self._next_word(what)
        value = to_float(word)
        if value is None or not value.is_integer():
            raise self.error(f"expected a whole number for {what}", line, token=word)
        if not low <= value <= high:
            raise self.error(f"{what} out of range", line, token=word, expected=f"{low}..{high}")
        return int(value)

    def index(self, what: str, count: int, things: str) -> int:
        """A 0-based index into a list of ``count`` things."""
        if count == 0:
            word, line = self._next_word(what)
            raise self.error(f"{what} out of range: the file has no {things}", line, token=word)
        return self.integer(what, 0, count - 1)

    def leftover(self) -> Iterator[tuple[str, int]]:
        return iter(self.words[self.pos:])


def _read_words(text: str, name: str) -> MeshData:
    """The word-by-word reader: slow, and exact about where a problem is."""
    numbers = _Numbers(text, name)
    big = _BIG
    num_verts = numbers.integer("the vertex count", 0, big)
    num_norms = numbers.integer("the normal count", 0, big)
    num_faces = numbers.integer("the face count", 0, big)
    # Cheap sanity check before allocating: each vertex and normal needs 3 words, each face at least 7.
    if 3 * (num_verts + num_norms) + 7 * num_faces > len(numbers.words):
        raise numbers.error("file ends early: the counts at its start promise more numbers than it holds",
                            numbers.last_line)

    vertices = np.array([numbers.real("vertex", i) for i in range(num_verts) for _ in range(3)],
                        dtype=np.float64).reshape(num_verts, 3)
    normals = np.array([numbers.real("normal", i) for i in range(num_norms) for _ in range(3)],
                       dtype=np.float64).reshape(num_norms, 3)
    faces: list[tuple[tuple[int, ...], tuple[int, ...]]] = []
    for f in range(num_faces):
        n = numbers.integer(f"the vertex count of face {f}", 0, big)
        if n < 3:
            line = numbers.words[numbers.pos - 1][1]
            raise numbers.error(f"face {f} has {n} vertices; a face needs at least 3", line, token=str(n))
        verts = tuple(numbers.index(f"a vertex index of face {f}", num_verts, "vertices") for _ in range(n))
        norms = tuple(numbers.index(f"a normal index of face {f}", num_norms, "normals") for _ in range(n))
        faces.append((verts, norms))
    for word, line in numbers.leftover():
        raise numbers.error("unexpected data after the last face (are the counts at the start right?)",
                            line, token=word)
    return MeshData(vertices=vertices, normals=normals, faces=faces, origin=name)


def _fmt(x: float) -> str:
    """Shortest text that reads back as exactly the same float."""
    x = float(x)
    if not np.isfinite(x):
        raise WriteError(f"cannot write the non-finite number {x!r} to a .3vn file")
    return str(int(x)) if x.is_integer() and abs(x) < 1e15 else repr(x)


def format_3vn(mesh: MeshData) -> str:
    """The ``.3vn`` text of a mesh.

    The format needs a normal index for every corner.  Faces that have none (a mesh with flat normals)
    get a computed face normal appended to the normal list, which shades the same way.
    """
    vertices = np.asarray(mesh.vertices, dtype=np.float64).reshape(-1, 3)
    normals = [tuple(n) for n in np.asarray(mesh.normals, dtype=np.float64).reshape(-1, 3)]
    face_lines = []
    for verts, norms in mesh.faces:
        if len(verts) < 3:
            raise WriteError(f"a face needs at least 3 vertices, not {len(verts)}")
        if len(norms) != len(verts):
            normals.append(tuple(_face_normal(vertices[list(verts)])))
            norms = (len(normals) - 1,) * len(verts)
        face_lines.append(" ".join(str(int(i)) for i in (len(verts), *verts, *norms)))
    lines = [f"{len(vertices)} {len(normals)} {len(face_lines)}"]
    lines += [" ".join(_fmt(c) for c in v) for v in vertices]
    lines += [" ".join(_fmt(c) for c in n) for n in normals]
    lines += face_lines
    return "\n".join(lines) + "\n"


def _face_normal(points: np.ndarray) -> np.ndarray:
    """Unit normal of a polygon by Newell's method (works for non-planar and non-convex polygons too)."""
    nxt = np.roll(points, -1, axis=0)
    normal = np.array([np.sum((points[:, 1] - nxt[:, 1]) * (points[:, 2] + nxt[:, 2])),
                       np.sum((points[:, 2] - nxt[:, 2]) * (points[:, 0] + nxt[:, 0])),
                       np.sum((points[:, 0] - nxt[:, 0]) * (points[:, 1] + nxt[:, 1]))])
    length = np.linalg.norm(normal)
    return normal / length if length > 0 else np.array([0.0, 0.0, 1.0])


def write_3vn(mesh: MeshData, path: PathLike) -> None:
    """Write a mesh as ``.3vn``, atomically: either the whole new file is there or the old one is untouched."""
    write_text_atomic(path, format_3vn(mesh))


def write_text_atomic(path: PathLike, text: str) -> None:
    """Write ``text`` (UTF-8, LF line ends) so that ``path`` holds either all of it or what it held
    before (see :func:`tracer.atomic.writing`)."""
    with writing(path, "w", encoding="utf-8", newline="\n") as out:
        out.write(text)
        out.flush()
        os.fsync(out.fileno())
