"""One exception family for what users see: input the tracer cannot use is a TracerError (so the CLI and the
add-on print one line), and still the ValueError it used to be for callers that catch that."""
from __future__ import annotations

import math

import numpy as np
import pytest

import tracer
from tracer.camera import CameraFrame
from tracer.errors import SceneError, TracerError, WriteError
from tracer.meshio import write_3vn
from tracer.model import Camera, MeshData, Shape
from tracer.render import render
from tracer.sdl.writer import save_sdl
from tracer.transforms import rotation


@pytest.mark.parametrize("make, fragment", [
    (lambda: Shape("blob"), "unknown shape kind 'blob'"),
    (lambda: CameraFrame.from_camera(Camera(eye=(0, 0, 5), look=(0, 0, 5)), 1.0), "coincide"),
    (lambda: rotation(30, 0, 0, 0), "rotation axis"),
])
def test_bad_scene_values_are_scene_errors(make, fragment):
    with pytest.raises(SceneError, match=fragment) as caught:
        make()
    assert isinstance(caught.value, TracerError) and isinstance(caught.value, ValueError)


def test_a_scene_built_in_python_with_a_bad_camera_fails_as_a_tracer_error():
    scene = tracer.parse_sdl("light 1 2 3 1 1 1  sphere")
    scene.camera = Camera(eye=(0, 0, 5), look=(0, 0, 5))
    with pytest.raises(TracerError, match="coincide"):
        render(scene, 4, 3, backend="numpy")


def test_what_a_format_cannot_express_is_a_write_error(tmp_path):
    scene = tracer.parse_sdl("light 1 2 3 1 1 1  sphere")
    scene.settings.background = (math.nan, 0.0, 0.0)
    with pytest.raises(WriteError, match="nan"):
        save_sdl(scene, tmp_path / "out.sdl")
    assert not (tmp_path / "out.sdl").exists()
    mesh = MeshData(vertices=np.array([[0.0, 0.0, math.inf]] * 3), normals=np.zeros((0, 3)), faces=[((0, 1, 2), (-1, -1, -1))])
    with pytest.raises(WriteError, match="non-finite"):
        write_3vn(mesh, tmp_path / "m.3vn")
