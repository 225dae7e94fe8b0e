"""Blender meshes: building them from generic shapes, recognising them again, reading them as tracer meshes."""
from __future__ import annotations

import os
from typing import Optional

import bpy
import numpy as np

from .pure import primitives
from .tracer import model, shapes
from .tracer.compile import remember_digest
from .tracer.meshio import read_3vn
from .tracer.sdl.parser import builtin_mesh

#: Custom properties on a mesh that stands for a generic shape.
KIND, PARAM, FILE, MATRIX, HASH = "sdl_kind", "sdl_param", "sdl_mesh_file", "sdl_mesh_matrix", "sdl_hash"


def build_mesh(name: str, gm: primitives.GenericMesh) -> bpy.types.Mesh:
    mesh = bpy.data.meshes.new(name)
    loop_vertices = gm.loop_vertices
    totals = gm.loop_totals
    starts = np.concatenate([[0], np.cumsum(totals)[:-1]]).astype(np.int32) if len(totals) else totals
    mesh.vertices.add(len(gm.vertices))
    mesh.vertices.foreach_set("co", np.ascontiguousarray(gm.vertices, dtype=np.float32).ravel())
    mesh.loops.add(len(loop_vertices))
    mesh.loops.foreach_set("vertex_index", loop_vertices)
    mesh.polygons.add(len(totals))
    mesh.polygons.foreach_set("loop_start", starts)
    mesh.polygons.foreach_set("loop_total", totals)
    mesh.polygons.foreach_set("use_smooth", np.asarray(gm.smooth, dtype=bool))
    mesh.update(calc_edges=True)
    if gm.sharp_edges:
        edge_verts = np.empty(len(mesh.edges) * 2, dtype=np.int32)
        mesh.edges.foreach_get("vertices", edge_verts)
        wanted = {tuple(sorted(e)) for e in gm.sharp_edges}
        sharp = np.array([tuple(sorted(p)) in wanted for p in edge_verts.reshape(-1, 2).tolist()], dtype=bool)
        mesh.edges.foreach_set("use_edge_sharp", sharp)
    if hasattr(mesh, "use_auto_smooth"):  # Blender < 4.1: sharp edges and custom normals need it
        mesh.use_auto_smooth = True
        mesh.auto_smooth_angle = np.pi
    if gm.corner_normals is not None:
        try:
            mesh.normals_split_custom_set([tuple(n) for n in gm.corner_normals.tolist()])
        except (RuntimeError, TypeError, ValueError):
            pass  # shading only
    mesh.update()
    return mesh


def mesh_hash(mesh) -> str:
    co = np.empty(len(mesh.vertices) * 3, dtype=np.float32)
    mesh.vertices.foreach_get("co", co)
    loops = np.empty(len(mesh.loops), dtype=np.int32)
    mesh.loops.foreach_get("vertex_index", loops)
    totals = np.empty(len(mesh.polygons), dtype=np.int32)
    mesh.polygons.foreach_get("loop_total", totals)
    return primitives.geometry_hash(co, loops, totals)


def mark_generic(mesh, kind: str, parameters: tuple[float, ...], mesh_file: Optional[str],
                 mesh_matrix: np.ndarray) -> None:
    mesh[KIND] = kind
    mesh[PARAM] = primitives.stored_parameters(parameters)
    if mesh_file is not None:
        mesh[FILE] = mesh_file
    mesh[MATRIX] = [float(v) for v in np.asarray(mesh_matrix, dtype=np.float64).ravel()]
    mesh[HASH] = mesh_hash(mesh)


class GenericInfo:
    """What a mesh stands for, if it is an unedited generic shape."""

    def __init__(self, kind: str, parameters: tuple[float, ...], mesh_file: Optional[str], mesh_matrix: np.ndarray):
        self.kind = kind
        self.parameters = parameters
        self.mesh_file = mesh_file
        self.mesh_matrix = mesh_matrix


def generic_info(mesh, cache: Optional[dict] = None) -> Optional[GenericInfo]:
    """The generic shape ``mesh`` stands for, or None if it is not one or has been edited since."""
    if mesh is None or not isinstance(mesh, bpy.types.Mesh) or KIND not in mesh:
        return None
    key = mesh.as_pointer()
    if cache is not None and key in cache:
        return cache[key]
    info = None
    kind = str(mesh[KIND])
    if kind in model.SHAPE_KINDS and mesh.get(HASH) == mesh_hash(mesh):
        matrix = np.array(list(mesh.get(MATRIX, np.eye(4).ravel())), dtype=np.float64).reshape(4, 4)
        info = GenericInfo(kind, primitives.parameters_of(kind, mesh.get(PARAM)), mesh.get(FILE), matrix)
    if cache is not None:
        cache[key] = info
    return info


#: generic_info for the panels: mesh name -> (signature, info); an entry goes when Blender updates the
#: mesh's geometry (forget_edited), and all of them when a file is loaded or an undo step restored.
_drawn_info: dict[str, tuple] = {}


def _signature(mesh) -> tuple:
    return (mesh.as_pointer(), len(mesh.vertices), len(mesh.loops), len(mesh.polygons),
            *(mesh.get(name) for name in (KIND, PARAM, FILE, HASH)))


def cached_generic_info(mesh) -> Optional[GenericInfo]:
    """generic_info, hashing the mesh only when it has changed since the last call (for redraws)."""
    if mesh is None or not isinstance(mesh, bpy.types.Mesh) or KIND not in mesh:
        return None
    signature = _signature(mesh)
    seen = _drawn_info.get(mesh.name_full)
    if seen is None or seen[0] != signature:
        seen = _drawn_info[mesh.name_full] = (signature, generic_info(mesh))
    return seen[1]


@bpy.app.handlers.persistent
def forget_edited(scene, depsgraph) -> None:
    """depsgraph_update_post: drop the cached info of meshes whose geometry changed (reading the updates looks
    through every datablock of the depsgraph: only when Blender says a mesh was updated)."""
    if _drawn_info and depsgraph.id_type_updated("MESH"):
        for update in depsgraph.updates:
            if update.is_updated_geometry and isinstance(update.id, bpy.types.Mesh):
                _drawn_info.pop(update.id.original.name_full, None)


@bpy.app.handlers.persistent
def forget_all(*_args) -> None:
    """load_post, undo_post, redo_post: other mesh data than before."""
    _drawn_info.clear()


#: The handlers above, by the bpy.app.handlers list they go in (see ui.register).
HANDLERS = (("depsgraph_update_post", forget_edited), ("load_post", forget_all), ("undo_post", forget_all),
            ("redo_post", forget_all))


def find_shared(kind: str, parameters: tuple[float, ...], mesh_file: Optional[str], digest: str):
    """An existing unedited mesh for this generic shape (so that imports share mesh data)."""
    identity = np.eye(4).ravel()
    for mesh in bpy.data.meshes:
        if (mesh.get(KIND) == kind and mesh.get(HASH) == digest
                and primitives.parameters_of(kind, mesh.get(PARAM)) == tuple(parameters)
                and mesh.get(FILE) == mesh_file and mesh.library is None and mesh.get(MATRIX) is not None
                and np.array_equal(list(mesh[MATRIX]), identity) and mesh_hash(mesh) == digest):
            return mesh
    return None


# ---------------------------------------------------------------------------------------------------------
# Blender meshes as tracer meshes

def _corner_normals(mesh) -> np.ndarray:
    count = len(mesh.loops)
    out = np.empty(count * 3, dtype=np.float32)
    if hasattr(mesh, "corner_normals"):  # Blender 4.1+
        mesh.corner_normals.foreach_get("vector", out)
    else:
        mesh.calc_normals_split()
        mesh.loops.foreach_get("normal", out)
    return out.reshape(-1, 3).astype(np.float64)


def _read(collection, name: str, count: int, dtype) -> np.ndarray:
    out = np.empty(count, dtype=dtype)
    collection.foreach_get(name, out)
    return out


def _triangle_normals(mesh, tri_verts: np.ndarray, tri_loops: np.ndarray, tri_polygons: np.ndarray):
    """The mesh's shading normals and each triangle corner's index into them.

    Blender 4.1+ says where its normals live (``normals_domain``): per vertex on a smooth mesh, per face on a
    flat one, per corner only where sharp edges or custom normals split them.  Its corner normals are then
    the vertex's or the face's normal copied, so reading them from that domain gives the same values in a
    fraction of the memory (a million quads have four million corners but a million vertices)."""
    domain = getattr(mesh, "normals_domain", "CORNER")
    if domain == "POINT":
        normals = _read(mesh.vertex_normals, "vector", len(mesh.vertices) * 3, np.float32)
        index = tri_verts
    elif domain == "FACE":
        normals = _read(mesh.polygon_normals, "vector", len(mesh.polygons) * 3, np.float32)
        index = np.repeat(tri_polygons, 3)
    else:
        return _corner_normals(mesh), tri_loops
    return normals.reshape(-1, 3).astype(np.float64), index


def _triangles(mesh) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Blender's triangles of the mesh's polygons: for each, its corners' vertices and corners (flat, three
    per triangle), its polygon and its material index.

    Blender 4.0+ keeps the corners' vertices, the triangles' polygons and the material indices as plain
    arrays (attributes), which read at memory speed; asking each triangle for its vertices and material goes
    through every item, ~0.5 s per million.  Blender 3.x asks the triangles."""
    mesh.calc_loop_triangles()
    tris = mesh.loop_triangles
    count = len(tris)
    tri_loops = _read(tris, "loops", count * 3, np.int32)
    attributes = mesh.attributes
    corner_vert = attributes.get(".corner_vert")
    if corner_vert is not None and hasattr(mesh, "loop_triangle_polygons"):
        tri_verts = _read(corner_vert.data, "value", len(mesh.loops), np.int32)[tri_loops]
        tri_polygons = _read(mesh.loop_triangle_polygons, "value", count, np.int32)
        materials = attributes.get("material_index")
        if materials is None or materials.domain != "FACE":  # (no attribute: every polygon has material 0)
            mat_index = np.zeros(count, dtype=np.int32)
        else:
            mat_index = _read(materials.data, "value", len(mesh.polygons), np.int32)[tri_polygons]
    else:
        tri_verts = _read(tris, "vertices", count * 3, np.int32)
        tri_polygons = _read(tris, "polygon_index", count, np.int32)
        mat_index = _read(tris, "material_index", count, np.int32)
    return tri_verts, tri_loops, tri_polygons, mat_index


def triangle_meshes(mesh, origin: str = "", uvs: bool = False) -> dict[int, object]:
    """The mesh's triangles (as Blender splits its polygons) with its shading normals, as one tracer MeshData
    per material index.  Faces are kept as flat arrays (model.FaceList): a million-polygon mesh as Python
    tuples took seconds to make and to hash.  The parts share the vertex and normal arrays.  Their digest
    (compile.mesh_digest) is taken here, once: whoever keeps them must not change them.  With ``uvs``, each
    triangle corner's texture coordinates from the UV map that renders (``corner_uvs``; none without one)."""
    tri_verts, tri_loops, tri_polygons, mat_index = _triangles(mesh)
    if len(mat_index) == 0:
        return {}
    vertices = _read(mesh.vertices, "co", len(mesh.vertices) * 3, np.float32).reshape(-1, 3).astype(np.float64)
    normals, normal_index = _triangle_normals(mesh, tri_verts, tri_loops, tri_polygons)
    materials = np.unique(mat_index)
    loop_uvs = _render_uvs(mesh) if uvs else None
    out = {}
    for index in materials:
        corners = None if len(materials) == 1 else _corners_of(np.nonzero(mat_index == index)[0])
        if corners is None:
            verts, norms = tri_verts, normal_index
        else:
            verts = tri_verts[corners]
            # (normals per vertex: one index array serves both, as FaceList allows)
            norms = verts if normal_index is tri_verts else normal_index[corners]
        faces = model.FaceList(np.full(len(verts) // 3, 3, dtype=np.int64), verts, norms)
        corner_uvs = None
        if loop_uvs is not None:
            corner_uvs = loop_uvs[tri_loops if corners is None else tri_loops[corners]]
        data = model.MeshData(vertices=vertices, normals=normals, faces=faces, origin=origin, corner_uvs=corner_uvs)
        # Never changed after this (a changed object is converted anew): hashed here, once, not at every compile.
        out[int(index)] = remember_digest(data)
    return out


def _render_uvs(mesh) -> Optional[np.ndarray]:
    """(corners, 2) float64: the UV map that renders (Blender's active_render layer), per corner; None if
    the mesh has no UV map."""
    layers = mesh.uv_layers
    layer = next((layer for layer in layers if layer.active_render), None) or layers.active
    if layer is None:
        return None
    return _read(layer.data, "uv", len(mesh.loops) * 2, np.float32).reshape(-1, 2).astype(np.float64)


def _corners_of(triangles: np.ndarray) -> np.ndarray:
    """Indices of the three corners of each of ``triangles`` in a flat (triangle, corner) array."""
    return (triangles[:, None] * 3 + np.arange(3)).reshape(-1)


#: .3vn files read: path -> (modification time, MeshData); one version of each file.
_exact_files: dict[str, tuple[float, object]] = {}


def exact_mesh_data(info: GenericInfo, mesh):
    """The float64 mesh behind an unedited generic polyhedron, teapot or ``mesh`` file (None: use Blender's)."""
    kind = info.kind
    if shapes.KINDS[kind].builtin_mesh:
        return builtin_mesh(kind)
    if kind == "mesh" and info.mesh_file and os.path.isfile(info.mesh_file):
        mtime = os.path.getmtime(info.mesh_file)
        mtime_read, data = _exact_files.get(info.mesh_file, (None, None))
        if mtime_read != mtime:
            try:
                # (kept unchanged while the file is: its digest is taken once)
                data = remember_digest(read_3vn(info.mesh_file))
            except Exception:  # noqa: BLE001 - a changed or broken file: fall back to Blender's copy
                return None
            _exact_files[info.mesh_file] = (mtime, data)
        gm = primitives.generic_mesh("mesh", mesh_data=data).transformed(info.mesh_matrix[:3, :3])
        if gm.hash() == mesh.get(HASH):
            return data
    return None
