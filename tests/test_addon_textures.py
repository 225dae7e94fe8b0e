"""Image textures inside Blender, whose Python has no Pillow: the add-on reads them through Blender's own
image loading (addon/images.py, the tracer's fallback decoder).  The textured scene rendered by F12 with
Pillow unimportable, under ``blender -b`` (Debian's Blender 3.4 here) and in the bpy module, equals the
tracer's image made outside Blender with Pillow."""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import bpy
import numpy as np
import pytest

import tracer
from addon import images
from blender_binary import BLENDER, blender_numpy_path
from tracer.errors import TracerError
from tracer.textures import images as tracer_images

ROOT = Path(__file__).resolve().parent.parent
SCRIPT = ROOT / "tests" / "blender_scripts" / "render_without_pillow.py"
SCENE = ROOT / "scenes" / "textures.sdl"
WIDTH, HEIGHT = 160, 120


def _exr_rgb(path: Path) -> np.ndarray:
    """An EXR read back through Blender: (height, width, 3), row 0 at the top."""
    image = bpy.data.images.load(str(path), check_existing=False)
    try:
        pixels = np.empty(WIDTH * HEIGHT * 4, dtype=np.float32)
        image.pixels.foreach_get(pixels)
    finally:
        bpy.data.images.remove(image)
    return pixels.reshape(HEIGHT, WIDTH, 4)[::-1, :, :3]


def _check(proc, out: Path) -> None:
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout[-4000:] + proc.stderr[-4000:]
    result = json.loads(lines[-1][len("RESULT "):])
    assert result["error"] is None and not result["pillow"], result
    assert result["images_left"] == []  # the decoder's own datablocks are removed again
    expected = tracer.render(tracer.load(str(SCENE)), WIDTH, HEIGHT).image  # outside Blender: Pillow
    rendered = _exr_rgb(out)
    differs = np.abs(rendered - expected).max(axis=2) > 1e-3
    # (Blender's camera rays equal the tracer's to float rounding, which may move a silhouette's edge pixel)
    assert differs.sum() <= WIDTH * HEIGHT // 1000, np.argwhere(differs)
    assert expected.std() > 0.05  # a picture with its textures, not a flat colour


@pytest.mark.skipif(BLENDER is None, reason="no blender on PATH")
def test_textured_scene_without_pillow_under_blender(tmp_path):
    out = tmp_path / "textures.exr"
    env = dict(os.environ, PYTHONPATH=blender_numpy_path(BLENDER, tmp_path))
    proc = subprocess.run([BLENDER, "-b", "--factory-startup", "--python-exit-code", "1", "--python", str(SCRIPT),
                           "--", str(ROOT), str(SCENE), str(WIDTH), str(HEIGHT), str(out)],
                          capture_output=True, text=True, env=env, cwd=tmp_path, timeout=300)
    _check(proc, out)


def test_textured_scene_without_pillow_in_the_bpy_module(tmp_path):
    out = tmp_path / "textures.exr"
    proc = subprocess.run([sys.executable, str(SCRIPT), str(ROOT), str(SCENE), str(WIDTH), str(HEIGHT), str(out)],
                          capture_output=True, text=True, env=dict(os.environ, PYTHONPATH=""), cwd=tmp_path,
                          timeout=300)
    _check(proc, out)


def test_blender_decoder_reads_what_pillow_reads():
    for name in ("uvgrid.bmp", "bricks.png"):
        path = ROOT / "scenes" / "images" / name
        # (load_image keeps Pillow's 8-bit texels; the decoder gives their values, byte / 255)
        np.testing.assert_allclose(images.decode(path), tracer_images.load_image(path) / 255.0, atol=1e-6)


def test_unreadable_images_are_one_line_errors(tmp_path):
    with pytest.raises(TracerError, match="texture image not found"):
        images.decode(tmp_path / "missing.png")
    bad = tmp_path / "bad.png"
    bad.write_bytes(b"not a picture")
    with pytest.raises(TracerError, match=r"bad\.png: cannot read texture image"):
        images.decode(bad)
    assert not [i for i in bpy.data.images if i.filepath.endswith("bad.png")]


def test_without_pillow_or_decoder_the_error_names_pillow(monkeypatch):
    monkeypatch.setitem(sys.modules, "PIL", None)
    monkeypatch.setattr(tracer_images, "_fallback_decoder", None)  # (restored afterwards)
    with pytest.raises(TracerError, match="needs Pillow"):
        tracer_images.load_image(ROOT / "scenes" / "images" / "bricks.png")


def test_a_rendered_viewport_of_textures_settles_without_pillow(monkeypatch):
    """The viewport rebuilds its scene after every change Blender reports.  Decoding a picture through a
    temporary Blender image is such a change (a datablock added and removed), so a rebuild that decoded again
    started the viewport again, for ever (Blender 3.4's GUI, scenes/textures.sdl).  Each picture is decoded
    once per content: after the first rebuild nothing is reported, and the image stays finished."""
    from blender_scripts.addon_env import fresh, import_sdl, set_resolution
    from test_addon_updates import _Viewport
    from addon import engine

    monkeypatch.setitem(sys.modules, "PIL", None)  # as in Blender's own Python: the add-on's decoder reads
    images.forget()
    fresh()
    import_sdl(SCENE)
    set_resolution(64, 48)
    monkeypatch.setattr(engine, "VIEWPORT_SLICE", 10.0)
    restarts = []
    with _Viewport() as view:
        for _ in range(3):
            picture = view.show()
            view._view_dirty = False
            bpy.context.evaluated_depsgraph_get()  # what Blender does before the next redraw: report changes
            restarts.append(view._view_dirty)
    assert restarts[1:] == [False, False], restarts
    assert picture.std() > 0.05  # traced with its textures
    path = ROOT / "scenes" / "images" / "bricks.png"
    assert images.decode(path) is images.decode(path)


def test_a_missing_picture_is_refused_by_strict_import_and_warned_by_lenient(tmp_path, capfd):
    """``makePixmap`` naming a file that is not there: Strict refuses the file (as the command line does),
    Lenient imports it without that texture and says so (as ``--lenient`` does).  A picture gone after the
    import: F12 draws the shape without it, says so, and prints no traceback."""
    from blender_scripts.addon_env import fresh, set_resolution
    from addon import engine

    sdl = tmp_path / "missing.sdl"
    sdl.write_text("makePixmap 1 nothere.png\nlight 3 3 3 1 1 1\ntexture 1 sphere\n")
    fresh()
    with pytest.raises(RuntimeError, match=r"makePixmap 1: .*nothere\.png: texture image not found"):
        bpy.ops.import_scene.sdl(filepath=str(sdl), strict=True)
    assert not bpy.data.objects
    proc = subprocess.run([sys.executable, "-m", "tracer", "render", str(sdl), "-o", str(tmp_path / "x.png"), "-q"],
                          capture_output=True, text=True, cwd=ROOT)
    assert proc.returncode == 2 and "nothere.png: texture image not found" in proc.stderr

    capfd.readouterr()
    assert bpy.ops.import_scene.sdl(filepath=str(sdl), strict=False) == {"FINISHED"}
    assert "nothere.png: texture image not found: drawn without that texture" in capfd.readouterr().out
    assert bpy.data.objects["sphere"].active_material.sdl.texture == 0

    fresh()
    shutil.copy(ROOT / "scenes" / "images" / "bricks.png", tmp_path / "gone.png")
    sdl.write_text("makePixmap 1 gone.png\nlight 3 3 3 1 1 1\ntexture 1 sphere\n")
    assert bpy.ops.import_scene.sdl(filepath=str(sdl), strict=True) == {"FINISHED"}
    (tmp_path / "gone.png").unlink()
    scene = bpy.context.scene
    scene.render.engine = engine.ENGINE_ID
    set_resolution(32, 24)
    capfd.readouterr()
    bpy.ops.render.render()
    out, err = capfd.readouterr()
    assert "error" not in engine.LAST_RENDER, engine.LAST_RENDER
    assert any("gone.png not found: drawn without it" in w for w in engine.LAST_RENDER["warnings"])
    assert "Traceback" not in out + err


def test_a_packed_or_generated_picture_is_traced_as_the_same_picture_in_a_file(tmp_path):
    """An Image Texture on Base Color whose picture is packed into the .blend, or made in Blender (a
    generated image with its pixels painted in), renders exactly as the same picture read from its file,
    with no warning; and a render does not leave Blender's images changed (no new datablock)."""
    from tracer.imageio import save_image

    from addon import engine
    from blender_scripts.addon_env import fresh, render_rgba, set_resolution

    rng = np.random.default_rng(7)
    picture = rng.integers(0, 256, (16, 16, 3), dtype=np.uint8)  # (row 0 at the top)
    save_image(picture, tmp_path / "noise.png")
    fresh()
    set_resolution(48, 48)
    bpy.ops.mesh.primitive_plane_add(size=2)
    plane = bpy.context.object
    material = bpy.data.materials.new("pictured")
    material.use_nodes = True
    tree = material.node_tree
    texture = tree.nodes.new("ShaderNodeTexImage")
    tree.links.new(texture.outputs["Color"], tree.nodes["Principled BSDF"].inputs["Base Color"])
    plane.data.materials.append(material)
    bpy.ops.object.light_add(type="SUN")
    bpy.ops.object.camera_add(location=(0.0, 0.0, 5.0))
    scene = bpy.context.scene
    scene.camera = bpy.context.object
    scene.camera.data.type, scene.camera.data.ortho_scale = "ORTHO", 2.0
    scene.render.engine = engine.ENGINE_ID
    scene.sdl_render.block_size, scene.sdl_render.progressive = 1, False

    def rendered(image):
        texture.image = image
        def pictures():  # (F12 makes Blender's own "Render Result")
            return sorted(i.name for i in bpy.data.images if i.type != "RENDER_RESULT")

        names = pictures()
        rgba = render_rgba(engine.ENGINE_ID)
        assert engine.LAST_RENDER["warnings"] == [], engine.LAST_RENDER["warnings"]
        assert pictures() == names
        return rgba

    in_file = rendered(bpy.data.images.load(str(tmp_path / "noise.png")))
    packed = bpy.data.images.load(str(tmp_path / "noise.png"), check_existing=False)
    packed.pack()
    (tmp_path / "noise.png").unlink()  # (the packed copy is all there is now)
    generated = bpy.data.images.new("painted", 16, 16)
    generated.pixels.foreach_set(np.concatenate([picture[::-1] / 255.0, np.ones((16, 16, 1))], axis=2)
                                 .astype(np.float32).reshape(-1))
    assert in_file[..., :3].std() > 0.05  # the picture's noise is in the render
    assert np.array_equal(rendered(packed), in_file)
    assert np.array_equal(rendered(generated), in_file)
    # and a Rendered viewport of the packed picture settles: reading its pixels is no change Blender reports
    from test_addon_updates import _Viewport

    texture.image = packed
    restarts = []
    with _Viewport() as view:
        for _ in range(3):
            view.show()
            view._view_dirty = False
            bpy.context.evaluated_depsgraph_get()
            restarts.append(view._view_dirty)
    assert restarts[1:] == [False, False], restarts
