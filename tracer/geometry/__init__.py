"""Generic geometry: the built-in polyhedra, the teapot, and tessellation."""
from __future__ import annotations

import functools


@functools.lru_cache(maxsize=None)
def builtin_mesh(kind: str):
    """The MeshData of a built-in polyhedron or the teapot, one object per kind (what every shape of that kind
    holds, whichever reader made it).

    The modules are imported here, not at the top, so that the model and the parser load (and their tests
    run) without the geometry modules, and the result is cached because a scene may hold a million copies
    of one polyhedron."""
    if kind == "teapot":
        from .teapot import teapot_mesh
        return teapot_mesh()
    from .polyhedra import polyhedron_mesh
    return polyhedron_mesh(kind)
