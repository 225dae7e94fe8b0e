"""Packaging: the manifest, register()/unregister() (twice in a row, leaving nothing behind), and the
installable zip that `make extension` builds, installed into Blender (the bpy module) and rendering."""
from __future__ import annotations

import os
import subprocess
import sys
import tomllib
import zipfile

import bpy

import addon
from blender_scripts.addon_env import ROOT, fresh

sys.path.insert(0, str(ROOT / "scripts"))
import build_extension  # noqa: E402

OPERATORS = ("IMPORT_SCENE_OT_sdl", "EXPORT_SCENE_OT_sdl", "OBJECT_OT_sdl_add_shape")
PANELS = ("SDL_PT_render", "SDL_PT_material", "SDL_PT_world", "SDL_PT_object")
PROPERTIES = ((bpy.types.Scene, "sdl_render"), (bpy.types.World, "sdl"), (bpy.types.Material, "sdl"))
MENUS = ("TOPBAR_MT_file_import", "TOPBAR_MT_file_export", "VIEW3D_MT_add")
HANDLERS = ("depsgraph_update_post", "load_post", "undo_post", "redo_post")


def _menu_funcs(menu: str) -> list:
    draw = getattr(bpy.types, menu).draw
    return [f for f in getattr(draw, "_draw_funcs", []) if getattr(f, "__module__", "").startswith("addon")]


def _engine_known() -> bool:
    """Whether Blender accepts SDL_RAYTRACER as a render engine (it refuses unknown ones)."""
    render = bpy.context.scene.render
    before = render.engine
    try:
        render.engine = "SDL_RAYTRACER"
    except TypeError:
        return False
    render.engine = before
    return True


def _state() -> dict:
    return {
        "operators": [name for name in OPERATORS if hasattr(bpy.types, name)],
        "panels": [name for name in PANELS if hasattr(bpy.types, name)],
        "properties": [name for owner, name in PROPERTIES if hasattr(owner, name)],
        "engine": _engine_known(),
        "menus": {menu: len(_menu_funcs(menu)) for menu in MENUS},
        "compat": sorted(name for name in dir(bpy.types)
                         if "SDL_RAYTRACER" in (getattr(getattr(bpy.types, name), "COMPAT_ENGINES", None) or ())),
        "ops": hasattr(bpy.ops.import_scene, "sdl") and "sdl" in dir(bpy.ops.import_scene),
        "handlers": sum(getattr(f, "__module__", "").startswith("addon") for name in HANDLERS
                        for f in getattr(bpy.app.handlers, name)),
    }


def test_register_unregister_twice_leaves_nothing_behind():
    addon.register()
    registered = _state()
    assert registered["operators"] == list(OPERATORS)
    assert registered["panels"] == list(PANELS)
    assert len(registered["properties"]) == 3 and registered["engine"]
    assert registered["menus"] == {menu: 1 for menu in MENUS}
    assert "RENDER_PT_format" in registered["compat"]  # Blender's own panels show for the engine
    # the SDL Shape panel's cache (meshes.HANDLERS), the engine's (object_cache.HANDLERS), Base Color edits,
    # the decoded pictures' (images.forget)
    assert registered["handlers"] == 9
    for _ in range(2):
        addon.unregister()
        gone = _state()
        assert gone["operators"] == [] and gone["panels"] == [] and gone["properties"] == []
        assert not gone["engine"]
        assert gone["menus"] == {menu: 0 for menu in MENUS}
        assert gone["compat"] == [] and gone["handlers"] == 0
        addon.unregister()  # a second unregister is harmless
    for _ in range(2):
        addon.register()
        addon.register()  # registering twice in a row is a no-op, not an error
        assert _state() == registered
        addon.unregister()
    addon.register()
    fresh()
    assert bpy.ops.import_scene.sdl.poll() is not None


def test_manifest():
    manifest = tomllib.loads((ROOT / "blender_manifest.toml").read_text())
    assert manifest["schema_version"] == "1.0.0"
    assert manifest["id"] == "sdl_raytracer" and manifest["type"] == "add-on"
    assert tuple(int(p) for p in manifest["blender_version_min"].split(".")) >= (4, 2, 0)
    assert set(manifest.get("permissions", {})) == {"files"}  # reads and writes files; no network
    assert addon.bl_info["blender"] >= (3, 4, 0)  # the legacy path


def test_extension_zip_contents(tmp_path):
    zip_path = build_extension.build(tmp_path / "ext.zip")
    names = set(zipfile.ZipFile(zip_path).namelist())
    assert {"blender_manifest.toml", "__init__.py", "engine.py", "pure/convert.py"} <= names
    assert {"tracer/__init__.py", "tracer/native/core.c", "tracer/native/build.py",
            "tracer/geometry/teapot.py"} <= names
    assert not [n for n in names if n.endswith((".so", ".pyc")) or "__pycache__" in n or n.startswith("tracer/usd")]
    legacy = set(zipfile.ZipFile(build_extension.build(tmp_path / "legacy.zip", legacy=True)).namelist())
    assert legacy == {f"sdl_raytracer/{n}" for n in names}


INSTALL_ZIP = ROOT / "tests" / "blender_scripts" / "install_zip.py"


def test_extension_zip_installs_and_renders(tmp_path):
    """The built zip, installed by Blender's extension installer into an empty user folder, renders with
    its own vendored tracer (whose C core it compiles on first use)."""
    import json

    zip_path = build_extension.build(tmp_path / "sdl_raytracer.zip")
    env = dict(os.environ, BLENDER_USER_EXTENSIONS=str(tmp_path / "ext"), BLENDER_USER_CONFIG=str(tmp_path / "cfg"),
               BLENDER_USER_SCRIPTS=str(tmp_path / "scripts"), PYTHONPATH="")
    out = tmp_path / "render.png"
    proc = subprocess.run([sys.executable, str(INSTALL_ZIP), str(zip_path), str(ROOT / "scenes" / "csg.sdl"), str(out)],
                          capture_output=True, text=True, env=env, timeout=240, cwd=tmp_path)
    lines = [line for line in proc.stdout.splitlines() if line.startswith("RESULT ")]
    assert proc.returncode == 0 and lines, proc.stdout[-3000:] + proc.stderr[-3000:]
    result = json.loads(lines[-1][len("RESULT "):])
    assert result["tracer"] == "bl_ext.user_default.sdl_raytracer.tracer"
    assert result["tracer_file"].startswith(str(tmp_path / "ext"))
    assert result["stats"]["width"] == 48 and "error" not in result["stats"]
    assert result["stats"]["rays"]["camera"] == 48 * 36
    assert out.is_file() and out.stat().st_size > 0


def test_bpy_module_exits_with_the_add_on_registered():
    """The README's bpy-module usage (register, work, end the script without unregistering) exits: the
    bpy module hangs at exit while the add-on's properties are registered, so the add-on unregisters then."""
    code = ("import sys; sys.path.insert(0, sys.argv[1]); import bpy, addon; addon.register(); "
            "bpy.ops.wm.read_factory_settings(use_empty=True); addon.register(); print('RESULT ok')")
    env = dict(os.environ, PYTHONPATH="")
    proc = subprocess.run([sys.executable, "-c", code, str(ROOT)], capture_output=True, text=True, env=env,
                          timeout=60, cwd=ROOT)
    assert proc.returncode == 0 and "RESULT ok" in proc.stdout, proc.stdout[-2000:] + proc.stderr[-2000:]


def test_a_failed_register_leaves_nothing_registered(monkeypatch):
    """A module's register() that fails half way (here after its classes, at its menus) is undone too."""
    import pytest

    from addon import operators

    addon.unregister()
    monkeypatch.setattr(operators, "_MENUS", operators._MENUS + (("NO_SUCH_MENU", operators.menu_add),))
    with pytest.raises(AttributeError):
        addon.register()
    state = _state()
    assert state["operators"] == [] and state["panels"] == [] and state["properties"] == []
    assert not state["engine"] and state["compat"] == [] and state["handlers"] == 0
    assert state["menus"] == {menu: 0 for menu in MENUS}
    monkeypatch.undo()
    addon.register()
    assert _state()["operators"] == list(OPERATORS)
