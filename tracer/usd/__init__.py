"""OpenUSD interchange: SDL scenes to and from USD stages (``.usda``, ``.usd``, ``.usdc``).

Needs the ``usd-core`` package (``pxr``); everything else in the tracer works without it.  See docs/usd.md.
"""
from __future__ import annotations

from .common import USD_EXTENSIONS


def save_usd(scene, path) -> None:
    """Write ``scene`` to a USD file, atomically (see :func:`tracer.usd.writer.save_usd`)."""
    # deferred: the reader and writer are loaded by the commands that use them (the command line imports this
    # package for USD_EXTENSIONS; tests/test_cli.py: what a plain render must not load)
    from .writer import save_usd as save
    save(scene, path)


def load_usd(path, strict: bool = True, time=None):
    """Read a USD file into a :class:`tracer.model.Scene` at time code ``time`` (a frame; default: the start
    frame), see :func:`tracer.usd.reader.load_usd`."""
    from .reader import load_usd as load  # deferred: (as the writer)
    return load(path, strict=strict, time=time)


__all__ = ["USD_EXTENSIONS", "load_usd", "save_usd"]
