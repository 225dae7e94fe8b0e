"""SDL Ray Tracer for Blender: import and export F. S. Hill's SDL scenes, and ray trace them exactly.

* File > Import > SDL (.sdl, .dat), or drop a file on the viewport; File > Export > SDL.
* Render engine "SDL Ray Tracer": final renders traced in blocks, coarse to fine, and the viewport's
  Rendered mode.  Generic shapes are traced exactly, Boolean modifiers as CSG, everything else as triangles.

Blender 4.2+ installs this as an extension (blender_manifest.toml); older Blenders (3.4+) as a legacy
add-on (bl_info).

The add-on imports the tracer as its own subpackage, ``from .tracer import model`` (``from ..tracer ...``
in ``pure/``), with no string imports and no ``sys.path`` changes, so that editors and readers can follow
every import:

* installed, the ``tracer`` package is vendored inside the add-on (scripts/build_extension.py), so
  ``<addon>.tracer`` is a real subpackage;
* in the checkout ``addon/tracer`` is a symbolic link to ``../tracer`` (which editors follow), and when the
  top-level ``tracer`` package found on ``sys.path`` is those same files (the tests, ``scripts/render_sdl.py``
  with ``blender -b``), :class:`SharedTracer` makes ``<addon>.tracer.X`` *be* the module ``tracer.X``: one
  copy of each module, so a test's ``tracer.model.Scene`` is the add-on's.

``pure/`` holds the modules that need no ``bpy`` (tested without it); the others import ``bpy``.  This
module imports nothing from Blender at import time.
"""
from __future__ import annotations

import importlib
import importlib.machinery
import importlib.util
import os
import sys

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


class SharedTracer:
    """A sys.meta_path finder (duck-typed, as tracer/startup.py's) that answers ``<addon>.tracer`` and its
    submodules with the top-level ``tracer`` package's modules themselves (see the module's note)."""

    def __init__(self, alias: str, target: str = "tracer"):
        self.alias, self.target = alias, target

    def find_spec(self, name, path=None, target=None):
        if name != self.alias and not name.startswith(self.alias + "."):
            return None
        return importlib.machinery.ModuleSpec(name, self)

    def create_module(self, spec):
        module = importlib.import_module(self.target + spec.name[len(self.alias):])
        spec.loader_state = module.__spec__  # (the import system sets __spec__ to ours: exec_module puts it back)
        return module

    def exec_module(self, module):
        module.__spec__ = module.__spec__.loader_state


def _share_the_checkouts_tracer() -> None:
    """In a checkout (``addon/tracer`` a link to, or on a system without links a file naming, ``../tracer``),
    alias ``<addon>.tracer`` to the top-level ``tracer`` package when that is the same files; a vendored copy,
    or a link beside some other ``tracer``, is imported as the subpackage it is."""
    here = os.path.join(os.path.dirname(os.path.abspath(__file__)), "tracer")
    if os.path.isdir(here) and not os.path.islink(here):
        return  # vendored
    spec = importlib.util.find_spec("tracer")
    if spec is None or not spec.submodule_search_locations:
        return
    top = os.path.realpath(spec.submodule_search_locations[0])
    if os.path.isdir(here) and top != os.path.realpath(here):
        return
    if not any(isinstance(f, SharedTracer) and f.alias == __name__ + ".tracer" for f in sys.meta_path):
        sys.meta_path.insert(0, SharedTracer(__name__ + ".tracer"))


_share_the_checkouts_tracer()


def _modules():
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
