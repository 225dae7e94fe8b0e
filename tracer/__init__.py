"""An exact Whitted ray tracer for F. S. Hill's Scene Description Language (SDL).

    >>> import tracer
    >>> scene = tracer.parse_sdl("light 4 4 4 1 1 1  sphere")
    >>> [round(h.t, 4) for h in tracer.hits(scene, (3, 2, 3), (-3, -2, -3))]
    [0.7868, 1.2132]
"""
from . import startup as _startup

if _startup.started_as_the_program():  # (before NumPy is imported: see tracer/startup.py)
    _startup.hear_signals_at_once()  # (before any other import: tracer.signals takes over in a moment)
    from . import signals as _signals

    _signals.install_at_start()  # SIGINT and SIGTERM end the program at once until its command starts
    _startup.prepare_the_program()

from .errors import RenderCancelled, SDLError, TracerError
from .model import CSG, Camera, Light, Material, MeshData, Scene, Settings, Shape
from .query import Hit, hits
from .render import RenderResult, TileUpdate, render
from .sdl.parser import load, parse_sdl

__all__ = ["CSG", "Camera", "Hit", "Light", "Material", "MeshData", "RenderCancelled", "RenderResult",
           "SDLError", "Scene", "Settings", "Shape", "TileUpdate", "TracerError", "hits", "load",
           "parse_sdl", "render"]
__version__ = "0.1.0"
