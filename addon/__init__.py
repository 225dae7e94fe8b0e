"""SDL Ray Tracer for Blender: import and export F. S. Hill's SDL scenes, and ray trace them exactly.

* File > Import > SDL (.sdl, .dat), or drop a file on the viewport; File > Export > SDL.
* Render engine "SDL Ray Tracer": final renders traced in blocks, coarse to fine, and the viewport's
  Rendered mode.  Generic shapes are traced exactly, Boolean modifiers as CSG, everything else as triangles.

Blender 4.2+ installs this as an extension (blender_manifest.toml); older Blenders (3.4+) as a legacy
add-on (bl_info).  The ``tracer`` package is vendored inside the installed add-on (see deps.py).

This module imports nothing from Blender at import time, so its pure parts (primitives, convert, raycam,
blocks) can be used and tested without bpy.
"""

bl_info = {
    "name": "SDL Ray Tracer",
    "author": "SDL Ray Tracer developers",
    "version": (0, 1, 0),
    "blender": (3, 4, 0),
    "location": "File > Import/Export > SDL; Render Properties > Render Engine",
    "description": "Import, export and ray trace F. S. Hill's SDL scenes",
    "category": "Import-Export",
}

_MODULES = ("props", "images", "engine", "operators", "ui")
_registered: list = []
_exit_hook = False


def _modules():
    import importlib

    return [importlib.import_module(f"{__name__}.{name}") for name in _MODULES]


def register() -> None:
    if _registered:  # already registered: a second register() is a no-op, not an error
        return
    done = []
    try:
        for module in _modules():
            done.append(module)  # before its register(): one that fails half way is undone too
            module.register()
    except Exception:
        for module in reversed(done):
            try:
                module.unregister()  # each module's unregister() removes what it has, whatever is missing
            except Exception:  # noqa: BLE001 - keep undoing the others; the first error is the one raised
                pass
        raise
    _registered.extend(done)
    _unregister_at_exit()


def _unregister_at_exit() -> None:
    """In the ``bpy`` module (no Blender binary) the process hangs at exit while the add-on's properties are
    still registered, and nothing else unregisters it there: do it at exit, before bpy's own exit handler."""
    global _exit_hook
    import bpy

    if not _exit_hook and not bpy.app.binary_path:
        import atexit

        atexit.register(unregister)
        _exit_hook = True


def unregister() -> None:
    while _registered:
        _registered.pop().unregister()
