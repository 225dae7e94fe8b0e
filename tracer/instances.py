"""The numbers of an *instance row*: a mesh placed by a single-precision affine (Blender's matrices, a
ShapeTable's float32 ``affines``), which a compiled scene does not store but computes when asked.

A primitive of a compiled scene normally holds its inverse matrix (LAPACK's), its rounding terms and its
bounds: 248 bytes.  For 10^5 instances of one mesh that is most of what a render holds, so instance rows
(tracer.compile.PrimitiveTable.slot) keep only their float32 affine (the scene's own row) and their world box
in single precision (the C core's object box, 24 bytes); everything else is computed from those two, by
the C core each time a ray reaches the instance (numeric.h's ``instance_numbers``) and by the NumPy path
once for all rows it traces, with the same operations in the same order, so both get the same bits:

* the inverse by cofactors (the adjugate over the determinant), the translation carried back by it;
* its rounding, relative, as numerics.inverse_rounding measures it (the largest residual of inverse @
  matrix - I over |inverse| @ |matrix|), summed left to right instead of by BLAS;
* the norms the error bounds take (max row sum of |inverse's linear part|, max |inverse's translation|);
* a bounding sphere round the single-precision box.

The row's generic size is its mesh's (tracer.compile.MeshBound.generic_size), one number per mesh.
"""
from __future__ import annotations

import numpy as np

#: Relative padding of a bounding sphere's radius (as tracer.compile pads every primitive's).
SPHERE_PADDING = 1e-9
#: Relative padding of an object's world box: far above the rounding of any hit, and of the shapes' own
#: edge tolerances (1e-12 of their size), far below anything that costs time.
BOX_PADDING = 1e-8


def affine_inverses(affines: np.ndarray) -> np.ndarray:
    """The inverses (k, 4, 4) of (k, 12) affines (the top three rows of each matrix, row after row), by
    cofactors in float64, in numeric.h's instance_inverse order.  A singular or non-finite matrix gives
    non-finite entries (the caller checks)."""
    m = np.asarray(affines, dtype=np.float64).reshape(-1, 3, 4)
    a = [[m[:, r, c] for c in range(4)] for r in range(3)]
    # cofactors of the linear part: adj[i][j] = cofactor of a[j][i]
    adj = [[a[1][1] * a[2][2] - a[1][2] * a[2][1], a[0][2] * a[2][1] - a[0][1] * a[2][2],
            a[0][1] * a[1][2] - a[0][2] * a[1][1]],
           [a[1][2] * a[2][0] - a[1][0] * a[2][2], a[0][0] * a[2][2] - a[0][2] * a[2][0],
            a[0][2] * a[1][0] - a[0][0] * a[1][2]],
           [a[1][0] * a[2][1] - a[1][1] * a[2][0], a[0][1] * a[2][0] - a[0][0] * a[2][1],
            a[0][0] * a[1][1] - a[0][1] * a[1][0]]]
    det = a[0][0] * adj[0][0] + a[0][1] * adj[1][0] + a[0][2] * adj[2][0]
    out = np.zeros((len(m), 4, 4))
    out[:, 3, 3] = 1.0
    with np.errstate(all="ignore"):
        for i in range(3):
            for j in range(3):
                out[:, i, j] = adj[i][j] / det
        for i in range(3):
            out[:, i, 3] = -(out[:, i, 0] * a[0][3] + out[:, i, 1] * a[1][3] + out[:, i, 2] * a[2][3])
    return out


def affine_inverse_rounding(inverses: np.ndarray, affines: np.ndarray) -> np.ndarray:
    """The rounding (k,) of inverses (k, 4, 4) of (k, 12) affines, relative, as numerics.inverse_rounding
    defines it, with each product's terms summed left to right (numeric.h's instance_rounding): the bottom
    rows are exact, so the three top rows of inverse @ matrix are all there is."""
    m = np.asarray(affines, dtype=np.float64).reshape(-1, 3, 4)
    error = np.zeros(len(m))
    with np.errstate(all="ignore"):
        for i in range(3):
            for j in range(4):
                terms = [inverses[:, i, k] * m[:, k, j] for k in range(3)]
                sizes = [np.abs(inverses[:, i, k]) * np.abs(m[:, k, j]) for k in range(3)]
                product = terms[0] + terms[1] + terms[2]
                magnitude = sizes[0] + sizes[1] + sizes[2]
                if j == 3:
                    product = product + inverses[:, i, 3]
                    magnitude = magnitude + np.abs(inverses[:, i, 3])
                residual = np.abs(product - (1.0 if i == j else 0.0))
                relative = np.where(magnitude > 0, residual / np.where(magnitude > 0, magnitude, 1.0), 0.0)
                error = np.maximum(error, relative)
    return error


def inverse_norms(inverses: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(max row sum of |linear part|, max |translation|) of inverses (k, 4, 4), the sums left to right (NumPy's
    reductions over axes of three take several times longer, and the C core sums so)."""
    linear, translation = np.abs(inverses[:, :3, :3]), np.abs(inverses[:, :3, 3])
    sums = linear[:, :, 0] + linear[:, :, 1] + linear[:, :, 2]
    return (np.maximum(np.maximum(sums[:, 0], sums[:, 1]), sums[:, 2]),
            np.maximum(np.maximum(translation[:, 0], translation[:, 1]), translation[:, 2]))


def spheres_of_boxes(boxes: np.ndarray) -> np.ndarray:
    """Bounding spheres (k, 4: centre, radius) round single-precision boxes (k, 6: lo, hi), in float64 as
    numeric.h's instance_sphere: the centre halfway, the radius half the diagonal, padded by SPHERE_PADDING."""
    lo, hi = boxes[:, :3].astype(np.float64), boxes[:, 3:].astype(np.float64)
    out = np.empty((len(boxes), 4))
    out[:, :3] = 0.5 * (lo + hi)
    e = hi - lo
    out[:, 3] = np.sqrt(e[:, 0] * e[:, 0] + e[:, 1] * e[:, 1] + e[:, 2] * e[:, 2]) * 0.5 * (1 + SPHERE_PADDING)
    return out


def padded_boxes(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """World boxes (k, 6: lo, hi) padded relatively: by BOX_PADDING times the largest coordinate's size plus
    the box's longest side.  (The maxima over the three axes spelt out: NumPy's reductions over rows of three
    take several times longer.)"""
    size, side = np.maximum(np.abs(lo), np.abs(hi)), hi - lo
    pad = BOX_PADDING * (np.maximum(np.maximum(size[:, 0], size[:, 1]), size[:, 2])
                         + np.maximum(np.maximum(side[:, 0], side[:, 1]), side[:, 2]))
    boxes = np.empty((len(lo), 6))
    np.subtract(lo, pad[:, None], out=boxes[:, :3])
    np.add(hi, pad[:, None], out=boxes[:, 3:])
    return boxes


def single_boxes(boxes: np.ndarray) -> np.ndarray:
    """(k, 6) boxes (lo, hi) in single precision, each axis's bounds put in order (as the C core's slab test
    takes them) and rounded outward, so that they still hold what they held: the C core's hierarchy keeps
    its boxes so (bvh_build.h), and an object's box as a float is what that hierarchy is built from.  A NaN
    bound stays NaN (no constraint on that axis)."""
    lo, hi = np.minimum(boxes[:, :3], boxes[:, 3:]), np.maximum(boxes[:, :3], boxes[:, 3:])
    out = np.empty((len(boxes), 6), dtype=np.float32)
    with np.errstate(all="ignore"):  # (overflow to inf, NaN, denormals: rounded as they come)
        for side, bound, toward in ((slice(0, 3), lo, -np.inf), (slice(3, 6), hi, np.inf)):
            rounded = bound.astype(np.float32)
            off = rounded > bound if toward < 0 else rounded < bound
            out[:, side] = np.where(off, np.nextafter(rounded, np.float32(toward)), rounded)
    return out
