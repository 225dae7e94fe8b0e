"""Small builders shared by the tests: scenes made directly from the model, no SDL needed."""
from __future__ import annotations

import numpy as np

from tracer.model import Camera, Light, Material, Scene, Settings, Shape
from tracer.transforms import rotation, scaling, translation

__all__ = ["shape", "scene_of", "rotation", "scaling", "translation", "Material", "Camera", "Light", "ray_hits",
           "hits_on", "scaled"]


def shape(kind: str, matrix=None, **material) -> Shape:
    return Shape(kind, np.eye(4) if matrix is None else matrix, Material(**material))


def scene_of(*objects, lights=(), camera=None, **settings) -> Scene:
    return Scene(objects=list(objects), lights=list(lights), camera=camera, settings=Settings(**settings))


def hits_on(backend: str, scene, start, direction) -> list:
    """tracer.hits (every crossing with t > 0, sorted, as tracer.query.Hit) computed by ``backend``: "numpy"
    is tracer.hits itself, "c" the C core's whole-line hits of each object."""
    import tracer
    from tracer.compile import CompiledScene, compile_scene
    from tracer.query import Hit

    if backend == "numpy":
        return tracer.hits(scene, start, direction)
    from tracer.native.tracer import NativeTracer

    compiled = scene if isinstance(scene, CompiledScene) else compile_scene(scene)
    core = NativeTracer(compiled, threads=1)
    origin, dirn = np.asarray(start, dtype=float), np.asarray(direction, dtype=float)
    found = []
    for k in range(len(compiled.objects)):
        h = core.object_hits(k, origin, dirn)
        for j in range(h.t.shape[1]):
            t = float(h.t[0, j])
            if t > 0.0:
                normal = h.normal[0, j] / np.linalg.norm(h.normal[0, j])
                found.append(Hit(t, bool(h.entering[0, j]), tuple((origin + t * dirn).tolist()),
                                 tuple(normal.tolist()), compiled.primitives[int(h.shape[0, j])].shape))
    return sorted(found, key=lambda hit: hit.t)


def ray_hits(scene, start, direction, backend: str = "numpy"):
    """(t, entering) pairs of tracer.hits (by ``backend``, see hits_on), for compact assertions."""
    return [(h.t, h.entering) for h in hits_on(backend, scene, start, direction)]


def scaled(backend: str, width: int, height: int) -> tuple[int, int]:
    """The image size a test on both backends renders (see the ``backend`` fixture in conftest.py): as asked
    for the C core, half of each side (at least 16) for the NumPy path, so that running a test twice costs
    little more than running it once."""
    if backend == "numpy":
        return max(16, width // 2), max(16, height // 2)
    return width, height


def assert_closed_and_outward(data) -> None:
    """A tessellation (MeshData) is closed and wound counter-clockwise seen from outside: every directed edge
    once and its reverse once, and each face's normal agrees with its corners' normals."""
    v = np.asarray(data.vertices)
    edges: dict[tuple[int, int], int] = {}
    for verts, norms in data.faces:
        for a, b in zip(verts, verts[1:] + verts[:1]):
            edges[(a, b)] = edges.get((a, b), 0) + 1
        p = v[list(verts)]
        face_normal = np.cross(p[1] - p[0], p[2] - p[0])
        assert np.all(np.asarray(data.normals)[list(norms)] @ face_normal > 0)
    assert all(count == 1 and edges.get((b, a)) == 1 for (a, b), count in edges.items())
