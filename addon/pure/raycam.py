"""Rays for Blender's camera, exactly as Blender projects (pure NumPy, no bpy).

Blender's view plane (``BKE_camera_params_compute_viewplane``): the sensor size that the sensor fit picks
(``AUTO`` fits the longer side of the image, counted in pixels times pixel aspect), divided by the focal
length, spans ``winx`` pixels (horizontal fit) or ``winy * ycor`` (vertical fit, ``ycor`` = pixel aspect
y / x); shift moves the plane by that many image widths (or heights); orthographic cameras span
``ortho_scale`` instead.  Rays go through pixel *centres*, as a rasteriser samples them, and start on
the near clipping plane, as Blender draws nothing nearer.

Rows count from the bottom of the full frame and columns from its left (Blender's pixel order).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class CameraParams:
    matrix: np.ndarray  # the camera object's world matrix (4x4); it looks down its local -Z, up is +Y
    ortho: bool = False
    lens: float = 50.0  # focal length, mm
    sensor_width: float = 36.0
    sensor_height: float = 24.0
    sensor_fit: str = "AUTO"  # AUTO, HORIZONTAL, VERTICAL
    ortho_scale: float = 6.0
    shift_x: float = 0.0
    shift_y: float = 0.0
    clip_start: float = 0.1

    def frame(self) -> tuple[np.ndarray, np.ndarray]:
        """(position, 3x3 rotation with unit columns): Blender normalises the camera's matrix."""
        m = np.asarray(self.matrix, dtype=np.float64)
        axes = m[:3, :3] / np.linalg.norm(m[:3, :3], axis=0)
        return m[:3, 3].copy(), axes


def fit(sensor_fit: str, width: float, height: float) -> str:
    if sensor_fit == "AUTO":
        return "HORIZONTAL" if width >= height else "VERTICAL"
    return sensor_fit


def viewplane(cam: CameraParams, winx: int, winy: int, aspx: float = 1.0, aspy: float = 1.0):
    """(xmin, xmax, ymin, ymax) of the view plane: at distance 1 for perspective, in world units for
    orthographic cameras."""
    ycor = aspy / aspx
    if cam.ortho:
        pixsize = cam.ortho_scale
    else:
        sensor = cam.sensor_height if cam.sensor_fit == "VERTICAL" else cam.sensor_width
        pixsize = sensor / cam.lens
    viewfac = winx if fit(cam.sensor_fit, aspx * winx, aspy * winy) == "HORIZONTAL" else ycor * winy
    pixsize /= viewfac
    dx = cam.shift_x * viewfac
    dy = cam.shift_y * viewfac
    return ((-0.5 * winx + dx) * pixsize, (0.5 * winx + dx) * pixsize,
            (-0.5 * ycor * winy + dy) * pixsize, (0.5 * ycor * winy + dy) * pixsize)


def pixel_rays(cam: CameraParams, winx: int, winy: int, rows, cols, aspx: float = 1.0, aspy: float = 1.0,
               dy=0.5, dx=0.5):
    """(origins, directions), each (N, 3) float64, of the rays through the given pixels of a ``winx`` x
    ``winy`` frame, at (dx, dy) inside each pixel (default: its centre)."""
    rows = np.asarray(rows, dtype=np.float64).ravel()
    cols = np.asarray(cols, dtype=np.float64).ravel()
    xmin, xmax, ymin, ymax = viewplane(cam, winx, winy, aspx, aspy)
    x = xmin + (cols + dx) * ((xmax - xmin) / winx)
    y = ymin + (rows + dy) * ((ymax - ymin) / winy)
    position, axes = cam.frame()
    if cam.ortho:
        local = np.column_stack([x, y, np.full_like(x, -cam.clip_start)])
        origins = position + local @ axes.T
        directions = np.broadcast_to(-axes[:, 2], origins.shape).copy()
    else:
        local = np.column_stack([x, y, -np.ones_like(x)])
        directions = local @ axes.T
        origins = position + cam.clip_start * directions
    return origins, directions


def projection_rays(perspective_matrix: np.ndarray, width: int, height: int, rows, cols, dy=0.5, dx=0.5):
    """Rays through region pixels (at (dx, dy) inside each, default the centre) for a viewport, from its
    ``perspective_matrix`` (window @ view): each starts on the near clipping plane and points to the far one."""
    inverse = np.linalg.inv(np.asarray(perspective_matrix, dtype=np.float64))
    rows = np.asarray(rows, dtype=np.float64).ravel()
    cols = np.asarray(cols, dtype=np.float64).ravel()
    ndc_x = 2.0 * (cols + dx) / width - 1.0
    ndc_y = 2.0 * (rows + dy) / height - 1.0

    def unproject(z: float) -> np.ndarray:
        clip = np.column_stack([ndc_x, ndc_y, np.full_like(ndc_x, z), np.ones_like(ndc_x)]) @ inverse.T
        return clip[:, :3] / clip[:, 3:4]

    near = unproject(-1.0)
    far = unproject(1.0)
    directions = far - near
    directions /= np.linalg.norm(directions, axis=1, keepdims=True)
    return near, directions


def border_rect(winx: int, winy: int, use_border: bool, border) -> tuple[int, int, int, int]:
    """(x0, y0, x1, y1) of the pixels a render covers: the whole frame, or Blender's render border
    (``int(min * size)`` to ``int(max * size)``, as Blender truncates)."""
    if not use_border:
        return 0, 0, winx, winy
    f = np.float32
    min_x, max_x, min_y, max_y = border
    x0, x1 = int(f(min_x) * f(winx)), int(f(max_x) * f(winx))
    y0, y1 = int(f(min_y) * f(winy)), int(f(max_y) * f(winy))
    x1 = max(x1, x0 + 1)
    y1 = max(y1, y0 + 1)
    return x0, y0, min(x1, winx), min(y1, winy)
