"""Read an OpenUSD stage into a :class:`tracer.model.Scene`.

Stages we wrote come back exactly: the ``sdl:*`` attributes are read first (shape keyword, material,
settings, camera, exact matrices).  Stages from other tools are read from their schemas: implicit prims
(Sphere, Cube, Cylinder, Cylinder_1, Cone, Plane), Mesh prims, world transforms composed by
UsdGeom.XformCache, UsdPreviewSurface materials, Sphere/Distant/Rect/Disk lights (tracer/usd/lights.py),
and the first Camera.  Invisible prims and guide/proxy purposes are skipped.  A z-up stage is turned into
SDL's y-up world.  Strict (the default), what cannot be read is a TracerError naming the file and prim;
lenient, a warning.  See docs/usd.md.

The traversal is one loop over ``Usd.PrimRange.PreAndPostVisit`` with an explicit stack for CSG groups,
so deep nesting cannot overflow Python's stack.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from pathlib import Path
from typing import Optional, Sequence, Union

import numpy as np

from .. import shapes
from ..camera import focal_length, view_angle
from ..errors import SceneError, TracerError
from ..geometry import builtin_mesh
from ..model import (CSG, FRESNEL_MODES, MAX_RECURSION_DEPTH, SHAPE_KINDS, Camera, Light, Material, Scene,
                     SceneObject, Settings, Shape, SourceLocation, TEXTURE_NUMBERS, traced_depth)
from ..sdl.parser import is_singular
from ..transforms import scaling, translation
from . import common as C
from .lights import read_light
from .meshes import sdl_mesh, usd_mesh
from .opening import held_stderr, open_stage, usd_error_message
from .preview import material_from_preview
from .writer import camera_frame

PathLike = Union[str, "os.PathLike[str]"]

#: Kinds written as their tessellation (USD has no implicit prim for them) and read back as the exact shape.
_TESSELLATED = frozenset(e.keyword for e in shapes.REGISTRY if e.family == "analytic" and e.usd_prim is None)

#: Our sdl:matrix is used instead of the prim's transform only while the two agree to this (relative).
MATRIX_AGREEMENT = 1e-12
#: The UsdLux lights read (tracer/usd/lights.py; a CylinderLight as a point light at its centre).
READ_LIGHTS = ("SphereLight", "DistantLight", "RectLight", "DiskLight", "CylinderLight")
#: What a value of the wrong type or shape raises while a prim is read (float("x"), a float where a triple
#: belongs, an index out of range): the prim cannot be read.
_BAD_VALUE = (ValueError, IndexError, TypeError, OverflowError)


@dataclass
class _Group:
    """A CSG group whose operands are being collected."""

    op: str  # or common.CHAIN
    path: object  # its Sdf.Path (a string would be parsed again at each use: time in the depth)
    groups: tuple[str, ...]
    children: list[SceneObject] = field(default_factory=list)
    links: list[tuple] = field(default_factory=list)  # a chain's: (op, side, groups) of each child's boolean


class _Reader:
    def __init__(self, stage, file: str, strict: bool = True, time: Optional[float] = None):
        pxr = C.pxr()
        self.Gf, self.Sdf, self.Usd, self.UsdGeom = pxr.Gf, pxr.Sdf, pxr.Usd, pxr.UsdGeom
        self.UsdLux, self.UsdShade, self.Tf = pxr.UsdLux, pxr.UsdShade, pxr.Tf
        self.stage = stage
        self.file = file
        self.strict = strict
        self.time = _time_code(pxr.Usd, stage) if time is None else pxr.Usd.TimeCode(float(time))
        self.xforms = self.UsdGeom.XformCache(self.time)
        # SDL's world is y-up: a z-up stage is turned so that its up becomes +y (see common.to_y_up).
        self.up = C.to_y_up(str(self.UsdGeom.GetStageUpAxis(stage)))
        self.scene = Scene()
        self._bound: Optional[dict] = None  # prim path -> its bound material (see _bound_material)

    # -- messages and attributes ------------------------------------------------------------------------

    def _where(self, prim) -> str:
        return f"{self.file}: <{prim.GetPath()}>" if prim else self.file

    def note(self, prim, message: str) -> None:
        """Something read approximately (a rect light as a point, say): a warning whether strict or not."""
        text = f"{self._where(prim)}: {message}"
        if text not in self.scene.warnings:
            self.scene.warnings.append(text)

    def problem(self, prim, message: str, lenient: str = "left out") -> None:
        """Something that cannot be read: an error when strict; otherwise a warning saying what was done
        instead (``lenient``)."""
        if self.strict:
            raise TracerError(f"{self._where(prim)}: {message}")
        self.note(prim, f"{message}: {lenient}")

    def get(self, prim, name: str, default=None):
        attr = prim.GetAttribute(name)
        if not attr or not attr.HasAuthoredValue():
            return default
        value = attr.Get(self.time)
        return default if value is None else value

    def triple(self, prim, name: str, default=None):
        value = self.get(prim, name)
        return default if value is None else tuple(float(x) for x in value)

    def world(self, prim) -> np.ndarray:
        """The prim's local-to-world matrix in SDL's y-up world.  An xformOp USD cannot evaluate is a
        ValueError with USD's own words (the prim is then reported as unreadable)."""
        try:
            return self.up @ C.from_gf(self.xforms.GetLocalToWorldTransform(prim))
        except self.Tf.ErrorException as exc:
            raise ValueError(f"its transform: {usd_error_message(exc)}") from None

    # -- the whole stage --------------------------------------------------------------------------------

    def read(self, composition_errors: Sequence[str] = ()) -> Scene:
        for message in composition_errors:  # a missing reference: what it would have brought is not there
            self.problem(None, message.rstrip("."), "read without it")
        self._settings()
        Usd = self.Usd
        stack: list[_Group] = []
        predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
        walk = iter(Usd.PrimRange.PreAndPostVisit(self.stage.GetPseudoRoot(), predicate))
        for prim in walk:
            if walk.IsPostVisit():
                if stack and stack[-1].path == prim.GetPath():
                    self._finish_group(stack.pop(), stack)
                continue
            if prim.IsPseudoRoot():
                continue
            if not self._shown(prim):
                walk.PruneChildren()
                continue
            try:
                obj = self._prim(prim, stack)
            except _BAD_VALUE as exc:
                self.problem(prim, f"cannot read it ({exc})")
                obj = None
            if obj is not _DESCEND:
                walk.PruneChildren()
                if obj is not None:
                    self._place(obj, stack, prim)
        return self.scene

    def _shown(self, prim) -> bool:
        """False for invisible prims and guide or proxy purposes (and their children).  The walk prunes a
        hidden prim's children, so every prim asked about has shown ancestors: its own authored visibility
        and purpose decide (USD's Compute* would walk the ancestors again, in time the square of the depth)."""
        imageable = self.UsdGeom.Imageable(prim)
        if not imageable:
            return True
        Tokens = self.UsdGeom.Tokens
        visibility = imageable.GetVisibilityAttr()
        if visibility.HasAuthoredValue() and visibility.Get(self.time) == Tokens.invisible:
            return False
        purpose = imageable.GetPurposeAttr()
        return not (purpose.HasAuthoredValue() and purpose.Get() in (Tokens.guide, Tokens.proxy))

    def _place(self, obj: SceneObject, stack: list[_Group], prim) -> None:
        if not stack:
            self.scene.objects.append(obj)
            return
        stack[-1].children.append(obj)
        if stack[-1].op == C.CHAIN:
            stack[-1].links.append((self.get(prim, C.A_CHAIN_OP), self.get(prim, C.A_CHAIN_SIDE),
                                    self._groups(prim, C.A_CHAIN_GROUPS)))

    def _finish_group(self, group: _Group, stack: list[_Group]) -> None:
        prim = self.stage.GetPrimAtPath(group.path)
        if group.op == C.CHAIN:
            return self._finish_chain(group, stack, prim)
        children = group.children
        if not children:
            self.problem(prim, f"{group.op} has no operands")
            return
        if len(children) == 1:
            self.problem(prim, f"{group.op} has one operand", "read as that object alone")
            self._place(children[0], stack, prim)
            return
        if len(children) > 2:
            self.problem(prim, f"{group.op} has {len(children)} operands", "combined left to right")
        obj = children[0]
        where = SourceLocation(f"{self.file}<{group.path}>", 0)  # (messages about the boolean name the file)
        for child in children[1:]:
            obj = CSG(group.op, obj, child, groups=group.groups, source=where)
        self._place(obj, stack, prim)

    def _finish_chain(self, group: _Group, stack: list[_Group], prim) -> None:
        """A chain (common.CHAIN): its first child, then each later one combined with what came before."""
        if not group.children:
            self.problem(prim, "chain has no operands")
            return
        obj = group.children[0]
        where = SourceLocation(f"{self.file}<{group.path}>", 0)
        for child, (op, side, groups) in zip(group.children[1:], group.links[1:]):
            if str(op) not in CSG.OPS or str(side) not in ("left", "right"):
                self.problem(prim, f"a link of the chain has {C.A_CHAIN_OP} {op!r} and {C.A_CHAIN_SIDE} "
                                   f"{side!r}", "that operand left out")
                continue
            obj = CSG(str(op), obj, child, groups, where) if side == "right" else CSG(str(op), child, obj, groups, where)
        self._place(obj, stack, prim)

    # -- settings ---------------------------------------------------------------------------------------

    def _settings_prim(self):
        """Where our writer put the scene's settings: /SDLScene, or wherever that prim landed when our file
        was referenced into another stage (the first prim carrying sdl:version)."""
        root = self.stage.GetPrimAtPath(C.ROOT)
        if root and root.HasAttribute(C.A_VERSION):
            return root
        return next((prim for prim in self.stage.Traverse() if prim.HasAttribute(C.A_VERSION)), None)

    def _settings(self) -> None:
        root = self._settings_prim()
        if root is None or self.get(root, C.A_VERSION) is None:
            return
        try:
            s = Settings()
            for field_name, name in C.SETTING_COLORS.items():
                setattr(s, field_name, self.triple(root, name, getattr(s, field_name)))
            for field_name, name in C.SETTING_FLOATS.items():
                setattr(s, field_name, float(self.get(root, name, getattr(s, field_name))))
            s.max_recursion_depth = whole_number(self.get(root, C.A_MAX_DEPTH, s.max_recursion_depth), C.A_MAX_DEPTH)
            s.smooth_terminator = bool(self.get(root, C.A_SMOOTH_TERMINATOR, False))
            numbers = [whole_number(n, C.A_PIXMAP_NUMBERS, TEXTURE_NUMBERS)
                       for n in self.get(root, C.A_PIXMAP_NUMBERS, [])]
            files = list(self.get(root, C.A_PIXMAP_FILES, []))
        except _BAD_VALUE as exc:
            self.problem(root, f"cannot read the scene settings ({exc})", "SDL's defaults used")
            return
        if s.max_recursion_depth > MAX_RECURSION_DEPTH or s.max_recursion_depth < 0:
            self.note(root, f"{C.A_MAX_DEPTH} = {s.max_recursion_depth} is outside 0..{MAX_RECURSION_DEPTH}: "
                            f"{traced_depth(s.max_recursion_depth)} used")
            s.max_recursion_depth = traced_depth(s.max_recursion_depth)
        self.scene.settings = s
        if len(numbers) != len(files):
            self.problem(root, "sdl:pixmapNumbers and sdl:pixmapFiles differ in length", "pixmaps left out")
            return
        attr = root.GetAttribute(C.A_PIXMAP_FILES)
        for number, asset in zip(numbers, files):
            self.scene.pixmaps[number] = self._asset_file(attr, asset)

    def _asset_file(self, attr, asset) -> str:
        """An asset path's file: as USD resolved it, else anchored to the layer that wrote it."""
        if asset.resolvedPath:
            return asset.resolvedPath
        path = asset.path
        if os.path.isabs(path):
            return path
        stack = attr.GetPropertyStack(self.time)
        layer = stack[0].layer if stack else self.stage.GetRootLayer()
        return layer.ComputeAbsolutePath(path) if not layer.anonymous else path

    # -- one prim ---------------------------------------------------------------------------------------

    def _prim(self, prim, stack: list[_Group]):
        """The object a prim stands for; None if it is something else handled here (light, camera, or
        unsupported); _DESCEND to look at its children (a CSG group is pushed on ``stack`` first)."""
        op = self.get(prim, C.A_CSG)
        if op is not None:
            if str(op) not in CSG.OPS + (C.CHAIN,):
                self.problem(prim, f"unknown sdl:csg {str(op)!r}", "its children read as separate objects")
            else:
                stack.append(_Group(str(op), prim.GetPath(), self._groups(prim)))
            return _DESCEND
        type_name = prim.GetTypeName()
        if prim.IsA(self.UsdGeom.Camera):
            self._camera(prim)
            return None
        if type_name in READ_LIGHTS:
            self._light(prim, type_name)
            return None
        if prim.HasAPI(self.UsdLux.LightAPI) or type_name.endswith("Light") or type_name.startswith("DomeLight"):
            what = type_name if "Light" in type_name else f"a light on a {type_name or 'typeless'} prim"
            self.problem(prim, f"{what} is not supported")
            return None
        if prim.IsA(self.UsdShade.Material) or prim.IsA(self.UsdShade.Shader) or prim.IsA(self.UsdShade.NodeGraph):
            return None
        if prim.IsA(self.UsdGeom.Gprim):
            return self._shape(prim)
        if prim.IsA(self.UsdGeom.PointInstancer):
            self.problem(prim, "PointInstancer is not supported")
            return None
        return _DESCEND

    def _shape(self, prim) -> Optional[Shape]:
        UsdGeom = self.UsdGeom
        kind = self.get(prim, C.A_SHAPE)
        kind = str(kind) if kind is not None else None
        if kind is not None and kind not in SHAPE_KINDS:
            self.note(prim, f"unknown sdl:shape {kind!r}: read from its USD type")
            kind = None
        world = self.world(prim)
        shape: Optional[Shape] = None
        if prim.IsA(UsdGeom.Sphere):
            r = float(UsdGeom.Sphere(prim).GetRadiusAttr().Get(self.time))
            shape = Shape("sphere", world @ scaling(r, r, r))
        elif prim.IsA(UsdGeom.Cube):
            h = 0.5 * float(UsdGeom.Cube(prim).GetSizeAttr().Get(self.time))
            shape = Shape("cube", world @ scaling(h, h, h))
        elif prim.IsA(UsdGeom.Cylinder) or prim.IsA(UsdGeom.Cone) or prim.GetTypeName() == "Cylinder_1":
            shape = self._round(prim, world)
        elif prim.IsA(UsdGeom.Plane):
            shape = self._plane(prim, world, kind)
        elif prim.IsA(UsdGeom.Mesh):
            shape = self._mesh(prim, world, kind)
        else:
            self.problem(prim, f"{prim.GetTypeName()} is not supported")
            return None
        if shape is None:
            return None
        if kind in _TESSELLATED and shape.kind == "mesh":
            shape = Shape(kind, shape.matrix, parameters=tuple(float(self.get(prim, p.usd_attribute, p.default))
                                                               for p in shapes.KINDS[kind].parameters))
        elif kind is not None and kind != shape.kind:
            self.note(prim, f"sdl:shape {kind!r} does not match its USD type: read as {shape.kind}")
        if not np.all(np.isfinite(shape.parameters)):  # (SDL's reader refuses nan and inf as numbers)
            self.problem(prim, f"its {shape.kind} has a parameter that is not a finite number: {shape.parameters}")
            return None
        exact = self.get(prim, C.A_MATRIX)
        if exact is not None:
            exact = C.from_gf(exact)
            scale = max(1.0, float(np.max(np.abs(exact))))
            if np.max(np.abs(exact - shape.matrix)) <= MATRIX_AGREEMENT * scale:
                shape.matrix = exact
        if is_singular(shape.matrix):  # as SDL refuses it: no inverse to carry rays into generic space
            self.problem(prim, f"its {shape.kind} has a singular transform (a scale or size of 0?)")
            return None
        shape.material = self._material(prim)
        shape.groups = self._groups(prim)
        shape.source = SourceLocation(f"{self.file}<{prim.GetPath()}>", 0)
        return shape

    def _groups(self, prim, name: str = C.A_GROUPS) -> tuple[str, ...]:
        groups = self.get(prim, name, [])
        if isinstance(groups, str):  # one name written as a string rather than a string array
            groups = [groups]
        return tuple(str(g) for g in groups)

    def _round(self, prim, world: np.ndarray) -> Shape:
        """Cylinder, Cylinder_1 or Cone: centred on the origin along ``axis``, from -height/2 to height/2
        (the cone's apex at +height/2); ours run from z = 0 (radius 1) to z = 1."""
        get = lambda name, default: float(self.get(prim, name, default))  # noqa: E731
        axis = str(self.get(prim, "axis", "Z"))
        height = get("height", 2.0)
        if prim.IsA(self.UsdGeom.Cone):
            bottom, top, kind = get("radius", 1.0), 0.0, "cone"
        elif prim.GetTypeName() == "Cylinder_1":
            bottom, top, kind = get("radiusBottom", 1.0), get("radiusTop", 1.0), "taperedCylinder"
        else:
            bottom, top, kind = get("radius", 1.0), get("radius", 1.0), "cylinder"
        place = world @ C.axis_frame(axis)
        if bottom == 0.0 and top != 0.0:  # the apex at the bottom: turn it over (a half turn about x)
            place = place @ np.diag([1.0, -1.0, -1.0, 1.0])
            bottom, top = top, bottom
        matrix = place @ translation(0.0, 0.0, -0.5 * height) @ scaling(bottom, bottom, height)
        if kind == "taperedCylinder":
            ratio = top / bottom if bottom else 0.0
            if ratio == 1.0:
                return Shape("cylinder", matrix)
            if ratio == 0.0:
                return Shape("cone", matrix)
            return Shape(kind, matrix, parameters=(ratio,))
        return Shape(kind, matrix)

    def _plane(self, prim, world: np.ndarray, kind: Optional[str]) -> Shape:
        axis = str(self.get(prim, "axis", "Z"))
        place = world @ C.plane_frame(axis)
        if kind == "plane":  # ours: the infinite plane, whatever size its stand-in has
            return Shape("plane", place)
        width, length = float(self.get(prim, "width", 2.0)), float(self.get(prim, "length", 2.0))
        return Shape("square", place @ scaling(0.5 * width, 0.5 * length, 1.0))

    # -- meshes -----------------------------------------------------------------------------------------

    def _mesh(self, prim, world: np.ndarray, kind: Optional[str]) -> Optional[Shape]:
        entry = shapes.KINDS.get(kind)
        if entry is not None and entry.builtin_mesh:
            return Shape(kind, world, mesh=builtin_mesh(kind))
        if kind in _TESSELLATED:
            return Shape("mesh", world)  # the caller makes the exact shape
        reads_file = entry is not None and entry.file_argument
        if reads_file and self.get(prim, C.A_MESH_POINTS) is not None:
            data = sdl_mesh(self, prim)
        else:
            data = usd_mesh(self, prim)
        if data is None:
            return None
        shape = Shape("mesh", world, mesh=data)
        mesh_file = self.get(prim, C.A_MESH_FILE)
        if reads_file and mesh_file:
            shape.mesh_file = str(mesh_file)
        return shape

    # -- materials --------------------------------------------------------------------------------------

    def _material(self, prim) -> Material:
        if self.get(prim, C.A_SHAPE) is not None and self.get(prim, C.NS + "diffuse") is not None:
            return self._sdl_material(prim)
        return self._preview_material(prim)

    def _sdl_material(self, prim) -> Material:
        default = Material()
        values = {}
        for field_name, keyword in C.MATERIAL_COLORS.items():
            values[field_name] = self.triple(prim, C.NS + keyword, getattr(default, field_name))
        for field_name, keyword in C.MATERIAL_FLOATS.items():
            values[field_name] = float(self.get(prim, C.NS + keyword, getattr(default, field_name)))
        values["texture"] = whole_number(self.get(prim, C.A_TEXTURE, 0), C.A_TEXTURE, TEXTURE_NUMBERS)
        values["parameters"] = tuple(float(p) for p in self.get(prim, C.A_PARAMETERS, []))
        fresnel = self.get(prim, C.A_FRESNEL)
        if fresnel is not None:
            if str(fresnel) not in FRESNEL_MODES:
                raise ValueError(f"unknown sdl:fresnel {str(fresnel)!r}")
            values["fresnel"] = str(fresnel)
            values["fresnel_tint"] = self.triple(prim, C.A_FRESNEL_TINT, default.fresnel_tint)
        return Material(**values)

    def _bound_material(self, prim):
        """The material bound to ``prim``.  Bindings are resolved for every geometric prim of the stage in
        one batch the first time one is asked for (each ComputeBoundMaterial walks the prim's ancestors, in
        time the square of the depth for a deep tree); a prim outside that batch is resolved alone."""
        if self._bound is None:
            Usd = self.Usd
            predicate = Usd.TraverseInstanceProxies(Usd.PrimDefaultPredicate)
            prims = [p for p in Usd.PrimRange(self.stage.GetPseudoRoot(), predicate) if p.IsA(self.UsdGeom.Gprim)]
            materials, _ = self.UsdShade.MaterialBindingAPI.ComputeBoundMaterials(prims)
            self._bound = {p.GetPath(): m for p, m in zip(prims, materials)}
        if prim.GetPath() in self._bound:
            return self._bound[prim.GetPath()]
        return self.UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]

    def _preview_material(self, prim) -> Material:
        """SDL material from the bound UsdPreviewSurface, else from displayColor, else SDL's default."""
        UsdShade = self.UsdShade
        bound = self._bound_material(prim)
        shader = None
        if bound:
            source = bound.ComputeSurfaceSource()
            candidate = source[0] if source else None
            if candidate and str(candidate.GetIdAttr().Get() or "") == "UsdPreviewSurface":
                shader = candidate
            elif candidate:
                self.note(prim, f"its material's surface {candidate.GetIdAttr().Get()!r} is not a "
                                "UsdPreviewSurface: display colour used")
            else:  # only render-context outputs (outputs:mtlx:surface, a renderer's own), or none
                self.note(prim, "its material has no universal surface output (a UsdPreviewSurface): "
                                "display colour used")
        if shader is None:
            color = self.UsdGeom.Gprim(prim).GetDisplayColorAttr().Get(self.time)
            if color is None or len(color) == 0:
                return Material()
            if len(color) > 1:
                self.note(prim, "displayColor varies over the surface: its first value used")
            diffuse = tuple(float(x) for x in color[0])
            return Material(ambient=diffuse, diffuse=diffuse)

        def value(name):
            inp = shader.GetInput(name)
            if inp and inp.HasConnectedSource():
                self.note(prim, f"its {name} comes from a shader network (a texture?): its own value used")
            return inp.Get(self.time) if inp else None

        return material_from_preview(value)

    # -- lights and camera ------------------------------------------------------------------------------

    def _light(self, prim, type_name: str) -> None:
        light = self.UsdLux.LightAPI(prim)
        base = light.GetColorAttr().Get(self.time)
        base = (1.0, 1.0, 1.0) if base is None else tuple(float(x) for x in base)
        # Only an authored intensity counts: the schema's fallbacks are physical units (a DistantLight's is
        # 50000 lux), which mean nothing to SDL's unitless light colours.
        intensity = float(self.get(prim, "inputs:intensity", 1.0))
        exposure = float(self.get(prim, "inputs:exposure", 0.0))
        if light.GetEnableColorTemperatureAttr().Get(self.time):
            self.note(prim, "colour temperature is not supported: the light's colour used")
        with np.errstate(over="ignore", invalid="ignore"):
            color = tuple(float(c * intensity * np.exp2(exposure)) for c in base)
        if not all(np.isfinite(color)):
            self.problem(prim, f"light brightness out of range (intensity {intensity:g}, exposure {exposure:g})")
            return
        exact = self.triple(prim, C.A_LIGHT_COLOR)
        # Our exact colour, unless the light was changed in another tool since (its float colour differs).
        if exact is not None and tuple(float(np.float32(c)) for c in exact) == color:
            color = exact
        if type_name == "CylinderLight":
            self.note(prim, f"{type_name} read as a point light at its centre")
            self.scene.lights.append(Light(tuple(float(x) for x in self.world(prim)[:3, 3]), color,
                                           name=str(prim.GetName())))
            return
        try:
            self.scene.lights.append(read_light(self, prim, type_name, color))
        except (*_BAD_VALUE, SceneError) as err:
            self.problem(prim, f"{type_name}: {err}")

    def _camera(self, prim) -> None:
        if self.scene.camera is not None:
            self.note(prim, "a second camera: the first one is used")
            return
        camera = self.UsdGeom.Camera(prim)
        world = self.world(prim)
        ours = self._sdl_camera(prim, camera, world)
        if ours is not None:
            self.scene.camera = ours
            return
        if str(camera.GetProjectionAttr().Get(self.time)) != self.UsdGeom.Tokens.perspective:
            self.note(prim, "orthographic camera read as a perspective one")
        focal = float(camera.GetFocalLengthAttr().Get(self.time))
        aperture = float(camera.GetVerticalApertureAttr().Get(self.time))
        if not (focal > 0 and aperture > 0):
            self.problem(prim, "camera without a usable focal length and aperture")
            return
        back, up_axis = world[:3, 2], world[:3, 1]
        if not (np.linalg.norm(back) > 0 and np.linalg.norm(np.cross(back, up_axis)) > 0):
            self.problem(prim, "camera with a degenerate transform")
            return
        eye = world[:3, 3]
        angle = view_angle(focal, aperture)
        if not 0.0 < angle < 180.0:  # a focal length so long (or film so small) that no angle is left
            self.problem(prim, f"camera focal length {focal:g} and aperture {aperture:g} give no usable view "
                               f"angle", "the scene framed instead")
            return
        # The look-at point a unit in front of the eye, or further for an eye so far out that a unit step
        # would be lost to rounding (half the eye's distance: no overflow even at 1e308).
        far = float(np.max(np.abs(eye)))
        step = 1.0 if far < 2.0 ** 40 else 0.5 * far
        self.scene.camera = Camera(tuple(float(x) for x in eye),
                                   tuple(float(x) for x in eye - step * back / np.linalg.norm(back)),
                                   tuple(float(x) for x in up_axis / np.linalg.norm(up_axis)), angle)

    def _sdl_camera(self, prim, camera, world: np.ndarray) -> Optional[Camera]:
        """The exact SDL camera we stored, if the USD camera still agrees with it (not moved or zoomed
        in another tool since)."""
        eye, look, up = (self.triple(prim, name) for name in (C.A_EYE, C.A_LOOK, C.A_UP))
        angle = self.get(prim, C.A_VIEW_ANGLE)
        if None in (eye, look, up, angle):
            return None
        try:
            ours = Camera(eye, look, up, float(angle))
            frame = camera_frame(ours)
            aperture = float(camera.GetVerticalApertureAttr().Get(self.time))
            focal = float(camera.GetFocalLengthAttr().Get(self.time))
            wanted = focal_length(ours.view_angle, aperture)
        except (ValueError, ZeroDivisionError, TypeError):
            self.note(prim, "its sdl: camera values are unusable: read from the USD camera")
            return None
        scale = max(1.0, float(np.max(np.abs(frame))))
        if np.max(np.abs(frame - world)) > 1e-9 * scale or abs(focal - wanted) > 1e-5 * wanted:
            self.note(prim, "the camera was changed after it was written: read from the USD camera")
            return None
        return ours


_DESCEND = object()


def whole_number(value, name: str, allowed: Optional[range] = None) -> int:
    """An integer attribute's value (a file may author it as a float, even inf or nan): ValueError naming it
    when it is not a whole number, or not in ``allowed``."""
    number = float(value)
    if not (math.isfinite(number) and number == int(number)):
        raise ValueError(f"{name} = {value!r} is not a whole number")
    if allowed is not None and int(number) not in allowed:
        raise ValueError(f"{name} = {value!r} is out of range ({allowed.start}..{allowed.stop - 1})")
    return int(number)


def _time_code(Usd, stage):
    """The time to read an animated stage at: its start frame, else each value's earliest sample (a plain
    default value where there are no samples)."""
    if stage.HasAuthoredTimeCodeRange():
        return Usd.TimeCode(stage.GetStartTimeCode())
    return Usd.TimeCode.EarliestTime()


def time_range(path: PathLike) -> Optional[tuple[float, float]]:
    """The stage's authored (start, end) time codes, or None when it has no time code range."""
    stage, _ = open_stage(path)
    if not stage.HasAuthoredTimeCodeRange():
        return None
    return float(stage.GetStartTimeCode()), float(stage.GetEndTimeCode())


def load_usd(path: PathLike, strict: bool = True, time: Optional[float] = None) -> Scene:
    """Read a USD file into a Scene, at time code ``time`` (a frame; default: the stage's start frame, else
    each value's earliest sample).

    Strict (the default), anything that cannot be read -- an unsupported prim or light, a broken mesh, a
    reference to a missing file -- raises a TracerError naming the file and prim.  With ``strict=False``
    each becomes one message in ``scene.warnings`` and the rest is read.  Approximations (a rect light read
    as a point light, a material that is not a UsdPreviewSurface) are warnings either way."""
    stage, composition_errors = open_stage(path)
    with held_stderr() as printed:  # what USD says while we read (a binding without its API, say)
        scene = _Reader(stage, os.fspath(path), strict, time).read(composition_errors)
    for message in dict.fromkeys(printed):
        scene.warnings.append(f"{os.fspath(path)}: USD says: {message}")
    scene.source = Path(path)
    return scene
