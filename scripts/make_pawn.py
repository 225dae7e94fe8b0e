"""Write scenes/meshes/pawn.3vn: a chess pawn as a surface of revolution (closed, not convex).

Run from the repository root: ``python scripts/make_pawn.py [segments]``.  The mesh is y-up, stands
on y = 0, is about 2.2 high and 1.6 wide, with one smooth normal per vertex.
"""
from __future__ import annotations

import sys

import numpy as np

# (radius, height) from the bottom centre to the top of the head; radius 0 at both ends closes it.
PROFILE = [(0.0, 0.0), (0.8, 0.0), (0.8, 0.12), (0.7, 0.2), (0.55, 0.28), (0.5, 0.35), (0.55, 0.42),
           (0.42, 0.5), (0.32, 0.7), (0.26, 0.95), (0.24, 1.2), (0.4, 1.28), (0.42, 1.34), (0.28, 1.4)]


def head(steps: int = 12) -> list[tuple[float, float]]:
    """A ball of radius 0.42 centred at y = 1.75, from just above the collar to the top pole."""
    start = np.arcsin(0.28 / 0.42) - np.pi / 2  # meets the collar at radius 0.28 below the centre
    angles = np.linspace(start, np.pi / 2, steps)
    return [(0.42 * np.cos(a), 1.75 + 0.42 * np.sin(a)) for a in angles[1:]][:-1] + [(0.0, 2.17)]


def lathe(profile, segments: int):
    prof = np.asarray(profile, dtype=float)
    # Per profile point, the outward normal in the (r, y) plane from the neighbouring points.
    tangent = np.gradient(prof, axis=0)
    normal2 = np.stack([tangent[:, 1], -tangent[:, 0]], axis=1)
    normal2 /= np.linalg.norm(normal2, axis=1, keepdims=True)
    normal2[0], normal2[-1] = (0.0, -1.0), (0.0, 1.0)  # the poles look straight down and up
    angles = np.linspace(0.0, 2 * np.pi, segments, endpoint=False)
    verts, norms, index = [], [], {}
    for i, (r, y) in enumerate(prof):
        ring = [0] if r == 0.0 else range(segments)
        for j in ring:
            index[i, j] = len(verts)
            c, s = np.cos(angles[j]), np.sin(angles[j])
            verts.append((r * c, y, -r * s))
            nr, ny = normal2[i]
            norms.append((nr * c, ny, -nr * s))
    faces = []
    for i in range(len(prof) - 1):
        for j in range(segments):
            k = (j + 1) % segments
            quad = [index.get((i, j), index.get((i, 0))), index.get((i, k), index.get((i, 0))),
                    index.get((i + 1, k), index.get((i + 1, 0))), index.get((i + 1, j), index.get((i + 1, 0)))]
            ring = [v for n, v in enumerate(quad) if v != quad[n - 1]]  # collapse pole corners
            faces.append(ring)
    return np.array(verts), np.array(norms), faces


def main() -> None:
    segments = int(sys.argv[1]) if len(sys.argv) > 1 else 40
    verts, norms, faces = lathe(PROFILE + head(), segments)
    with open("scenes/meshes/pawn.3vn", "w") as out:
        out.write(f"{len(verts)} {len(norms)} {len(faces)}\n")
        for v in verts:
            out.write("%.6f %.6f %.6f\n" % tuple(v))
        for n in norms:
            out.write("%.6f %.6f %.6f\n" % tuple(n))
        for f in faces:
            out.write(f"{len(f)} {' '.join(map(str, f))} {' '.join(map(str, f))}\n")


if __name__ == "__main__":
    main()
