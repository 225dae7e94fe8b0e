"""UsdGeom.Mesh prims as :class:`tracer.model.MeshData`: ours exactly, anyone's as polygons.

The functions take the stage reader (``tracer.usd.reader``) for its time code, attribute access and
messages (``note`` for approximations, ``problem`` for what cannot be read).
"""
from __future__ import annotations

from typing import Optional

import numpy as np

from ..errors import SceneError
from ..model import MeshData
from . import common as C


def sdl_mesh(reader, prim) -> Optional[MeshData]:
    """A mesh we wrote: vertices and normals as doubles, the .3vn normal indices, faces from USD."""
    key = str(prim.GetPath())
    vertices = np.array(reader.get(prim, C.A_MESH_POINTS), dtype=np.float64).reshape(-1, 3)
    normals = np.array(reader.get(prim, C.A_MESH_NORMALS, []), dtype=np.float64).reshape(-1, 3)
    corners = [int(i) for i in reader.get(prim, C.A_MESH_NORMAL_INDICES, [])]
    mesh = reader.UsdGeom.Mesh(prim)
    counts = [int(n) for n in mesh.GetFaceVertexCountsAttr().Get(reader.time)]
    indices = [int(i) for i in mesh.GetFaceVertexIndicesAttr().Get(reader.time)]
    if sum(counts) != len(indices) or len(corners) != len(indices):
        reader.note(prim, "sdl:meshNormalIndices does not match the faces: read as a plain USD mesh")
        return usd_mesh(reader, prim)
    faces, at = [], 0
    for n in counts:
        verts = tuple(indices[at:at + n])
        norms = tuple(corners[at:at + n])
        faces.append((verts, () if all(i < 0 for i in norms) else norms))
        at += n
    if any(not 0 <= v < len(vertices) for f in faces for v in f[0]) or \
            any(not 0 <= i < len(normals) for f in faces for i in f[1]):
        raise SceneError("a face index is out of range")
    return _checked(reader, prim, MeshData(vertices, normals, faces, origin=f"{reader.file}<{key}>",
                                           corner_uvs=_our_uvs(reader, prim, len(indices))))


def _checked(reader, prim, mesh: MeshData) -> Optional[MeshData]:
    """The mesh, unless its numbers cannot be traced (then the reader's problem, and None)."""
    problem = mesh.coordinate_problem()
    if problem is None:
        return mesh
    reader.problem(prim, problem)
    return None


def _our_uvs(reader, prim, n_corners: int) -> Optional[np.ndarray]:
    """Our exact corner_uvs, unless primvars:st was changed in another tool since (then its values)."""
    exact = reader.get(prim, C.A_MESH_UVS)
    found = _texture_coordinates(reader, prim, n_corners, list(range(n_corners)), list(range(n_corners)))
    if exact is None or len(exact) != n_corners:
        return found
    exact = np.array(exact, dtype=np.float64).reshape(-1, 2)
    if found is not None and not np.array_equal(exact.astype(np.float32), found.astype(np.float32)):
        return found
    return exact


def _texture_coordinates(reader, prim, n_points_or_corners: int, corners: list[int],
                         vertices: list[int]) -> Optional[np.ndarray]:
    """(len(corners), 2) texture coordinates of these face corners (their places among all the faces'
    corners, and their vertices) from the mesh's ``st`` primvar (else its first texCoord2f one): per corner
    (faceVarying) or per point (vertex), indexed or not; None where it has none that fits (with a note)."""
    UsdGeom = reader.UsdGeom
    primvars = UsdGeom.PrimvarsAPI(prim)
    primvar = primvars.GetPrimvar("st")
    if not (primvar and primvar.HasAuthoredValue()):
        candidates = [p for p in primvars.GetPrimvars() if p.HasAuthoredValue()
                      and p.GetTypeName().role == reader.Sdf.ValueTypeNames.TexCoord2f.role
                      and p.GetTypeName().isArray]
        if not candidates:
            return None
        primvar = candidates[0]
    values = primvar.ComputeFlattened(reader.time)
    if values is None or len(values) == 0:
        return None
    uvs = np.array(values, dtype=np.float64).reshape(-1, 2)
    interpolation = primvar.GetInterpolation()
    if interpolation == UsdGeom.Tokens.faceVarying:
        pick = corners
    elif interpolation in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
        pick = vertices
    else:
        reader.note(prim, f"its texture coordinates are {interpolation}: left out")
        return None
    if pick and (max(pick) >= len(uvs)):
        reader.note(prim, f"its texture coordinates ({len(uvs)}, {interpolation}) do not fit the mesh: left out")
        return None
    return uvs[pick]


def usd_mesh(reader, prim) -> Optional[MeshData]:
    """Any UsdGeom.Mesh: polygons (holes left out), normals if it has them, left-handed faces turned."""
    UsdGeom = reader.UsdGeom
    mesh = UsdGeom.Mesh(prim)
    points = mesh.GetPointsAttr().Get(reader.time)
    counts = mesh.GetFaceVertexCountsAttr().Get(reader.time)
    indices = mesh.GetFaceVertexIndicesAttr().Get(reader.time)
    if points is None or counts is None or indices is None or len(counts) == 0:
        reader.problem(prim, "mesh without points or faces")
        return None
    vertices = np.array(points, dtype=np.float64).reshape(-1, 3)
    counts = [int(n) for n in counts]
    indices = [int(i) for i in indices]
    if sum(counts) != len(indices) or any(not 0 <= i < len(vertices) for i in indices):
        reader.problem(prim, "faceVertexCounts/faceVertexIndices do not fit its points")
        return None
    normals, normal_of = _normals(reader, prim, mesh, len(vertices), len(counts), len(indices))
    holes = set(int(h) for h in (mesh.GetHoleIndicesAttr().Get(reader.time) or []))
    left_handed = str(mesh.GetOrientationAttr().Get(reader.time)) == UsdGeom.Tokens.leftHanded
    faces, kept_corners, at, skipped = [], [], 0, 0
    for f, n in enumerate(counts):
        corners = range(at, at + n)
        at += n
        if f in holes:
            continue
        if n < 3:
            skipped += 1
            continue
        verts = tuple(indices[c] for c in corners)
        norms = tuple(normal_of(f, c, indices[c]) for c in corners) if normal_of else ()
        order = list(corners)
        if left_handed:
            verts, norms, order = verts[::-1], norms[::-1], order[::-1]
        faces.append((verts, norms))
        kept_corners += order
    if skipped:
        reader.note(prim, f"{skipped} faces with fewer than 3 vertices left out")
    if not faces:
        return None
    uvs = _texture_coordinates(reader, prim, len(indices), kept_corners, [indices[c] for c in kept_corners])
    return _checked(reader, prim, MeshData(vertices, normals, faces, origin=f"{reader.file}<{prim.GetPath()}>",
                                           corner_uvs=uvs))


def _normals(reader, prim, mesh, n_points: int, n_faces: int, n_corners: int):
    """(normals (N, 3), function (face, corner, vertex) -> normal index), or an empty list and None."""
    UsdGeom = reader.UsdGeom
    primvar = UsdGeom.PrimvarsAPI(prim).GetPrimvar("normals")
    if primvar and primvar.HasAuthoredValue():
        values = primvar.Get(reader.time)
        interpolation = primvar.GetInterpolation()
        indices = primvar.GetIndices(reader.time) if primvar.IsIndexed() else None
    else:
        values = mesh.GetNormalsAttr().Get(reader.time)
        interpolation = mesh.GetNormalsInterpolation()
        indices = None
    if values is None or len(values) == 0:
        return np.zeros((0, 3)), None
    normals = np.array(values, dtype=np.float64).reshape(-1, 3)
    lookup = [int(i) for i in indices] if indices is not None else None
    expected = {UsdGeom.Tokens.vertex: n_points, UsdGeom.Tokens.varying: n_points,
                UsdGeom.Tokens.faceVarying: n_corners, UsdGeom.Tokens.uniform: n_faces,
                UsdGeom.Tokens.constant: 1}.get(interpolation)
    count = len(lookup) if lookup is not None else len(normals)
    if expected is None or count < expected or (lookup and any(not 0 <= i < len(normals) for i in lookup)):
        reader.note(prim, f"its normals ({count}, {interpolation}) do not fit the mesh: flat normals used")
        return np.zeros((0, 3)), None
    if interpolation in (UsdGeom.Tokens.vertex, UsdGeom.Tokens.varying):
        pick = lambda f, c, v: v  # noqa: E731
    elif interpolation == UsdGeom.Tokens.faceVarying:
        pick = lambda f, c, v: c  # noqa: E731
    elif interpolation == UsdGeom.Tokens.uniform:
        pick = lambda f, c, v: f  # noqa: E731
    else:
        pick = lambda f, c, v: 0  # noqa: E731
    if lookup is not None:
        return normals, lambda f, c, v: lookup[pick(f, c, v)]
    return normals, pick
