"""Generic geometry: the built-in polyhedra, the teapot, and tessellation."""
from __future__ import annotations

import functools


@functools.lru_cache(maxsize=None)
def builtin_mesh(kind: str):
    """The MeshData of a built-in polyhedron or the teapot, one object per kind (what every shape of that kind
    holds, whichever reader made it).

    The result is cached because a scene may hold a million copies of one polyhedron."""
    if kind == "teapot":
        # deferred: the teapot's patches and the polyhedra are loaded by the first scene that uses them, not
        # by every import of the model
        from .teapot import teapot_mesh
        return teapot_mesh()
    from .polyhedra import polyhedron_mesh  # deferred: (as the teapot)
    return polyhedron_mesh(kind)
