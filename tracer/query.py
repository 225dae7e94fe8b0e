"""``hits()``: the lecture's hand computation as an API — every place a ray crosses the scene's surfaces."""
from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence, Union

import numpy as np

from .compile import CompiledScene, compile_scene
from .errors import SceneError
from .model import Scene, Shape


@dataclass(frozen=True)
class Hit:
    t: float  # in units of the direction as given: point = start + t * direction
    entering: bool  # the ray goes into the object here
    point: tuple[float, float, float]
    normal: tuple[float, float, float]  # unit, world space, pointing out of the object
    shape: Shape  # the primitive whose surface this is


def hits(scene: Union[Scene, CompiledScene], start: Sequence[float], direction: Sequence[float]) -> list[Hit]:
    """All hits with t > 0 of the ray ``start + t * direction`` with the scene's objects, sorted by t.

    CSG objects contribute only the hits that bound the boolean's result.
    """
    compiled = scene if isinstance(scene, CompiledScene) else compile_scene(scene)
    origin = np.asarray(start, dtype=float).reshape(1, 3)
    dirn = np.asarray(direction, dtype=float).reshape(1, 3)
    if not (np.all(np.isfinite(origin)) and np.all(np.isfinite(dirn))) or not np.any(dirn):
        raise SceneError("a ray needs a finite start and a finite, non-zero direction")
    found: list[Hit] = []
    for obj in compiled.objects:
        h = obj.intersect(origin, dirn)
        for k in range(h.slots):
            t = float(h.t[0, k])
            if not (np.isfinite(t) and t > 0.0):
                continue
            normal = h.normal[0, k] / np.linalg.norm(h.normal[0, k])
            point = origin[0] + t * dirn[0]
            found.append(Hit(t, bool(h.entering[0, k]), tuple(point.tolist()), tuple(normal.tolist()),
                             compiled.primitives[int(h.shape[0, k])].shape))
    found.sort(key=lambda hit: hit.t)
    return found
