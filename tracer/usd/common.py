"""What the USD writer and reader share: attribute names, axis frames, matrix conversion, the pxr import.

Matrices: ours are column-vector 4x4 (``world = M @ generic``, translation in the last column); USD's
``GfMatrix4d`` is row-vector (``p' = p * U``, translation in the last row), so ``U = M.T`` -- an exact
conversion both ways.
"""
from __future__ import annotations

import numpy as np

from .. import signals
from ..errors import TracerError
from ..model import iter_shapes

#: File extensions USD reads and writes (the format of ``.usd`` is binary crate).
USD_EXTENSIONS = (".usda", ".usd", ".usdc")

#: The root prim: stage default prim, scene settings as attributes.
ROOT = "/SDLScene"
OBJECTS = ROOT + "/Objects"
LIGHTS = ROOT + "/Lights"
MATERIALS = ROOT + "/Materials"
CAMERA = ROOT + "/Camera"

#: Namespaced attributes.  Colours are ``color3d`` and numbers ``double`` so that every value round-trips
#: exactly (the schema attributes are mostly float).
NS = "sdl:"
A_SHAPE = "sdl:shape"  # the SDL keyword (a tessellated kind's parameters: ShapeKind.parameters' usd_attribute)
A_MESH_FILE = "sdl:meshFile"  # mesh statement's file, relative to the USD file's folder
A_MESH_POINTS = "sdl:meshPoints"  # double3[]: the mesh's vertices, exactly
A_MESH_NORMALS = "sdl:meshNormals"  # double3[]: the mesh's normal list, exactly
A_MESH_NORMAL_INDICES = "sdl:meshNormalIndices"  # int[], one per face corner; -1 for faces without normals
A_MESH_UVS = "sdl:meshUVs"  # double2[], one per face corner: MeshData.corner_uvs exactly (primvars:st for others)
A_MATRIX = "sdl:matrix"  # matrix4d: our exact matrix (USD convention) where the prim's own op differs
A_GROUPS = "sdl:groups"  # string[]: def macros the object was made in
A_CSG = "sdl:csg"  # token on a CSG group: union, intersection, difference
A_OPERAND = "sdl:operand"  # token on a CSG child: left, right
#: A chain (sdl:csg = "chain", for booleans nested deeper than the writer's CHAIN_DEPTH): its first child is
#: where the chain starts; each later child is combined with what came before by its sdl:chainOp (union,
#: intersection, difference), on the side its sdl:chainSide names ("right": before op child; "left": child op
#: before), the boolean taking that child's sdl:chainGroups.
CHAIN = "chain"
A_CHAIN_OP = "sdl:chainOp"
A_CHAIN_SIDE = "sdl:chainSide"
A_CHAIN_GROUPS = "sdl:chainGroups"
A_LIGHT_COLOR = "sdl:color"  # double3 on a light
A_EYE, A_LOOK, A_UP, A_VIEW_ANGLE = "sdl:eye", "sdl:look", "sdl:up", "sdl:viewAngle"
A_VERSION = "sdl:version"

#: Material fields and their SDL keywords (attribute ``sdl:<keyword>``).
MATERIAL_COLORS = {"ambient": "ambient", "diffuse": "diffuse", "specular": "specular", "emissive": "emissive"}
MATERIAL_FLOATS = {"specular_exponent": "specularExponent", "reflectivity": "reflectivity",
                   "transparency": "transparency", "speed_of_light": "speedOfLight",
                   "specular_fraction": "specularFraction", "surface_roughness": "surfaceRoughness"}
A_FRESNEL = "sdl:fresnel"  # token: Material.fresnel (written where not "constant")
A_FRESNEL_TINT = "sdl:fresnelTint"  # color3d
A_TEXTURE = "sdl:texture"
A_PARAMETERS = "sdl:parameters"

#: Scene settings on the root prim.
SETTING_COLORS = {"global_ambient": "sdl:globalAmbient", "background": "sdl:background"}
SETTING_FLOATS = {"min_reflectivity": "sdl:minReflectivity", "min_transparency": "sdl:minTransparency"}
A_MAX_DEPTH = "sdl:maxRecursionDepth"
A_SMOOTH_TERMINATOR = "sdl:smoothTerminator"  # bool, written where true
A_PIXMAP_NUMBERS = "sdl:pixmapNumbers"  # int[]
A_PIXMAP_FILES = "sdl:pixmapFiles"  # asset[], same order

FORMAT_VERSION = 1


def pxr():
    """The pxr modules we use, or a TracerError saying how to get them."""
    try:
        # usd-core's module loader catches any exception raised while its modules load, a KeyboardInterrupt
        # too, and goes on with the rest half set up: a signal meanwhile is acted on once they are loaded.
        with signals.shielded():
            from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade, Vt  # noqa: F401
    except ImportError as exc:  # pragma: no cover - depends on the environment
        raise TracerError("USD files need the usd-core package: pip install usd-core") from exc
    import pxr as module
    return module


def scene_points(objects, lights, camera) -> np.ndarray:
    """Where the things in a scene are, (N, 3): each shape's origin (planes left out: they reach
    everywhere), each light and the camera's eye."""
    points = [s.matrix[:3, 3] for obj in objects for s in iter_shapes(obj) if s.kind != "plane"]
    points += [np.asarray(light.position, dtype=np.float64) for light in lights]
    if camera is not None:
        points.append(np.asarray(camera.eye, dtype=np.float64))
    return np.array(points, dtype=np.float64).reshape(-1, 3)


def to_gf(matrix: np.ndarray):
    """Our column-vector matrix as a USD Gf.Matrix4d (its transpose), exactly."""
    from pxr import Gf
    return Gf.Matrix4d(*(float(x) for x in np.asarray(matrix, dtype=np.float64).T.reshape(-1)))


def from_gf(gf_matrix) -> np.ndarray:
    """A USD Gf.Matrix4d as our column-vector matrix, exactly."""
    return np.array([[gf_matrix[i][j] for j in range(4)] for i in range(4)], dtype=np.float64).T


def axis_frame(axis: str) -> np.ndarray:
    """A proper rotation taking generic +z to the USD ``axis`` (X, Y or Z), cyclic so nothing is mirrored:
    for X the generic (x, y, z) go to (y, z, x) and for Y to (z, x, y)."""
    frame = np.eye(4)
    if axis == "X":
        frame[:3, :3] = [[0, 0, 1], [1, 0, 0], [0, 1, 0]]
    elif axis == "Y":
        frame[:3, :3] = [[0, 1, 0], [0, 0, 1], [1, 0, 0]]
    return frame


def plane_frame(axis: str) -> np.ndarray:
    """A proper rotation taking the generic square's (x, y, z) to a UsdGeom.Plane's (width, length, normal)
    directions: for Z (x, y, z); for Y (x, z, y) with the width reversed; for X (z, y, x) with the width
    reversed (the square is symmetric, so reversing the width only keeps the frame from mirroring)."""
    frame = np.eye(4)
    if axis == "Y":
        frame[:3, :3] = [[-1, 0, 0], [0, 0, 1], [0, 1, 0]]
    elif axis == "X":
        frame[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    return frame


def to_y_up(up_axis: str) -> np.ndarray:
    """The rotation that turns a stage's world into SDL's y-up one: the identity for a y-up stage (all we
    write); for a z-up one a quarter turn about x, (x, y, z) -> (x, z, -y), so that its +z becomes +y and
    nothing is mirrored."""
    if up_axis != "Z":
        return np.eye(4)
    return np.array([[1.0, 0.0, 0.0, 0.0], [0.0, 0.0, 1.0, 0.0], [0.0, -1.0, 0.0, 0.0], [0.0, 0.0, 0.0, 1.0]])
