"""Write a :class:`tracer.model.Scene` as an OpenUSD stage (``.usda``, ``.usd``, ``.usdc``).

See docs/usd.md for the mapping.  In short: every object is one prim under ``/SDLScene/Objects`` with its
exact 4x4 matrix as its only xform op (``xformOp:transform``); sphere, cube, cylinder, cone and plane are
UsdGeom implicit prims, everything else a UsdGeom.Mesh; every SDL value is kept in ``sdl:*`` attributes so
that :func:`tracer.usd.reader.load_usd` gives back the same scene, and materials are also UsdPreviewSurface
shaders so that other tools show them.
"""
from __future__ import annotations

import os
from dataclasses import dataclass
from pathlib import Path
from typing import Optional, Union

import numpy as np

from .. import shapes
from ..atomic import through_private_folder, writing
from ..camera import CameraFrame, focal_length
from ..errors import TracerError
from ..geometry import builtin_mesh
from ..meshio import _face_normal
from ..model import CSG, Camera, Light, Material, MeshData, Scene, SceneObject, Shape
from ..transforms import translation
from . import common as C
from .lights import light_schema, prim_name, write_light
from .preview import preview_inputs

PathLike = Union[str, "os.PathLike[str]"]

#: USD's generic cylinder and cone are centred on the origin; ours run from z = 0 to 1.  We write them with
#: height 1 (radius 1, axis Z), so that the USD prim spans z in [-0.5, 0.5], and move them up by half.
CENTRED = translation(0.0, 0.0, 0.5)

#: The SDL plane is infinite; its UsdGeom.Plane (finite, for other tools) reaches this many times past the
#: farthest thing in the scene.
PLANE_REACH = 10.0

#: Booleans nested deeper than this below an object are written as a chain (see _chained): a prim's cost to
#: USD grows with its depth (its crate writer took 46 s for 2,000 nested booleans, the cube of the nesting,
#: and a .usda file spells every path out in full: 240 MB for the same 2,000 levels).
CHAIN_DEPTH = 32

#: USD's default vertical film aperture (mm); the focal length is chosen to give the SDL view angle.
VERTICAL_APERTURE = 15.2908
#: Our default image is 640 x 480.
ASPECT = 4.0 / 3.0
#: The camera's clipping range for other tools (see Writer._clipping_range): near in scene units, and the
#: least far (USD's default).
NEAR_CLIP, DEFAULT_FAR_CLIP = 0.01, 1e6


def camera_frame(camera: Camera) -> np.ndarray:
    """The camera-to-world matrix USD expects (the camera looks down its -z, +y up): columns u, v, n, eye,
    the tracer's own camera axes (:class:`tracer.camera.CameraFrame`; ValueError for a degenerate camera)."""
    return CameraFrame.from_camera(camera, ASPECT).to_world()


class _Writer:
    def __init__(self, scene: Scene, folder: Path):
        pxr = C.pxr()
        self.Gf, self.Sdf, self.Usd, self.UsdGeom = pxr.Gf, pxr.Sdf, pxr.Usd, pxr.UsdGeom
        self.UsdLux, self.UsdShade, self.Vt, self.Tf = pxr.UsdLux, pxr.UsdShade, pxr.Vt, pxr.Tf
        self.scene = scene
        self.folder = folder
        self.stage = self.Usd.Stage.CreateInMemory()
        self.materials: dict[Material, object] = {}  # each distinct material's UsdShade.Material
        self.material_paths: dict[Material, str] = {}  # and its prim's path
        self.names: dict[str, int] = {}
        self.light_names: set[str] = set()
        self.reach = self._scene_reach()

    # -- small helpers ----------------------------------------------------------------------------------

    def _attr(self, prim, name: str, type_name, value) -> None:
        prim.CreateAttribute(name, type_name, custom=True).Set(value)

    def _color(self, prim, name: str, value) -> None:
        self._attr(prim, name, self.Sdf.ValueTypeNames.Color3d, self.Gf.Vec3d(*map(float, value)))

    def _vec(self, prim, name: str, value) -> None:
        self._attr(prim, name, self.Sdf.ValueTypeNames.Double3, self.Gf.Vec3d(*map(float, value)))

    def _double(self, prim, name: str, value) -> None:
        self._attr(prim, name, self.Sdf.ValueTypeNames.Double, float(value))

    def _name(self, base: str) -> str:
        count = self.names.get(base, 0)
        self.names[base] = count + 1
        return f"{base}_{count}"

    def _set_transform(self, xformable, matrix: np.ndarray) -> None:
        """The matrix as the prim's one xform op, ``xformOp:transform`` (matrix4d, USD's transpose)."""
        xformable.MakeMatrixXform().Set(C.to_gf(matrix))

    def _scene_reach(self) -> float:
        """How far from the origin things in the scene are (for sizing the finite stand-in of a plane)."""
        points = C.scene_points(self.scene.objects, self.scene.lights, self.scene.camera)
        return float(np.max(np.linalg.norm(points, axis=1), initial=0.0)) + 10.0

    # -- the stage --------------------------------------------------------------------------------------

    def build(self):
        stage, UsdGeom = self.stage, self.UsdGeom
        UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.y)
        UsdGeom.SetStageMetersPerUnit(stage, 1.0)
        root = UsdGeom.Xform.Define(stage, C.ROOT).GetPrim()
        stage.SetDefaultPrim(root)
        stage.GetRootLayer().customLayerData = {"sdl:writer": "tracer (python -m tracer convert)",
                                                "sdl:version": C.FORMAT_VERSION}
        self._settings(root)
        self.UsdGeom.Scope.Define(stage, C.MATERIALS)
        self.UsdGeom.Scope.Define(stage, C.LIGHTS)
        self._lights()
        if self.scene.camera is not None:
            self._camera(self.scene.camera)
        UsdGeom.Xform.Define(stage, C.OBJECTS)
        self._objects()
        return stage

    def _settings(self, root) -> None:
        s = self.scene.settings
        self._attr(root, C.A_VERSION, self.Sdf.ValueTypeNames.Int, C.FORMAT_VERSION)
        for field, name in C.SETTING_COLORS.items():
            self._color(root, name, getattr(s, field))
        for field, name in C.SETTING_FLOATS.items():
            self._double(root, name, getattr(s, field))
        self._attr(root, C.A_MAX_DEPTH, self.Sdf.ValueTypeNames.Int, int(s.max_recursion_depth))
        if s.smooth_terminator:
            self._attr(root, C.A_SMOOTH_TERMINATOR, self.Sdf.ValueTypeNames.Bool, True)
        numbers = sorted(self.scene.pixmaps)
        self._attr(root, C.A_PIXMAP_NUMBERS, self.Sdf.ValueTypeNames.IntArray, self.Vt.IntArray(numbers))
        files = [self._relative(self.scene.pixmaps[i]) for i in numbers]
        self._attr(root, C.A_PIXMAP_FILES, self.Sdf.ValueTypeNames.AssetArray,
                   self.Sdf.AssetPathArray([self.Sdf.AssetPath(f) for f in files]))

    def _relpath(self, name: str) -> str:
        """A file name (relative to the current folder, or absolute) relative to the USD file's folder, with
        forward slashes (absolute if there is no relative path, e.g. another drive on Windows)."""
        try:
            return Path(os.path.relpath(os.path.abspath(name), os.path.abspath(self.folder))).as_posix()
        except ValueError:
            return Path(os.path.abspath(name)).as_posix()

    def _relative(self, name: str) -> str:
        """The same as an asset path: ``./...`` or ``../...``, so that USD anchors it to the file."""
        rel = self._relpath(name)
        return rel if rel.startswith("../") or os.path.isabs(rel) else "./" + rel

    def _lights(self) -> None:
        """Every light's prim, all first made in one change block (as the objects' are, see _objects: defining
        them one at a time recomposed the growing list each time, 20,000 lights took 29 s), then authored."""
        planned = []
        for index, light in enumerate(self.scene.lights):
            planned.append((light, f"{C.LIGHTS}/{prim_name(light, index, self.light_names)}"))
        self.names["light"] = len(planned)
        self._define_all([(path, *light_schema(self, light)) for light, path in planned])
        for light, path in planned:
            write_light(self, light, path)

    def _camera(self, camera: Camera) -> None:
        cam = self.UsdGeom.Camera.Define(self.stage, C.CAMERA)
        cam.CreateProjectionAttr(self.UsdGeom.Tokens.perspective)
        cam.CreateVerticalApertureAttr(VERTICAL_APERTURE)
        cam.CreateHorizontalApertureAttr(VERTICAL_APERTURE * ASPECT)
        cam.CreateFocalLengthAttr(focal_length(camera.view_angle, VERTICAL_APERTURE))
        cam.CreateClippingRangeAttr(self.Gf.Vec2f(*self._clipping_range(camera)))
        self._set_transform(cam, camera_frame(camera))
        prim = cam.GetPrim()
        self._vec(prim, C.A_EYE, camera.eye)
        self._vec(prim, C.A_LOOK, camera.look)
        self._vec(prim, C.A_UP, camera.up)
        self._double(prim, C.A_VIEW_ANGLE, camera.view_angle)

    def _clipping_range(self, camera: Camera) -> tuple[float, float]:
        """Our rays start at the eye and never end; other tools clip.  USD's default (1, 1e6) would cut
        away what lies within a unit of the eye, a large part of a small SDL scene: near is 0.01, and far
        reaches ten times past the farthest object or light."""
        points = C.scene_points(self.scene.objects, self.scene.lights, None)
        eye = np.asarray(camera.eye, dtype=np.float64)
        farthest = float(np.max(np.linalg.norm(points - eye, axis=1))) if len(points) else 0.0
        return NEAR_CLIP, max(DEFAULT_FAR_CLIP, 10.0 * farthest)

    # -- objects ----------------------------------------------------------------------------------------

    def _objects(self) -> None:
        """Every object's prim, and its material's.  All those prims are first made together, in one
        Sdf.ChangeBlock, so that the stage recomposes once: Define() one at a time recomposes the growing list
        of siblings each time, which made big scenes quadratic (20,000 spheres took more than 12 minutes).
        Define() on a prim already defined with that type only returns it, so the authoring is unchanged."""
        placed = self._place_objects()
        bound = self.Sdf.TokenListOp.Create(prependedItems=["MaterialBindingAPI"])  # what its Apply() authors
        self._define_all([(path, self._schema(obj), None if isinstance(obj, (CSG, _Chain)) else bound)
                          for obj, path, _ in placed]
                         + [prim for path in self.material_paths.values()
                            for prim in ((path, self.UsdShade.Material, None),
                                         (path + "/PreviewSurface", self.UsdShade.Shader, None))])
        Token, Strings = self.Sdf.ValueTypeNames.Token, self.Sdf.ValueTypeNames.StringArray
        for obj, path, operand in placed:
            if isinstance(obj, (CSG, _Chain)):
                prim = self.UsdGeom.Xform.Define(self.stage, path).GetPrim()
                self._attr(prim, C.A_CSG, Token, C.CHAIN if isinstance(obj, _Chain) else obj.op)
            else:
                prim = self._shape(obj, path)
            if isinstance(operand, _Link):
                self._attr(prim, C.A_CHAIN_OP, Token, operand.op)
                self._attr(prim, C.A_CHAIN_SIDE, Token, operand.side)
                if operand.groups:
                    self._attr(prim, C.A_CHAIN_GROUPS, Strings, self.Vt.StringArray(list(operand.groups)))
            elif operand is not None:
                self._attr(prim, C.A_OPERAND, Token, operand)
            if obj.groups:
                self._attr(prim, C.A_GROUPS, Strings, self.Vt.StringArray(list(obj.groups)))

    def _place_objects(self) -> list[tuple[object, str, Optional[object]]]:
        """Every object (a boolean before its left and right operands) with its prim path and its operand
        side (or, in a chain, its _Link); also names each distinct material's prim in ``material_paths``, in
        the order of first use.  A boolean with booleans nested more than CHAIN_DEPTH deep below it is
        written as a _Chain."""
        placed = []
        depths = _boolean_depths(self.scene.objects)
        # An explicit stack, so that deeply nested booleans cannot overflow Python's.
        todo: list[tuple[object, str, Optional[object]]] = [
            (o, C.OBJECTS, None) for o in reversed(self.scene.objects)]
        while todo:
            obj, parent, operand = todo.pop()
            if isinstance(obj, CSG) and depths[id(obj)] > CHAIN_DEPTH:
                obj = _chained(obj, depths)
            name = C.CHAIN if isinstance(obj, _Chain) else obj.op if isinstance(obj, CSG) else obj.kind
            path = f"{parent}/{self._name(name)}"
            placed.append((obj, path, operand))
            if isinstance(obj, _Chain):
                todo += [(link.operand, path, link) for link in reversed(obj.links)] + [(obj.start, path, None)]
            elif isinstance(obj, CSG):
                todo += [(obj.right, path, "right"), (obj.left, path, "left")]
            elif obj.material not in self.material_paths:
                self.material_paths[obj.material] = f"{C.MATERIALS}/{self._name('material')}"
        return placed

    def _schema(self, obj: SceneObject):
        """The UsdGeom schema of an object's prim: the implicit prim its kind names, else a Mesh (a boolean's
        and a chain's: an Xform)."""
        if isinstance(obj, (CSG, _Chain)):
            return self.UsdGeom.Xform
        return getattr(self.UsdGeom, shapes.KINDS[obj.kind].usd_prim or "Mesh")

    def _define_all(self, prims: list) -> None:
        """Define each (path, schema, API schemas or None) prim, parents first, in one change block (one
        recomposition; applying an API schema later would recompose again)."""
        Sdf, layer = self.Sdf, self.stage.GetEditTarget().GetLayer()
        type_names = {}
        with Sdf.ChangeBlock():
            for path, schema, api_schemas in prims:
                if schema not in type_names:
                    type_names[schema] = self.Usd.SchemaRegistry.GetSchemaTypeName(self.Tf.Type.Find(schema))
                spec = Sdf.CreatePrimInLayer(layer, path)
                spec.specifier = Sdf.SpecifierDef
                spec.typeName = type_names[schema]
                if api_schemas is not None:
                    spec.SetInfo("apiSchemas", api_schemas)

    def _shape(self, shape: Shape, path: str):
        UsdGeom, stage = self.UsdGeom, self.stage
        kind = shape.kind
        entry = shapes.KINDS[kind]
        gprim = self._schema(shape).Define(stage, path)
        # (what each schema needs; the matrix to place it by, and our exact one where that may differ)
        matrix, exact_matrix = self._geometry[entry.usd_prim or "Mesh"](gprim, shape)
        self._set_transform(gprim, matrix)
        prim = gprim.GetPrim()
        self._attr(prim, C.A_SHAPE, self.Sdf.ValueTypeNames.Token, kind)
        if exact_matrix is not None:
            self._attr(prim, C.A_MATRIX, self.Sdf.ValueTypeNames.Matrix4d, C.to_gf(exact_matrix))
        for parameter, value in zip(entry.parameters, shape.parameters):
            self._double(prim, parameter.usd_attribute, value)
        if entry.file_argument:
            self._mesh_data(prim, shape)
        extent = UsdGeom.Boundable.ComputeExtentFromPlugins(gprim, self.Usd.TimeCode.Default())
        if extent is not None:
            gprim.CreateExtentAttr(extent)
        gprim.CreateDisplayColorAttr(self.Vt.Vec3fArray([self.Gf.Vec3f(*map(float, shape.material.diffuse))]))
        self._material(prim, shape.material)
        return prim

    @property
    def _geometry(self) -> dict:
        """Per UsdGeom schema a kind may name (ShapeKind.usd_prim), what authors its prim's geometry."""
        return {"Sphere": self._sphere, "Cube": self._cube, "Cylinder": self._round, "Cone": self._round,
                "Plane": self._plane, "Mesh": self._tessellated}

    @staticmethod
    def _sphere(gprim, shape: Shape):
        gprim.CreateRadiusAttr(1.0)
        return shape.matrix, None

    @staticmethod
    def _cube(gprim, shape: Shape):
        gprim.CreateSizeAttr(2.0)
        return shape.matrix, None

    def _round(self, gprim, shape: Shape):
        """USD's cylinder and cone, centred on the origin: ours stand on z = 0 (see CENTRED)."""
        gprim.CreateRadiusAttr(1.0)
        gprim.CreateHeightAttr(1.0)
        gprim.CreateAxisAttr(self.UsdGeom.Tokens.z)
        return shape.matrix @ CENTRED, shape.matrix  # (M @ CENTRED @ CENTRED⁻¹ may be off by an ulp)

    def _plane(self, gprim, shape: Shape):
        half = self._plane_half_size(shape.matrix)
        gprim.CreateWidthAttr(2.0 * half)
        gprim.CreateLengthAttr(2.0 * half)
        gprim.CreateAxisAttr(self.UsdGeom.Tokens.z)
        gprim.CreateDoubleSidedAttr(True)
        return shape.matrix, None

    def _tessellated(self, gprim, shape: Shape):
        self._mesh(gprim, self._generic_mesh(shape))
        return shape.matrix, None

    def _plane_half_size(self, matrix: np.ndarray) -> float:
        """Half the side of the square that stands in for an infinite plane: it reaches ``PLANE_REACH`` times
        past everything else in the scene (in the plane's generic units)."""
        smallest = float(np.min(np.linalg.norm(matrix[:3, :2], axis=0)))
        distance = self.reach + float(np.linalg.norm(matrix[:3, 3]))
        return PLANE_REACH * distance / max(smallest, 1e-300)

    @staticmethod
    def _generic_mesh(shape: Shape) -> MeshData:
        """The polygons of a shape USD has no implicit prim for: its kind's tessellation, else its mesh."""
        entry = shapes.KINDS[shape.kind]
        if entry.tessellate is not None:
            return entry.function("tessellate")(*entry.traced(shape.parameters))
        if shape.mesh is None:
            if entry.builtin_mesh:
                return builtin_mesh(shape.kind)
            raise TracerError(f"cannot write the {shape.kind}: it has no mesh data")
        return shape.mesh

    def _mesh(self, mesh, data: MeshData) -> None:
        """Points, faces and per-corner (faceVarying) normals; faces without normals get their flat one."""
        vertices = np.asarray(data.vertices, dtype=np.float64).reshape(-1, 3)
        normals = np.asarray(data.normals, dtype=np.float64).reshape(-1, 3)
        counts, indices, corner_normals = [], [], []
        for verts, norms in data.faces:
            counts.append(len(verts))
            indices.extend(int(v) for v in verts)
            if len(norms) == len(verts):
                corner_normals.extend(normals[list(norms)])
            else:
                flat = _face_normal(vertices[list(verts)])
                corner_normals.extend([flat] * len(verts))
        Vt = self.Vt
        mesh.CreatePointsAttr(Vt.Vec3fArray.FromNumpy(vertices.astype(np.float32)))
        mesh.CreateFaceVertexCountsAttr(Vt.IntArray(counts))
        mesh.CreateFaceVertexIndicesAttr(Vt.IntArray(indices))
        corner = np.asarray(corner_normals, dtype=np.float64).reshape(-1, 3)
        mesh.CreateNormalsAttr(Vt.Vec3fArray.FromNumpy(corner.astype(np.float32)))
        mesh.SetNormalsInterpolation(self.UsdGeom.Tokens.faceVarying)
        mesh.CreateSubdivisionSchemeAttr(self.UsdGeom.Tokens.none)
        mesh.CreateOrientationAttr(self.UsdGeom.Tokens.rightHanded)
        if data.corner_uvs is not None:  # texture coordinates, one per face corner, as other tools name them
            st = self.UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("st", self.Sdf.ValueTypeNames.TexCoord2fArray,
                                                              self.UsdGeom.Tokens.faceVarying)
            st.Set(Vt.Vec2fArray.FromNumpy(np.asarray(data.corner_uvs, dtype=np.float32).reshape(-1, 2)))

    def _mesh_data(self, prim, shape: Shape) -> None:
        """A ``mesh`` statement's data exactly (doubles, and the separate normal list of .3vn), and its file."""
        data = shape.mesh
        Sdf, Vt = self.Sdf, self.Vt
        if shape.mesh_file is not None:
            name = shape.mesh_file
            if self.scene.source is not None and not os.path.isabs(name):
                name = str(Path(self.scene.source).parent / name)
            self._attr(prim, C.A_MESH_FILE, Sdf.ValueTypeNames.String, self._relpath(name))
        if data is None:
            return
        self._attr(prim, C.A_MESH_POINTS, Sdf.ValueTypeNames.Double3Array,
                   Vt.Vec3dArray.FromNumpy(np.asarray(data.vertices, dtype=np.float64).reshape(-1, 3)))
        self._attr(prim, C.A_MESH_NORMALS, Sdf.ValueTypeNames.Double3Array,
                   Vt.Vec3dArray.FromNumpy(np.asarray(data.normals, dtype=np.float64).reshape(-1, 3)))
        corners = [int(n) for verts, norms in data.faces
                   for n in (norms if len(norms) == len(verts) else [-1] * len(verts))]
        self._attr(prim, C.A_MESH_NORMAL_INDICES, Sdf.ValueTypeNames.IntArray, Vt.IntArray(corners))
        if data.corner_uvs is not None:
            self._attr(prim, C.A_MESH_UVS, Sdf.ValueTypeNames.Double2Array,
                       Vt.Vec2dArray.FromNumpy(np.asarray(data.corner_uvs, dtype=np.float64).reshape(-1, 2)))

    # -- materials --------------------------------------------------------------------------------------

    def _material(self, prim, material: Material) -> None:
        Sdf = self.Sdf
        for field, keyword in C.MATERIAL_COLORS.items():
            self._color(prim, C.NS + keyword, getattr(material, field))
        for field, keyword in C.MATERIAL_FLOATS.items():
            self._double(prim, C.NS + keyword, getattr(material, field))
        self._attr(prim, C.A_TEXTURE, Sdf.ValueTypeNames.Int, int(material.texture))
        self._attr(prim, C.A_PARAMETERS, Sdf.ValueTypeNames.DoubleArray,
                   self.Vt.DoubleArray([float(p) for p in material.parameters]))
        if material.fresnel != "constant":
            self._attr(prim, C.A_FRESNEL, Sdf.ValueTypeNames.Token, material.fresnel)
            self._color(prim, C.A_FRESNEL_TINT, material.fresnel_tint)
        usd_material = self.materials.get(material)
        if usd_material is None:
            usd_material = self._preview_surface(material, self.material_paths[material])
            self.materials[material] = usd_material
        binding = self.UsdShade.MaterialBindingAPI.Apply(prim)
        binding.Bind(usd_material)

    def _preview_surface(self, material: Material, path: str):
        UsdShade, Sdf, Gf = self.UsdShade, self.Sdf, self.Gf
        usd_material = UsdShade.Material.Define(self.stage, path)
        shader = UsdShade.Shader.Define(self.stage, path + "/PreviewSurface")
        shader.CreateIdAttr("UsdPreviewSurface")
        for name, value in preview_inputs(material).items():
            if isinstance(value, tuple):
                shader.CreateInput(name, Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(*map(float, value)))
            elif isinstance(value, int):
                shader.CreateInput(name, Sdf.ValueTypeNames.Int).Set(value)
            else:
                shader.CreateInput(name, Sdf.ValueTypeNames.Float).Set(float(value))
        usd_material.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
        return usd_material


@dataclass
class _Link:
    """One boolean of a chain: ``operand`` combined by ``op`` with what the chain made before it, on the
    right of it (``side`` "right") or on its left ("left"); the boolean's def groups."""

    op: str
    side: str
    operand: SceneObject
    groups: tuple[str, ...]


@dataclass
class _Chain:
    """A boolean tree written flat (common.CHAIN): ``start``, then each link applied in turn."""

    start: SceneObject
    links: list[_Link]
    groups: tuple[str, ...] = ()


def _chained(obj: CSG, depths: dict[int, int]) -> _Chain:
    """``obj`` as a chain along its spine: from it down to a primitive, always into the deeper operand (a tree
    nested deep is a long spine with shallow operands hanging off it, each written on its own, as a chain
    again if it is deep too).  The links are listed from the spine's bottom up, the order they apply in."""
    links = []
    node: SceneObject = obj
    while isinstance(node, CSG):
        left_deeper = depths.get(id(node.left), 0) >= depths.get(id(node.right), 0)
        if left_deeper:
            links.append(_Link(node.op, "right", node.right, node.groups))
            node = node.left
        else:
            links.append(_Link(node.op, "left", node.left, node.groups))
            node = node.right
    return _Chain(node, links[::-1])


def _boolean_depths(objects) -> dict[int, int]:
    """How deeply booleans nest below each boolean of the scene (by id; 1 for a boolean of two primitives),
    without recursion."""
    depths: dict[int, int] = {}
    for root in objects:
        todo = [(root, False)]
        while todo:
            node, ready = todo.pop()
            if not isinstance(node, CSG) or id(node) in depths:
                continue
            if ready:
                depths[id(node)] = 1 + max(depths.get(id(node.left), 0), depths.get(id(node.right), 0))
            else:
                todo += [(node, True), (node.left, False), (node.right, False)]
    return depths


def build_stage(scene: Scene, folder: PathLike = "."):
    """The scene as an in-memory Usd.Stage; file names in it are relative to ``folder``."""
    return _Writer(scene, Path(folder)).build()


def save_usd(scene: Scene, path: PathLike) -> None:
    """Write the scene to ``path`` (.usda text, .usdc or .usd binary), atomically: ``path`` is the old file
    or the whole new one, and no other file is ever named in its folder (tracer.atomic)."""
    path = Path(path)
    suffix = path.suffix.lower()
    if suffix not in C.USD_EXTENSIONS:
        raise TracerError(f"{path}: not a USD file name (use {', '.join(C.USD_EXTENSIONS)})")
    stage = build_stage(scene, path.parent)
    # USD picks the format by the extension; for .usd it would follow $USD_DEFAULT_FILE_FORMAT: ask for crate.
    args = {"format": "usdc"} if suffix == ".usd" else {}
    # No file of ours or usd-core's may be named in the user's folder before the new one is whole (a kill -9
    # would leave it there): text is written through an anonymous file, a crate file (which usd-core can only
    # write to a name, beside which it makes a temporary of its own) in a private folder elsewhere, then copied.
    layer = stage.GetRootLayer()
    if suffix == ".usda":
        with writing(path, "w", encoding="utf-8") as handle:
            handle.write(layer.ExportToString())
    else:
        with through_private_folder(path, suffix) as temp:
            if not layer.Export(str(temp), args=args):
                raise TracerError(f"{path}: USD could not write the file")
    # A layer of this name that USD still holds in memory would otherwise hide the new file from Open().
    from pxr import Sdf
    layer = Sdf.Layer.Find(str(path))
    if layer is not None:
        layer.Reload()
