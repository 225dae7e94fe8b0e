"""Where the add-on finds the ``tracer`` package.

Installed as an extension (or as a legacy add-on zip) the tracer is vendored *inside* the add-on package,
as ``<addon>.tracer``; in a development checkout or in the tests it is the ``tracer`` package of the
environment.  Everything in the add-on imports tracer modules through :func:`module`, so both work
without touching ``sys.path``.
"""
from __future__ import annotations

import importlib
from types import ModuleType


def _locate() -> str:
    vendored = f"{__package__}.tracer"
    try:
        importlib.import_module(vendored)
    except ModuleNotFoundError as exc:
        if exc.name != vendored:  # the vendored copy exists but something it needs is missing
            raise
        importlib.import_module("tracer")
        return "tracer"
    return vendored


#: The importable name of the tracer package in use ("tracer", or "<addon package>.tracer").
TRACER = _locate()


def module(name: str = "") -> ModuleType:
    """A tracer module by its name inside the package: ``module("sdl.parser")``; ``module()`` is the package."""
    return importlib.import_module(f"{TRACER}.{name}" if name else TRACER)
