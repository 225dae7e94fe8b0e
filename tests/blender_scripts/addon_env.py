"""Shared by the add-on tests (tests/test_addon_*.py): bpy with the add-on registered, and small helpers.

``import bpy`` is unconditional: where bpy is missing the add-on tests fail (they are part of the suite,
not optional); only the ``blender -b`` tests skip, when there is no ``blender`` on PATH.
"""
from __future__ import annotations

import os
import tempfile
from pathlib import Path

import bpy  # noqa: F401  (must fail loudly when missing)
import numpy as np

import addon
from addon import scene_build
from addon.pure import convert

ROOT = Path(__file__).resolve().parents[2]
SCENES = ROOT / "scenes"
SCENE_FILES = sorted(SCENES.glob("*.sdl"))


def fresh() -> None:
    """An empty Blender file with the add-on registered (register() twice is a no-op)."""
    addon.register()
    bpy.ops.wm.read_factory_settings(use_empty=True)
    addon.register()


def import_sdl(path, **kwargs):
    result = bpy.ops.import_scene.sdl(filepath=str(path), **kwargs)
    assert result == {"FINISHED"}, result
    return result


def shape_objects() -> list:
    """Imported shape objects in file order (cutters included)."""
    objs = [o for o in bpy.data.objects if scene_build.OBJ_KIND in o]
    return sorted(objs, key=lambda o: o[scene_build.OBJ_ORDER])


def world(obj) -> np.ndarray:
    return scene_build.matrix_np(obj.matrix_world)


def effective_matrix(obj) -> np.ndarray:
    """The object's world matrix times the rotation baked into a sheared shape's mesh: the shape's
    transform in Blender's axes as Blender shows it (float32)."""
    mesh_matrix = np.array(list(obj.data.get("sdl_mesh_matrix", np.eye(4).ravel())), dtype=np.float64)
    return world(obj) @ mesh_matrix.reshape(4, 4)


def to_blender(matrix) -> np.ndarray:
    return convert.to_blender(matrix, convert.axis_matrix())


def set_resolution(width: int, height: int, percentage: int = 100) -> None:
    r = bpy.context.scene.render
    r.resolution_x, r.resolution_y, r.resolution_percentage = width, height, percentage
    r.pixel_aspect_x = r.pixel_aspect_y = 1.0


def render_rgba(engine_id: str, path: str | None = None) -> np.ndarray:
    """Render the scene with ``engine_id`` to an EXR and read it back: (height, width, 4) float32 linear,
    row 0 at the *top*."""
    scene = bpy.context.scene
    if scene.render.engine != engine_id:  # (setting it, even unchanged, frees the engine Persistent Data kept)
        scene.render.engine = engine_id
    scene.render.image_settings.file_format = "OPEN_EXR"
    scene.render.image_settings.color_depth = "32"
    scene.view_settings.view_transform = "Standard"
    scene.view_settings.look = "None"
    scene.view_settings.exposure = 0.0
    scene.view_settings.gamma = 1.0
    if path is None:
        fd, path = tempfile.mkstemp(suffix=".exr")
        os.close(fd)
    scene.render.filepath = path
    scene.render.use_file_extension = False
    bpy.ops.render.render(write_still=True)
    image = bpy.data.images.load(path, check_existing=False)
    try:
        width, height = image.size
        pixels = np.empty(width * height * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
        os.unlink(path)
    return pixels.reshape(height, width, 4)[::-1]


def compositor(scene):
    """An empty compositor node tree for ``scene`` and the socket whose image F12 writes: the Composite node's
    Image in Blender 3.4-4.5 (scene.node_tree); in 5.0, which has neither, the Image output of the group the
    scene composites with (scene.compositing_node_group)."""
    scene.render.use_compositing = True
    if hasattr(scene, "compositing_node_group"):
        tree = bpy.data.node_groups.new("Compositing", "CompositorNodeTree")
        tree.interface.new_socket("Image", in_out="OUTPUT", socket_type="NodeSocketColor")
        scene.compositing_node_group = tree
        return tree, tree.nodes.new("NodeGroupOutput").inputs["Image"]
    scene.use_nodes = True
    tree = scene.node_tree
    tree.nodes.clear()
    return tree, tree.nodes.new("CompositorNodeComposite").inputs["Image"]


def iou(a: np.ndarray, b: np.ndarray) -> float:
    union = np.logical_or(a, b).sum()
    return 1.0 if union == 0 else float(np.logical_and(a, b).sum() / union)


def two_files_with_their_own_pixmap_1(folder: Path) -> list[Path]:
    """Two SDL files in folders a/ and b/, each with ``makePixmap 1 tex.png`` (red in a/, green in b/) on a
    cube lit by the global ambient light only (left in a, right in b), so each cube shows its image's colour."""
    from tracer.imageio import save_image

    paths = []
    for name, color, x in (("a", (1.0, 0.0, 0.0), -1.5), ("b", (0.0, 1.0, 0.0), 1.5)):
        sub = folder / name
        sub.mkdir()
        save_image(np.full((4, 4, 3), color), sub / "tex.png")
        path = sub / f"{name}.sdl"
        path.write_text("globalAmbient 1 1 1\nbackground 0 0 0\ncamera 0 0 10  0 0 0  0 1 0  40\n"
                        "makePixmap 1 tex.png\n"
                        f"push ambient 1 1 1 diffuse 0 0 0 texture 1 translate {x} 0 0 cube pop\n")
        paths.append(path)
    return paths
