"""Numbers between SDL and Blender (pure NumPy, no bpy).

* Axes: SDL files are y-up with the camera looking down -z; Blender is z-up.  The default conversion is the
  one Blender's own importers use for y-up formats (forward -Z, up Y), a quarter turn about x.  Its matrix
  holds only 0 and +-1, so converting in float64 is exact both ways.
* Exactness: Blender keeps matrices and properties in float32.  The add-on keeps the exact float64 values
  from the file beside them (custom properties) with a *snapshot* of what Blender showed when they were
  stored; as long as Blender still shows the snapshot the exact values are used, and once the user edits
  the Blender value, that value is (see :func:`recall`).
* Transforms Blender cannot hold: an object's transform is translation x rotation x scale, with no
  shear.  :func:`split_shear` factors a sheared linear map into a part an object can hold and a rotation
  that goes into the mesh.
"""
from __future__ import annotations

from typing import Sequence

import numpy as np

from ..tracer.transforms import rotation_scale_rotation

_AXES = {"X": (0, 1.0), "Y": (1, 1.0), "Z": (2, 1.0), "-X": (0, -1.0), "-Y": (1, -1.0), "-Z": (2, -1.0)}


def _basis(forward: str, up: str) -> np.ndarray:
    """Rows: the file's right, forward and up directions as unit vectors of its own frame."""
    f_axis, f_sign = _AXES[forward]
    u_axis, u_sign = _AXES[up]
    if f_axis == u_axis:
        raise ValueError(f"forward {forward} and up {up} must be different axes")
    fwd = np.zeros(3)
    fwd[f_axis] = f_sign
    upv = np.zeros(3)
    upv[u_axis] = u_sign
    right = np.cross(fwd, upv)
    return np.array([right, fwd, upv])


def axis_matrix(forward: str = "-Z", up: str = "Y") -> np.ndarray:
    """4x4 matrix taking a file whose forward and up axes are ``forward``/``up`` to Blender's frame
    (forward +Y, up +Z), as ``bpy_extras.io_utils.axis_conversion(from_forward, from_up)`` does."""
    # Blender's frame has right = +X, forward = +Y, up = +Z, so the rows of _basis map file -> Blender.
    m = np.eye(4)
    m[:3, :3] = _basis(forward, up)
    return m


def to_blender(matrix: np.ndarray, conversion: np.ndarray) -> np.ndarray:
    return conversion @ np.asarray(matrix, dtype=np.float64)


def from_blender(matrix: np.ndarray, conversion: np.ndarray) -> np.ndarray:
    # The conversion is a signed permutation: its inverse is its transpose, exactly.
    inverse = np.eye(4)
    inverse[:3, :3] = conversion[:3, :3].T
    return inverse @ np.asarray(matrix, dtype=np.float64)


def points_to_blender(points, conversion: np.ndarray) -> np.ndarray:
    return np.asarray(points, dtype=np.float64) @ conversion[:3, :3].T


def points_from_blender(points, conversion: np.ndarray) -> np.ndarray:
    return np.asarray(points, dtype=np.float64) @ conversion[:3, :3]


# ---------------------------------------------------------------------------------------------------------
# Exact values kept beside float32 ones

def shortest32(value: float) -> float:
    """The float32 ``value`` as the shortest decimal that reads back to it (0.1f -> 0.1, not 0.100000001)."""
    return float(str(np.float32(value)))


def unchanged(shown_now: Sequence[float], snapshot: Sequence[float], relative: float = 1e-6) -> bool:
    """Whether Blender still shows the snapshot (to float32 noise, each number relative to its size but at
    least 1: Blender recomposes matrices from location/rotation/scale, which moves the last bits)."""
    a = np.asarray(shown_now, dtype=np.float64).ravel()
    b = np.asarray(snapshot, dtype=np.float64).ravel()
    return a.shape == b.shape and bool(np.all(np.abs(a - b) <= relative * np.maximum(1.0, np.abs(b))))


def recall(exact: Sequence[float] | None, snapshot: Sequence[float] | None,
           shown_now: Sequence[float]) -> list[float]:
    """The exact values if Blender still shows, bit for bit, the snapshot taken with them, else what it shows
    now (each number as its shortest float32 decimal)."""
    if exact is not None and snapshot is not None and list(map(float, shown_now)) == list(map(float, snapshot)):
        return [float(v) for v in exact]
    return [shortest32(v) for v in shown_now]


# ---------------------------------------------------------------------------------------------------------
# Shear

def has_shear(linear: np.ndarray, tolerance: float = 1e-9) -> bool:
    """True if the columns of a 3x3 map are not orthogonal (an object's scale and rotation cannot hold it)."""
    gram = np.asarray(linear, dtype=np.float64).T @ np.asarray(linear, dtype=np.float64)
    off = gram - np.diag(np.diag(gram))
    return bool(np.max(np.abs(off)) > tolerance * max(float(np.max(np.abs(np.diag(gram)))), 1e-300))


def split_shear(matrix: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Factor an affine ``matrix`` = ``object_part @ mesh_part`` where ``object_part`` is translation x
    rotation x scale (columns orthogonal, what an object can hold) and ``mesh_part`` a rotation (4x4, no
    translation) to bake into the mesh.  Without shear ``mesh_part`` is the identity."""
    matrix = np.asarray(matrix, dtype=np.float64)
    linear = matrix[:3, :3]
    if not has_shear(linear):
        return matrix.copy(), np.eye(4)
    u, s, vt = rotation_scale_rotation(linear)
    obj = np.eye(4)
    obj[:3, :3] = u * s  # U diag(s): orthogonal columns
    obj[:3, 3] = matrix[:3, 3]
    mesh = np.eye(4)
    mesh[:3, :3] = vt
    return obj, mesh
