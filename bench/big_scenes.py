"""Large scenes for the scaling benchmarks, written on demand (never committed: 1M triangles is ~85 MB).

    python3 bench/big_scenes.py mesh 1000000 out/torus1m.3vn     # a torus of ~N triangles, with normals
    python3 bench/big_scenes.py mesh-scene 1000000 out/torus1m.sdl  # ... and an SDL scene that uses it
    python3 bench/big_scenes.py spheres 100000 out/spheres1e5.sdl  # N small spheres, one SDL line each

The torus is a (rings x segments) grid of quads, each split into two triangles, with one unit normal per
vertex: a closed, smooth surface whose triangles are all about the same size, like a scanned model.
"""
from __future__ import annotations

import argparse
import math
import sys
from pathlib import Path

import numpy as np


def torus_arrays(triangles: int, ring: float = 1.0, tube: float = 0.35):
    """Vertices (V, 3), unit normals (V, 3) and triangles (T, 3) of a torus with about ``triangles``
    triangles (T = 2 V; the tube gets a third as many segments as the ring)."""
    quads = max(triangles // 2, 12)
    segments = max(3, int(round(math.sqrt(quads / 3.0))))
    rings = max(3, quads // segments)
    u = np.linspace(0, 2 * np.pi, rings, endpoint=False)[:, None]
    v = np.linspace(0, 2 * np.pi, segments, endpoint=False)[None, :]
    centre = np.stack([np.cos(u), np.sin(u), np.zeros_like(u)], axis=-1)  # (R, 1, 3)
    normal = np.stack([np.cos(u) * np.cos(v), np.sin(u) * np.cos(v), np.broadcast_to(np.sin(v), (rings, segments))],
                      axis=-1)
    vertices = (ring * centre + tube * normal).reshape(-1, 3)
    normals = normal.reshape(-1, 3)
    i = np.arange(rings)[:, None]
    j = np.arange(segments)[None, :]
    a = i * segments + j
    b = ((i + 1) % rings) * segments + j
    c = ((i + 1) % rings) * segments + (j + 1) % segments
    d = i * segments + (j + 1) % segments
    faces = np.concatenate([np.stack([a, b, c], -1).reshape(-1, 3), np.stack([a, c, d], -1).reshape(-1, 3)])
    return vertices, normals, faces


def write_torus_3vn(path: Path, triangles: int) -> int:
    """Write the torus as .3vn (vertex i uses normal i); returns the number of triangles written."""
    vertices, normals, faces = torus_arrays(triangles)
    with open(path, "w", encoding="ascii") as out:
        out.write(f"{len(vertices)} {len(normals)} {len(faces)}\n")
        out.write("\n".join(_rows("%.7f %.7f %.7f", vertices)) + "\n")
        out.write("\n".join(_rows("%.6f %.6f %.6f", normals)) + "\n")
        out.write("\n".join(_rows("3 %d %d %d %d %d %d", np.concatenate([faces, faces], axis=1))) + "\n")
    return len(faces)


def _rows(fmt: str, array: np.ndarray):
    for start in range(0, len(array), 65536):
        chunk = array[start:start + 65536]
        yield "\n".join(fmt % tuple(row) for row in chunk.tolist())


def mesh_scene(mesh_file: str) -> str:
    """A scene with the mesh seen at an angle, a floor and two lights."""
    return "\n".join([
        "! written by bench/big_scenes.py", "camera 0 -3.2 2.2  0 0 0  0 0 1  40", "light 3 -4 6  1 1 1",
        "light -4 -2 3  0.4 0.4 0.4", "background 0.1 0.1 0.15", "globalAmbient 0.2 0.2 0.2",
        "push diffuse 0.5 0.5 0.5 translate 0 0 -0.4 plane pop",
        "diffuse 0.8 0.5 0.3 specular 0.4 0.4 0.4 specularExponent 30",
        f"push rotate 30 1 0 0 mesh {mesh_file} pop", ""])


def sphere_lines(count: int, seed: int = 1) -> str:
    """``count`` random small spheres above a plane, two lights: one SDL line per sphere."""
    sys.path.insert(0, str(Path(__file__).resolve().parent))
    from run import sphere_scene
    return sphere_scene(count, seed)


def main(argv=None) -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("what", choices=("mesh", "mesh-scene", "spheres"))
    p.add_argument("count", type=int)
    p.add_argument("out")
    args = p.parse_args(argv)
    out = Path(args.out)
    out.parent.mkdir(parents=True, exist_ok=True)
    if args.what == "spheres":
        out.write_text(sphere_lines(args.count))
    elif args.what == "mesh":
        write_torus_3vn(out, args.count)
    else:
        mesh = out.with_suffix(".3vn")
        write_torus_3vn(mesh, args.count)
        out.write_text(mesh_scene(mesh.name))
    return 0


if __name__ == "__main__":
    sys.exit(main())
