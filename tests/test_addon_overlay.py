"""Overlay, proved: each bundled scene is rendered one object at a time by Blender's Workbench (which draws
the add-on's generic meshes, and Boolean modifiers for CSG) and by SDL_RAYTRACER (which traces the exact
shapes and CSG), and every object's silhouette must agree: IoU >= 0.97.

Workbench renders headless here with the bpy module (EGL on Mesa; it prints EGL_BAD_MATCH warnings and
renders anyway).  Anti-aliasing is off on both sides, so both sample each pixel at its centre."""
from __future__ import annotations

import bpy
import numpy as np
import pytest

from blender_scripts.addon_env import SCENE_FILES, fresh, import_sdl, iou, render_rgba, set_resolution, shape_objects

WIDTH, HEIGHT = 160, 120
MIN_IOU = 0.97
#: Objects covering fewer pixels than this are judged on a render with the camera zoomed onto them, so a
#: one-pixel edge does not decide the score of a tiny object.
MIN_PIXELS = 400


def _setup_engines() -> None:
    scene = bpy.context.scene
    scene.render.film_transparent = True
    scene.display.render_aa = "OFF"
    scene.display.shading.light = "FLAT"
    scene.display.shading.color_type = "SINGLE"
    s = scene.sdl_render
    s.block_size, s.progressive, s.samples, s.max_recursion_depth = 1, False, 1, 0


def _masks() -> tuple[np.ndarray, np.ndarray]:
    workbench = render_rgba("BLENDER_WORKBENCH")[..., 3] > 0.5
    traced = render_rgba("SDL_RAYTRACER")[..., 3] > 0.5
    return workbench, traced


def _zoom_onto(mask: np.ndarray) -> None:
    """Shift and narrow the camera so that the object's pixels fill the frame (both engines see the same
    camera, so this only gives the comparison more pixels)."""
    cam = bpy.context.scene.camera.data
    rows, cols = np.nonzero(mask)
    if rows.size == 0:
        return
    cy = (HEIGHT - 1 - 0.5 * (rows.min() + rows.max()) + 0.5) / HEIGHT - 0.5
    cx = (0.5 * (cols.min() + cols.max()) + 0.5) / WIDTH - 0.5
    extent = max((rows.max() - rows.min() + 3) / HEIGHT, (cols.max() - cols.min() + 3) / WIDTH)
    zoom = min(8.0, 0.9 / extent)
    # shift is in units of the larger frame side; Blender's sensor fit here is vertical for imported cameras
    side = max(WIDTH, HEIGHT)
    if cam.type == "ORTHO":
        cam.ortho_scale /= zoom
    else:
        cam.lens *= zoom
    cam.shift_x = (cam.shift_x + cx * WIDTH / side) * zoom
    cam.shift_y = (cam.shift_y + cy * HEIGHT / side) * zoom


PIXELS: dict = {}


def measure(path) -> dict[str, float]:
    fresh()
    import_sdl(path)
    set_resolution(WIDTH, HEIGHT)
    _setup_engines()
    objects = [o for o in shape_objects() if not o.get("sdl_cutter")]
    shown = {o.name: o.hide_render for o in bpy.data.objects}
    scores = {}
    cam = bpy.context.scene.camera.data
    lens, shift = cam.lens, (cam.shift_x, cam.shift_y)
    for obj in objects:
        for other in objects:
            other.hide_render = other is not obj
        workbench, traced = _masks()
        if max(workbench.sum(), traced.sum()) < MIN_PIXELS:
            _zoom_onto(workbench | traced)
            workbench, traced = _masks()
            cam.lens, (cam.shift_x, cam.shift_y) = lens, shift
        assert workbench.sum() > 50 and traced.sum() > 50, (obj.name, workbench.sum(), traced.sum())
        scores[f"{obj.name}:{obj['sdl_kind']}"] = round(iou(workbench, traced), 4)
        PIXELS[f"{path.stem}/{obj.name}"] = (int(workbench.sum()), int(traced.sum()))
    for o in bpy.data.objects:
        o.hide_render = shown[o.name]
    return scores


@pytest.mark.parametrize("path", SCENE_FILES, ids=lambda p: p.stem)
def test_silhouettes_overlay(path):
    scores = measure(path)
    print(path.stem, scores, {k: v for k, v in PIXELS.items() if k.startswith(path.stem + "/")})
    assert scores and min(scores.values()) >= MIN_IOU, scores


def test_blender_objects_overlay():
    """Objects that are not generic shapes are traced as the triangles Blender makes of them (modifiers
    applied); a generic shape with a Boolean modifier whose operand is a plain Blender mesh is CSG of the
    exact shape and that mesh."""
    import math

    fresh()
    scene = bpy.context.scene
    bpy.ops.mesh.primitive_monkey_add(location=(-2.5, 0, 0))
    monkey = bpy.context.object
    monkey.modifiers.new("subdivide", "SUBSURF").levels = 1
    bpy.ops.mesh.primitive_cylinder_add(location=(2.5, 0, 0), rotation=(0.4, 0.2, 0))
    bpy.ops.object.sdl_add_shape(kind="sphere")
    sphere = bpy.context.object
    sphere.location = (0, 0, 0.3)
    bpy.ops.mesh.primitive_cube_add(size=1.2, location=(0.6, 0.0, 0.9), scale=(1.0, 3.0, 1.0))
    cutter = bpy.context.object  # through the whole sphere, so the cut shows in the silhouette
    cutter.hide_render = True
    boolean = sphere.modifiers.new("cut", "BOOLEAN")
    boolean.operation, boolean.object = "DIFFERENCE", cutter
    bpy.ops.object.camera_add(location=(0, -9, 3), rotation=(math.radians(75), 0, 0))
    scene.camera = bpy.context.object
    set_resolution(WIDTH, HEIGHT)
    _setup_engines()
    targets = [monkey, bpy.data.objects["Cylinder"], sphere]
    scores = {}
    for obj in targets:
        for other in targets:
            other.hide_render = other is not obj
        workbench, traced = _masks()
        assert workbench.sum() > 500
        scores[obj.name] = round(iou(workbench, traced), 4)
        if obj is sphere:
            boolean.show_render = False  # the uncut sphere: a different silhouette, so the cut was traced
            assert iou(render_rgba("SDL_RAYTRACER")[..., 3] > 0.5, traced) < 0.95
            boolean.show_render = True
    print("blender objects", scores)
    assert min(scores.values()) >= MIN_IOU, scores
    from addon import engine
    assert engine.LAST_RENDER["objects"] == 1  # the sphere and its cutter: one CSG object
