"""The lecture's camera and its rays, and a default camera for files that have none.

The camera has an eye, axes u (right), v (up) and n (pointing *back*, away from the view), and a window
in the near plane N = 1 that spans [-W, W] x [-H, H] with H = tan(viewAngle / 2) and W = H * aspect.
Rows count from the bottom and columns from the left, as in the lecture; unlike the lecture's pixel
corners, rays go through pixel *centres*, so the traced image overlays a rasterised preview exactly.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Optional, Sequence

import numpy as np

from .errors import SceneError
from .model import Camera, Scene

DEFAULT_VIEW_ANGLE = 40.0
#: Default camera direction (from the scene's centre toward the eye): in front, a little right and above
#: (SDL scenes are y-up).
DEFAULT_VIEW_DIRECTION = (0.45, 0.55, 1.0)


@dataclass(frozen=True)
class CameraFrame:
    eye: np.ndarray
    u: np.ndarray
    v: np.ndarray
    n: np.ndarray
    half_height: float  # H at N = 1
    half_width: float  # W at N = 1

    @classmethod
    def from_camera(cls, camera: Camera, aspect: float) -> "CameraFrame":
        eye = np.asarray(camera.eye, dtype=float)
        n = _unit(eye - np.asarray(camera.look, dtype=float))
        if n is None:
            raise SceneError("camera eye and look-at point coincide")
        up = _unit(np.asarray(camera.up, dtype=float))
        u = np.cross(up if up is not None else np.zeros(3), n)
        if not np.linalg.norm(u) > 1e-12:
            raise SceneError("camera up vector is parallel to the viewing direction")
        u /= np.linalg.norm(u)
        v = np.cross(n, u)
        if not 0.0 < camera.view_angle < 180.0:
            raise SceneError(f"camera view angle must be between 0 and 180 degrees, not {camera.view_angle}")
        h = math.tan(math.radians(camera.view_angle) / 2.0)
        return cls(eye, u, v, n, h, h * aspect)

    def to_world(self) -> np.ndarray:
        """The camera-to-world matrix, columns u, v, n, eye: a camera that looks down its -z with +y up,
        as Blender's and USD's cameras do."""
        m = np.eye(4)
        m[:3, 0], m[:3, 1], m[:3, 2], m[:3, 3] = self.u, self.v, self.n, self.eye
        return m

    def directions(self, rows: np.ndarray, cols: np.ndarray, n_rows: int, n_cols: int,
                   dy: np.ndarray | float = 0.5, dx: np.ndarray | float = 0.5) -> np.ndarray:
        """Directions of the rays through (row from bottom, column) + (dx, dy) within the pixel: (N, 3).

        ``dir = -n + W (2 (c + dx) / nCols - 1) u + H (2 (r + dy) / nRows - 1) v``; t = 1 is on the near plane.
        """
        su = self.half_width * (2.0 * (np.asarray(cols, float) + dx) / n_cols - 1.0)
        sv = self.half_height * (2.0 * (np.asarray(rows, float) + dy) / n_rows - 1.0)
        return -self.n[None, :] + su[:, None] * self.u[None, :] + sv[:, None] * self.v[None, :]


def _unit(vector: np.ndarray):
    """``vector`` scaled to length 1, or None if it is 0 or not finite.  Divided by its largest entry first,
    so that a vector of 1e308s (a camera far away) has a direction and one of 1e-300s does too."""
    with np.errstate(all="ignore"):
        largest = np.max(np.abs(vector))
        if not (np.isfinite(largest) and largest > 0):
            return None
        scaled = vector / largest
        return scaled / np.linalg.norm(scaled)


def focal_length(view_angle: float, film_height: float) -> float:
    """The focal length giving a vertical view angle (degrees) on a film ``film_height`` high (same unit)."""
    return film_height / (2.0 * math.tan(math.radians(view_angle) / 2.0))


def view_angle(focal: float, film_height: float) -> float:
    """The vertical view angle (degrees) of a film ``film_height`` high at distance ``focal``: the inverse of
    :func:`focal_length`."""
    return math.degrees(2.0 * math.atan(0.5 * film_height / focal))


def scene_bounds(compiled) -> tuple[np.ndarray, np.ndarray] | None:
    """World bounding box of the bounded primitives of a compiled scene, or None if there are none."""
    boxes = [c for c in (p.world_corners() for p in compiled.primitives if p.bounded) if c is not None]
    if not boxes:
        return None
    pts = np.concatenate(boxes)
    return pts.min(axis=0), pts.max(axis=0)


def framing_camera(compiled, aspect: float = 4 / 3) -> Camera:
    """A camera that sees the whole scene: from in front, a little right and above, the bounding sphere
    of the bounded objects filling the narrower of the two view angles."""
    bounds = scene_bounds(compiled)
    if bounds is None:
        center, radius = np.zeros(3), 1.0
    else:
        lo, hi = bounds
        half = 0.5 * hi - 0.5 * lo  # halved first: hi - lo of a scene reaching +-1e308 would overflow
        center, radius = 0.5 * lo + 0.5 * hi, max(float(np.linalg.norm(half)), 1e-9)
    half_v = math.radians(DEFAULT_VIEW_ANGLE) / 2.0
    half_h = math.atan(math.tan(half_v) * aspect)
    distance = 1.05 * radius / math.sin(min(half_v, half_h))
    direction = np.asarray(DEFAULT_VIEW_DIRECTION) / np.linalg.norm(DEFAULT_VIEW_DIRECTION)
    with np.errstate(over="ignore", invalid="ignore"):
        eye = center + distance * direction
    if not (np.all(np.isfinite(eye)) and np.all(np.isfinite(center))):
        source = getattr(compiled.scene, "source", None)
        raise SceneError(f"{source or 'scene'}: the scene is too large (about {radius:.3g} across) for an "
                          f"automatic camera: give one with 'camera'")
    return Camera(tuple(eye), tuple(center), (0.0, 1.0, 0.0), DEFAULT_VIEW_ANGLE)


def scene_camera(scene: Scene, compiled, aspect: float) -> Camera:
    return scene.camera if scene.camera is not None else framing_camera(compiled, aspect)


def camera_problem(eye: Sequence[float], look: Sequence[float], up: Sequence[float], angle: float) -> Optional[str]:
    """Why a camera statement's numbers make no camera, or None if they do."""
    forward = np.subtract(look, eye)
    if not np.any(forward):
        return "camera eye and look-at point are the same"
    if np.linalg.norm(np.cross(forward, up)) <= 1e-12 * np.linalg.norm(forward) * np.linalg.norm(up):
        return "camera up vector is zero or points along the view direction"
    if not 0.0 < angle < 180.0:
        return "camera view angle must be between 0 and 180 degrees"
    return None
