"""Polygon meshes as the scene model holds them: :class:`MeshData` (vertices, normals, faces, corner texture
coordinates) and :class:`FaceList`, its faces as flat arrays.  Below the rest of the model so that the
geometry that makes built-in meshes (tracer.geometry) needs nothing else of it; ``tracer.model`` exports both.
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Optional, Union

import numpy as np


class FaceList(Sequence):
    """Polygons kept as three flat arrays instead of a list of tuples (how big meshes are read: a million
    faces as tuples would take ~300 MB and seconds to make).  It reads like the list: item k is
    ``(vertex indices, normal indices)`` of face k, as tuples of ints.

    ``sizes`` (F,) corners per face; ``vertex_index`` (sum of sizes,) every face's vertex indices, face
    after face; ``normal_index`` the same for normals, or None when no face has normals (or the very same
    array as ``vertex_index`` when corner k of every face uses normal k of its vertex: one array, not two).
    Faces that all have one size (a triangle or quad mesh) keep only that size: ``sizes`` and ``offsets``
    are then made when asked for.
    """

    def __init__(self, sizes, vertex_index, normal_index=None):
        shared = normal_index is not None and normal_index is vertex_index
        self.vertex_index = np.asarray(vertex_index).reshape(-1)
        self.normal_index = (None if normal_index is None else self.vertex_index if shared
                             else np.asarray(normal_index).reshape(-1))
        sizes = np.asarray(sizes, dtype=np.int64).reshape(-1)
        self._count = len(sizes)
        self._uniform = int(sizes[0]) if len(sizes) and (sizes == sizes[0]).all() else None
        self._sizes = None if self._uniform is not None else sizes
        self._offsets = None if self._uniform is not None else np.concatenate([[0], np.cumsum(sizes)]).astype(np.int64)
        total = self._count * self._uniform if self._uniform is not None else self._offsets[-1]
        if total != len(self.vertex_index) or (
                self.normal_index is not None and len(self.normal_index) != len(self.vertex_index)):
            raise ValueError("face sizes do not match the number of indices")

    @property
    def sizes(self) -> np.ndarray:
        return np.full(self._count, self._uniform, dtype=np.int64) if self._sizes is None else self._sizes

    @property
    def offsets(self) -> np.ndarray:
        """(F + 1,) where each face's indices start, and the total."""
        if self._offsets is None:
            return np.arange(self._count + 1, dtype=np.int64) * self._uniform
        return self._offsets

    @property
    def uniform_size(self) -> Optional[int]:
        """The corner count of every face when they all have the same, else None."""
        return self._uniform

    def all_triangles(self) -> bool:
        return self._count == 0 or self._uniform == 3

    def arrays(self) -> list[np.ndarray]:
        """The arrays this list keeps (each once)."""
        kept = [self.vertex_index] + [a for a in (self._sizes, self._offsets) if a is not None]
        return kept + ([] if self.normal_index is None or self.normal_index is self.vertex_index
                       else [self.normal_index])

    def __len__(self) -> int:
        return self._count

    def __getitem__(self, k):
        if isinstance(k, slice):
            return [self[i] for i in range(*k.indices(len(self)))]
        k = range(len(self))[k]  # negative indices, IndexError
        if self._uniform is not None:
            a, b = k * self._uniform, (k + 1) * self._uniform
        else:
            a, b = int(self._offsets[k]), int(self._offsets[k + 1])
        verts = tuple(self.vertex_index[a:b].tolist())
        return verts, (() if self.normal_index is None else tuple(self.normal_index[a:b].tolist()))

    def __iter__(self):
        verts = self.vertex_index.tolist()
        norms = None if self.normal_index is None else self.normal_index.tolist()
        bounds = self.offsets.tolist()
        for a, b in zip(bounds[:-1], bounds[1:]):
            yield tuple(verts[a:b]), (() if norms is None else tuple(norms[a:b]))

    def __eq__(self, other) -> bool:
        if isinstance(other, FaceList):
            return (np.array_equal(self.sizes, other.sizes) and np.array_equal(self.vertex_index, other.vertex_index)
                    and (self.normal_index is None) == (other.normal_index is None)
                    and (self.normal_index is None or np.array_equal(self.normal_index, other.normal_index)))
        try:
            return len(self) == len(other) and all(a == tuple(map(tuple, b)) for a, b in zip(self, other))
        except TypeError:
            return NotImplemented

    __hash__ = None

    def triangle_corners(self) -> np.ndarray:
        """(T, 3) the corners (indices into ``vertex_index``: face after face) of the fan triangles of
        :meth:`triangles`, in its order."""
        fans = np.maximum(self.sizes - 2, 0)
        face = np.repeat(np.arange(len(self.sizes)), fans)
        k = np.arange(len(face)) - np.repeat(np.cumsum(fans) - fans, fans) + 1  # 1 .. size - 2 in each face
        start = self.offsets[:-1][face]
        return np.stack([start, start + k, start + k + 1], axis=1)

    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """MeshData.triangles() for these faces, without a Python loop over them."""
        corners = self.triangle_corners()
        tri_v = self.vertex_index[corners].astype(np.int64)
        tri_n = (np.full(tri_v.shape, -1, dtype=np.int64) if self.normal_index is None
                 else self.normal_index[corners].astype(np.int64))
        return tri_v.reshape(-1, 3), tri_n.reshape(-1, 3)


#: Largest size of a mesh vertex's or normal's coordinate.  Building and tracing a mesh adds coordinates
#: (centroids), subtracts them (edges, box sizes) and multiplies two such results (box areas, cross products):
#: within 1e150 all of these stay finite, beyond it they overflow to infinity, which a bounding-volume
#: hierarchy cannot split.
MAX_MESH_COORDINATE = 1e150


@dataclass
class MeshData:
    """A polygon mesh in generic coordinates.

    ``faces`` holds, per polygon, its vertex indices and its normal indices (same length, 0-based),
    as the ``.3vn`` format does.  ``normals`` may be empty: then flat face normals are used.
    """

    vertices: np.ndarray  # (V, 3) float64
    normals: np.ndarray  # (N, 3) float64
    faces: Union[list[tuple[tuple[int, ...], tuple[int, ...]]], FaceList]
    #: Where the data came from (a file path, or e.g. "built-in:icosahedron").
    origin: str = ""
    #: Texture coordinates per face corner, (C, 2) float64, or None: the corners of face 0, then of face 1,
    #: ... (C = the sum of the faces' sizes; Blender's loop UVs).  An image texture on a mesh that has them is
    #: looked up at the (u, v) interpolated at the hit, instead of the shape's own mapping.
    corner_uvs: Optional[np.ndarray] = None

    def triangle_corners(self) -> np.ndarray:
        """(T, 3) int64: for each triangle of :meth:`triangles`, its corners' places among all the faces'
        corners (face after face: the rows of ``corner_uvs``)."""
        if isinstance(self.faces, FaceList):
            return self.faces.triangle_corners()
        out: list[tuple[int, int, int]] = []
        start = 0
        for verts, _ in self.faces:
            out += [(start, start + k, start + k + 1) for k in range(1, len(verts) - 1)]
            start += len(verts)
        return np.asarray(out, dtype=np.int64).reshape(-1, 3)

    def corner_count(self) -> int:
        """How many face corners there are (the rows ``corner_uvs`` must have)."""
        if isinstance(self.faces, FaceList):
            return len(self.faces.vertex_index)
        return sum(len(verts) for verts, _ in self.faces)

    def coordinate_problem(self) -> Optional[str]:
        """Why the mesh's numbers cannot be traced (see MAX_MESH_COORDINATE), or None."""
        for what, values in (("vertex", self.vertices), ("normal", self.normals)):
            values = np.asarray(values, dtype=np.float64).reshape(-1, 3)
            bad = ~(np.abs(values) <= MAX_MESH_COORDINATE).all(axis=1)  # (NaN is bad too)
            if bad.any():
                index = int(np.argmax(bad))
                shown = ", ".join(f"{x:g}" for x in values[index].tolist())
                return (f"{what} {index} is ({shown}): a mesh's {what} coordinates must be finite and at most "
                        f"{MAX_MESH_COORDINATE:g} in size (the tracer adds and multiplies them)")
        return None

    def triangles(self) -> tuple[np.ndarray, np.ndarray]:
        """Fan-triangulate: (T, 3) vertex indices and (T, 3) normal indices (-1 where the face has none)."""
        if isinstance(self.faces, FaceList):
            return self.faces.triangles()
        tri_v: list[tuple[int, int, int]] = []
        tri_n: list[tuple[int, int, int]] = []
        for verts, norms in self.faces:
            norms = tuple(norms) if len(norms) == len(verts) else (-1,) * len(verts)
            for k in range(1, len(verts) - 1):
                tri_v.append((verts[0], verts[k], verts[k + 1]))
                tri_n.append((norms[0], norms[k], norms[k + 1]))
        return (np.asarray(tri_v, dtype=np.int64).reshape(-1, 3),
                np.asarray(tri_n, dtype=np.int64).reshape(-1, 3))
