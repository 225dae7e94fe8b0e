"""Blender scene -> SDL file (and .3vn meshes beside it), through tracer.sdl.writer.save_sdl.

Generic shapes are written as their keyword with the transform statements that rebuild their exact
matrix (the writer decomposes any affine matrix); every other object with geometry as a ``mesh`` whose
polygons go to a ``.3vn`` file beside the scene; an unedited imported ``mesh`` keeps naming its file.
The writer replaces the files atomically.
"""
from __future__ import annotations

import os
import re
from typing import Optional

import numpy as np

from .engine import camera_params, render_size, stored_sdl_camera
from .pure import convert, raycam
from .scene_build import SceneBuilder, flat
from .tracer.camera import view_angle
from .tracer.meshio import write_3vn
from .tracer.model import Camera
from .tracer.sdl.writer import save_sdl

_UNWRITABLE = re.compile(r"[\s{}!]")
_SAFE = re.compile(r"[^A-Za-z0-9._-]")  # what a mesh file's name may hold


def _to_target(conversion: np.ndarray) -> np.ndarray:
    return convert.from_blender(np.eye(4), conversion)


def camera_to_sdl(cam_obj, render, to_target: np.ndarray):
    """The SDL camera for a Blender camera (None for cameras SDL cannot express)."""
    data = cam_obj.data
    if data.type != "PERSP":
        return None
    stored = stored_sdl_camera(cam_obj)
    if stored is not None:
        eye, look, up, angle = stored
    else:
        params = camera_params(cam_obj)
        eye, axes = params.frame()
        look = eye - axes[:, 2]
        up = axes[:, 1]
        _, _, ymin, ymax = raycam.viewplane(params, *render_size(render), render.pixel_aspect_x,
                                            render.pixel_aspect_y)
        angle = convert.shortest32(view_angle(1.0, ymax - ymin))  # window at distance 1
    rot = to_target[:3, :3]
    return Camera(tuple(float(v) for v in rot @ eye), tuple(float(v) for v in rot @ look),
                  tuple(float(v) for v in rot @ up), float(angle))


def build_export_scene(context, conversion: Optional[np.ndarray] = None, use_selection: bool = False,
                       mesh_names: Optional[dict] = None):
    """(tracer Scene in SDL axes, warnings) for the objects of the view layer's (viewport) depsgraph that
    render: objects hidden in the viewport are left out as well as those hidden for rendering."""
    conversion = convert.axis_matrix() if conversion is None else np.asarray(conversion, dtype=np.float64)
    to_target = _to_target(conversion)
    depsgraph = context.evaluated_depsgraph_get()
    builder = SceneBuilder(depsgraph, mode="EXPORT", to_target=to_target)
    scene = builder.build(context.scene, skip_hidden_render=True, selected_only=use_selection)
    cam_obj = context.scene.camera
    if cam_obj is not None and cam_obj.type == "CAMERA":
        scene.camera = camera_to_sdl(cam_obj.evaluated_get(depsgraph), context.scene.render, to_target)
        if scene.camera is None:
            builder.warnings.append(f"{cam_obj.name}: only perspective cameras can be written to SDL")
    if mesh_names is not None:
        mesh_names.update(builder.mesh_object_names)
    return scene, builder.warnings


def _write_named_meshes(scene, names: dict, filepath: str) -> list:
    """Mesh data without a file goes to ``<scene>_<object name>.3vn`` beside the scene (the importer names
    the object after it again), rather than the writer's ``<scene>_mesh<k>.3vn``.  Returns the files made
    (new ones), for removal if the scene file cannot be written."""
    folder = os.path.dirname(os.path.abspath(filepath))
    stem = _SAFE.sub("_", os.path.splitext(os.path.basename(filepath))[0]) or "scene"
    by_mesh: dict[int, str] = {}
    used: set[str] = set()
    made = []
    try:
        for shape in scene.shapes():
            if shape.kind != "mesh" or shape.mesh_file is not None or shape.mesh is None or id(shape) not in names:
                continue
            if id(shape.mesh) not in by_mesh:
                base = f"{stem}_{_SAFE.sub('_', names[id(shape)])}"
                name, k = base + ".3vn", 1
                while name in used:
                    k += 1
                    name = f"{base}.{k}.3vn"
                used.add(name)
                target = os.path.join(folder, name)
                existed = os.path.exists(target)
                write_3vn(shape.mesh, target)
                if not existed:
                    made.append(target)
                by_mesh[id(shape.mesh)] = name
            shape.mesh_file = by_mesh[id(shape.mesh)]
    except BaseException:
        _remove(made)
        raise
    return made


def _remove(paths) -> None:
    for path in paths:
        try:
            os.unlink(path)
        except OSError:
            pass


def _fix_mesh_files(scene, folder: str) -> None:
    """Unedited imported meshes name their .3vn relative to the new file; where SDL cannot spell that
    name (spaces, braces), the mesh data is written beside the file instead."""
    for shape in scene.shapes():
        if shape.kind != "mesh" or shape.mesh_file is None:
            continue
        try:
            rel = os.path.relpath(shape.mesh_file, folder)
        except ValueError:
            rel = shape.mesh_file
        rel = rel.replace(os.sep, "/")
        shape.mesh_file = None if (_UNWRITABLE.search(rel) or not os.path.isfile(shape.mesh_file)) else rel


def export_sdl(context, filepath: str, conversion: Optional[np.ndarray] = None,
               use_selection: bool = False) -> list[str]:
    """Write the scene; returns warnings.  Nothing is left half-written if it fails."""
    names: dict = {}
    scene, warnings = build_export_scene(context, conversion, use_selection, mesh_names=names)
    _fix_mesh_files(scene, os.path.dirname(os.path.abspath(filepath)))
    scene.source = None
    made = _write_named_meshes(scene, names, filepath)
    try:
        save_sdl(scene, filepath)
    except BaseException:
        _remove(made)
        raise
    return warnings
