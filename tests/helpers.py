"""Small builders shared by the tests: scenes made directly from the model, no SDL needed."""
from __future__ import annotations

import numpy as np

from tracer.model import Camera, Light, Material, Scene, Settings, Shape
from tracer.transforms import rotation, scaling, translation

__all__ = ["shape", "scene_of", "rotation", "scaling", "translation", "Material", "Camera", "Light", "ray_hits"]


def shape(kind: str, matrix=None, **material) -> Shape:
    return Shape(kind, np.eye(4) if matrix is None else matrix, Material(**material))


def scene_of(*objects, lights=(), camera=None, **settings) -> Scene:
    return Scene(objects=list(objects), lights=list(lights), camera=camera, settings=Settings(**settings))


def ray_hits(scene, start, direction):
    """(t, entering) pairs of tracer.hits, for compact assertions."""
    import tracer

    return [(h.t, h.entering) for h in tracer.hits(scene, start, direction)]
