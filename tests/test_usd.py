"""USD interchange (tracer.usd, docs/usd.md): SDL -> USD -> SDL keeps everything, what we write passes USD's
compliance checks, stages written by hand with the pxr API render with their objects where they belong, and
the command line converts and renders USD files."""
from __future__ import annotations

import math
import os
import subprocess
import sys
import warnings
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

# usd-core is part of requirements-dev.txt: without it these tests fail (they are not optional).
from pxr import Gf, Sdf, Tf, Usd, UsdGeom, UsdLux, UsdShade, UsdUtils, Vt

import tracer
from tracer.camera import CameraFrame
from tracer.errors import TracerError
from tracer.model import CSG, Camera, Light, Material, MeshData, Scene, Settings, Shape
from tracer.sdl.writer import save_sdl
from tracer.transforms import rotation, scaling, translation
from tracer.usd import load_usd, save_usd
from tracer.usd.common import from_gf, to_gf

ROOT = Path(__file__).parent.parent
SCENES = sorted((ROOT / "scenes").glob("*.sdl"))
SCENE_IDS = [p.stem for p in SCENES]


# --- comparing scenes field by field -----------------------------------------------------------------------

def same_file(a: str, b: str) -> bool:
    return os.path.realpath(a) == os.path.realpath(b)


def assert_same_scene(a: Scene, b: Scene, tol: float = 0.0, groups: bool = True) -> None:
    """Every object, matrix (to ``tol`` relative to the matrix's size), material, light, camera, setting and
    pixmap of ``a`` is in ``b``.  File names are compared as the files they name; ``groups`` (def macro
    names) only if asked, since SDL writes them as comments."""
    assert b.settings == a.settings
    assert b.lights == a.lights
    assert b.camera == a.camera
    assert sorted(a.pixmaps) == sorted(b.pixmaps)
    for number, name in a.pixmaps.items():
        assert same_file(name, b.pixmaps[number]), (number, name, b.pixmaps[number])
    assert len(a.objects) == len(b.objects)
    pairs = list(zip(a.objects, b.objects))
    while pairs:
        x, y = pairs.pop()
        assert type(x) is type(y)
        assert x.groups == y.groups or not groups
        if isinstance(x, CSG):
            assert x.op == y.op
            pairs += [(x.left, y.left), (x.right, y.right)]
            continue
        assert (x.kind, x.parameters, x.material) == (y.kind, y.parameters, y.material)
        error = float(np.max(np.abs(x.matrix - y.matrix)))
        assert error <= tol * max(1.0, float(np.max(np.abs(x.matrix)))), (x.kind, error)
        assert (x.mesh is None) == (y.mesh is None)
        if x.mesh is not None:
            assert np.array_equal(x.mesh.vertices, y.mesh.vertices)
            assert np.array_equal(x.mesh.normals, y.mesh.normals)
            assert [tuple(map(tuple, f)) for f in x.mesh.faces] == [tuple(map(tuple, f)) for f in y.mesh.faces]
        assert (x.mesh_file is None) == (y.mesh_file is None)
        if x.mesh_file is not None:
            assert same_file(Path(a.source).parent / x.mesh_file, Path(b.source).parent / y.mesh_file)


def sdl_to_usd_to_sdl(path: Path, folder: Path, ext: str = ".usda") -> tuple[Scene, Scene, Scene]:
    original = tracer.load(path)
    usd_path = folder / f"{path.stem}{ext}"
    save_usd(original, usd_path)
    from_usd = load_usd(usd_path)
    sdl_path = folder / "back" / f"{path.stem}.sdl"
    sdl_path.parent.mkdir(exist_ok=True)
    save_sdl(from_usd, sdl_path)
    return original, from_usd, tracer.load(sdl_path)


# --- round trips -------------------------------------------------------------------------------------------

@pytest.mark.parametrize("path", SCENES, ids=SCENE_IDS)
def test_bundled_scene_round_trips_through_usd(path, tmp_path):
    original, from_usd, back = sdl_to_usd_to_sdl(path, tmp_path)
    assert not from_usd.warnings
    assert_same_scene(original, from_usd, tol=0.0)  # USD itself loses nothing
    assert_same_scene(original, back, tol=1e-9, groups=False)  # SDL's transform statements: a few ulps


@pytest.mark.parametrize("ext", [".usdc", ".usd"])
def test_binary_formats_round_trip_too(ext, tmp_path):
    original, from_usd, _ = sdl_to_usd_to_sdl(ROOT / "scenes" / "shapes.sdl", tmp_path, ext)
    assert_same_scene(original, from_usd)
    assert (tmp_path / f"shapes{ext}").read_bytes().startswith(b"PXR-USDC")  # binary crate


def test_scene_round_trip_covers_every_kind_and_feature():
    kinds, groups, ops, textures = set(), False, set(), set()
    for path in SCENES:
        scene = tracer.load(path)
        kinds |= {s.kind for s in scene.shapes()}
        groups |= any(s.groups for s in scene.shapes())
        ops |= {o.op for o in scene.objects if isinstance(o, CSG)}
        textures |= {s.material.texture for s in scene.shapes()}
    assert len(kinds) == 16 and groups and ops == {"union", "intersection", "difference"}
    assert {-1, -2, -3, 1, 2} <= textures


@pytest.mark.parametrize("path", SCENES, ids=SCENE_IDS)
def test_images_from_sdl_and_from_its_usd_are_identical(path, tmp_path):
    original = tracer.load(path)
    save_usd(original, tmp_path / "scene.usda")
    converted = load_usd(tmp_path / "scene.usda")
    a = tracer.render(original, 96, 72).image
    b = tracer.render(converted, 96, 72).image
    assert np.array_equal(np.round(a * 255), np.round(b * 255))
    assert float(np.max(np.abs(a - b))) == 0.0


def random_matrix(draw) -> np.ndarray:
    """A random invertible affine matrix: rotation, scale (mirrors too), shear and translation."""
    values = st.floats(-5, 5, allow_nan=False, allow_infinity=False)
    m = rotation(draw(st.floats(-360, 360)), *draw(st.tuples(values, values, values).filter(
        lambda v: math.hypot(*v) > 0.1)))
    scale = [draw(st.sampled_from([-1.0, 1.0])) * draw(st.floats(0.1, 8)) for _ in range(3)]
    shear = np.eye(4)
    shear[0, 1], shear[1, 2] = draw(values) / 5, draw(values) / 5
    return translation(draw(values), draw(values), draw(values)) @ m @ shear @ scaling(*scale)


colors = st.tuples(*[st.floats(0, 2, allow_nan=False)] * 3)


@st.composite
def random_materials(draw) -> Material:
    return Material(ambient=draw(colors), diffuse=draw(colors), specular=draw(colors), emissive=draw(colors),
                    specular_exponent=draw(st.floats(0, 500)), reflectivity=draw(st.floats(0, 1)),
                    transparency=draw(st.floats(0, 1)), speed_of_light=draw(st.floats(0.1, 3)),
                    specular_fraction=draw(st.floats(0, 1)), surface_roughness=draw(st.floats(0.01, 2)),
                    texture=draw(st.integers(-3, 0)),
                    parameters=tuple(draw(st.lists(st.floats(-100, 100), max_size=10))))


TRIANGLES = MeshData(np.array([[0.1, 0.2, 0.3], [1.0 / 3.0, 0.0, 0.0], [0.0, 1.0, 2.0 / 7.0], [1.0, 1.0, 1.0]]),
                     np.array([[0.0, 0.0, 1.0], [0.6, 0.8, 0.0]]),
                     [((0, 1, 2), (0, 0, 1)), ((1, 3, 2), ())])


@st.composite
def random_objects(draw, depth=0):
    if depth < 3 and draw(st.integers(0, 3)) == 0:
        return CSG(draw(st.sampled_from(CSG.OPS)), draw(random_objects(depth + 1)),
                   draw(random_objects(depth + 1)), groups=tuple(draw(st.lists(st.sampled_from("abc"), max_size=2))))
    kind = draw(st.sampled_from(["sphere", "cube", "square", "plane", "taperedCylinder", "cylinder", "cone",
                                 "torus", "octahedron", "mesh"]))
    shape = Shape(kind, random_matrix(draw), draw(random_materials()),
                  groups=tuple(draw(st.lists(st.sampled_from(["jack", "arm", "x.y"]), max_size=3))))
    if kind == "taperedCylinder":
        shape.parameters = (draw(st.floats(0, 3)),)
    if kind == "mesh":
        shape.mesh = TRIANGLES
    if kind == "octahedron":
        from tracer.sdl.parser import builtin_mesh
        shape.mesh = builtin_mesh(kind)
    return shape


@st.composite
def random_scenes(draw) -> Scene:
    vec = st.tuples(*[st.floats(-50, 50, allow_nan=False)] * 3)
    camera = draw(st.none() | st.builds(Camera, vec, vec, st.just((0.0, 1.0, 0.0)), st.floats(1, 170)))
    if camera is not None and np.linalg.norm(np.cross(np.subtract(camera.look, camera.eye), camera.up)) < 1e-3:
        camera = None
    return Scene(objects=draw(st.lists(random_objects(), min_size=1, max_size=5)),
                 lights=draw(st.lists(st.builds(Light, vec, colors), max_size=3)), camera=camera,
                 settings=Settings(draw(colors), draw(colors), draw(st.floats(0, 1)), draw(st.floats(0, 1)),
                                   draw(st.integers(0, 20))))


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture])
@given(random_scenes())
def test_random_scenes_round_trip_exactly(tmp_path, scene):
    """Shears, mirrors, odd materials, nested booleans, groups, meshes with and without normals: all exact."""
    path = tmp_path / "random.usdc"
    save_usd(scene, path)
    back = load_usd(path)
    assert not back.warnings
    assert_same_scene(scene, back, tol=0.0)


def test_deep_csg_needs_no_recursion(tmp_path):
    obj = Shape("sphere")
    for k in range(1500):
        obj = CSG("union", obj, Shape("cube", translation(k, 0, 0)))
    save_usd(Scene(objects=[obj]), tmp_path / "deep.usdc")
    back = load_usd(tmp_path / "deep.usdc")
    assert len(back.shapes()) == 1501
    assert back.objects[0].op == "union" and back.objects[0].right.matrix[0, 3] == 1499


# --- what the files look like to other tools ---------------------------------------------------------------

@pytest.fixture(scope="module")
def written(tmp_path_factory):
    folder = tmp_path_factory.mktemp("usd")
    paths = {}
    for path in SCENES:
        paths[path.stem] = folder / f"{path.stem}.usda"
        save_usd(tracer.load(path), paths[path.stem])
    return paths


@pytest.mark.parametrize("name", SCENE_IDS)
def test_compliance_checker_finds_nothing(written, name):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", DeprecationWarning)  # it is deprecated in favour of UsdValidation
        checker = UsdUtils.ComplianceChecker()
        checker.CheckCompliance(str(written[name]))
    assert checker.GetErrors() == []
    assert checker.GetFailedChecks() == []
    assert checker.GetWarnings() == []


@pytest.mark.parametrize("name", SCENE_IDS)
def test_usd_validation_framework_finds_nothing(written, name):
    validation = pytest.importorskip("pxr.UsdValidation")
    validators = validation.ValidationRegistry().GetOrLoadAllValidators()
    assert validators
    errors = validation.ValidationContext(validators).Validate(Usd.Stage.Open(str(written[name])))
    assert [e.GetMessage() for e in errors] == []


def test_stage_metadata_and_layout(written):
    stage = Usd.Stage.Open(str(written["csg"]))
    assert UsdGeom.GetStageUpAxis(stage) == "Y" and UsdGeom.GetStageMetersPerUnit(stage) == 1.0
    assert stage.GetDefaultPrim().GetPath() == "/SDLScene"
    root = stage.GetPrimAtPath("/SDLScene")
    assert root.GetAttribute("sdl:background").Get() == Gf.Vec3d(0.2, 0.25, 0.3)
    assert root.GetAttribute("sdl:maxRecursionDepth").Get() == 3
    # the nested difference: a group with two operands, left then right, each visible with its own transform
    outer = stage.GetPrimAtPath("/SDLScene/Objects/difference_0")
    assert outer.GetAttribute("sdl:csg").Get() == "difference"
    children = outer.GetChildren()
    assert [c.GetName() for c in children] == ["difference_1", "cylinder_0"]
    assert [c.GetAttribute("sdl:operand").Get() for c in children] == ["left", "right"]
    inner = children[0].GetChildren()
    assert [c.GetTypeName() for c in inner] == ["Cube", "Sphere"]
    cache = UsdGeom.XformCache()
    for prim in inner + [children[1]]:
        assert UsdGeom.Imageable(prim).ComputeVisibility() == UsdGeom.Tokens.inherited
        assert UsdGeom.Xformable(prim).GetXformOpOrderAttr().Get() == Vt.TokenArray(["xformOp:transform"])
    sphere = from_gf(cache.GetLocalToWorldTransform(inner[1]))
    assert np.array_equal(sphere, translation(4.4, 1.5, 1) @ scaling(1.1, 1.1, 1.1))


def test_implicit_prims_match_the_sdl_generic_shapes(written):
    """Other tools see the same surfaces: USD's cylinder and cone are centred on the origin, ours start at
    z = 0, so their transform includes half a unit up; the cone's apex (+height/2) is our z = 1."""
    stage = Usd.Stage.Open(str(written["lecture"]))
    scene = tracer.load(ROOT / "scenes" / "lecture.sdl")
    cache = UsdGeom.XformCache()
    prims = [p for p in stage.Traverse() if p.HasAttribute("sdl:shape")]
    assert [p.GetAttribute("sdl:shape").Get() for p in prims] == [s.kind for s in scene.shapes()]
    for prim, shape in zip(prims, scene.shapes()):
        world = from_gf(cache.GetLocalToWorldTransform(prim))
        if shape.kind in ("cylinder", "cone"):
            gprim = UsdGeom.Cylinder(prim) if shape.kind == "cylinder" else UsdGeom.Cone(prim)
            assert (gprim.GetRadiusAttr().Get(), gprim.GetHeightAttr().Get(), gprim.GetAxisAttr().Get()) == (1, 1, "Z")
            usd_base, usd_top = world @ [0, 0, -0.5, 1], world @ [0, 0, 0.5, 1]
            assert np.allclose(usd_base, shape.matrix @ [0, 0, 0, 1], atol=1e-12)
            assert np.allclose(usd_top, shape.matrix @ [0, 0, 1, 1], atol=1e-12)
        else:
            assert np.array_equal(world, shape.matrix)
        if shape.kind == "sphere":
            assert UsdGeom.Sphere(prim).GetRadiusAttr().Get() == 1.0
        binding = UsdShade.MaterialBindingAPI(prim).ComputeBoundMaterial()[0]
        surface = binding.ComputeSurfaceSource()[0]
        assert surface.GetIdAttr().Get() == "UsdPreviewSurface"
        assert np.allclose(surface.GetInput("diffuseColor").Get(), shape.material.diffuse, atol=1e-7)
        assert prim.GetAttribute("sdl:diffuse").Get() == Gf.Vec3d(*shape.material.diffuse)


def test_meshes_for_other_tools(written):
    stage = Usd.Stage.Open(str(written["shapes"]))
    by_kind = {p.GetAttribute("sdl:shape").Get(): p for p in stage.Traverse() if p.HasAttribute("sdl:shape")}
    for kind in ("square", "taperedCylinder", "torus", "teapot"):
        mesh = UsdGeom.Mesh(by_kind[kind])
        assert mesh, kind
        counts = np.array(mesh.GetFaceVertexCountsAttr().Get())
        assert len(mesh.GetFaceVertexIndicesAttr().Get()) == counts.sum()
        assert len(mesh.GetNormalsAttr().Get()) == counts.sum() and mesh.GetNormalsInterpolation() == "faceVarying"
        assert mesh.GetSubdivisionSchemeAttr().Get() == "none"
    assert by_kind["taperedCylinder"].GetAttribute("sdl:smallRadius").Get() == 0.5
    # the torus mesh lies on the generic torus: ring radius 1, tube 0.2
    points = np.array(UsdGeom.Mesh(by_kind["torus"]).GetPointsAttr().Get(), dtype=float)
    ring = np.hypot(points[:, 0], points[:, 1])
    assert np.allclose(np.hypot(ring - 1.0, points[:, 2]), 0.2, atol=1e-6)
    # the SDL plane is infinite: a big UsdGeom.Plane stands in for it
    plane = UsdGeom.Plane(by_kind["plane"])
    assert plane.GetWidthAttr().Get() > 100 and plane.GetAxisAttr().Get() == "Z"


def test_lights_and_camera_for_other_tools(written):
    stage = Usd.Stage.Open(str(written["lecture"]))
    scene = tracer.load(ROOT / "scenes" / "lecture.sdl")
    cache = UsdGeom.XformCache()
    lights = [p for p in stage.Traverse() if p.IsA(UsdLux.SphereLight)]
    assert len(lights) == len(scene.lights)
    for prim, light in zip(lights, scene.lights):
        lux = UsdLux.SphereLight(prim)
        assert lux.GetRadiusAttr().Get() == 0 and lux.GetIntensityAttr().Get() == 1
        assert np.allclose(lux.GetColorAttr().Get(), light.color, atol=1e-7)
        assert np.array_equal(from_gf(cache.GetLocalToWorldTransform(prim))[:3, 3], light.position)
    camera = UsdGeom.Camera(stage.GetPrimAtPath("/SDLScene/Camera"))
    gf_camera = camera.GetCamera(Usd.TimeCode.Default())
    assert gf_camera.GetFieldOfView(Gf.Camera.FOVVertical) == pytest.approx(scene.camera.view_angle, abs=1e-4)
    frame = from_gf(cache.GetLocalToWorldTransform(camera.GetPrim()))
    assert np.allclose(frame[:3, 3], scene.camera.eye)
    view = np.subtract(scene.camera.look, scene.camera.eye)
    assert np.allclose(-frame[:3, 2], view / np.linalg.norm(view))  # USD cameras look down -z
    assert np.dot(frame[:3, 1], scene.camera.up) > 0.9
    # Other tools clip; the range holds every object and light (USD's default near of 1 would not).
    near, far = gf_camera.clippingRange.min, gf_camera.clippingRange.max
    things = [s.matrix[:3, 3] for s in scene.shapes() if s.kind != "plane"] + [l.position for l in scene.lights]
    distances = np.linalg.norm(np.subtract(things, scene.camera.eye), axis=1)
    assert near < 0.1 * distances.min() and far > distances.max()


def test_matrix_convention_is_usd_row_vectors():
    m = translation(1, 2, 3) @ rotation(30, 1, 2, 3) @ scaling(1, 2, -3)
    gf = to_gf(m)
    assert np.allclose(np.array(gf.Transform(Gf.Vec3d(0.5, -1, 2))), (m @ [0.5, -1, 2, 1])[:3])
    assert tuple(gf.ExtractTranslation()) == (1, 2, 3)
    assert np.array_equal(from_gf(gf), m)


# --- stages made by other tools ----------------------------------------------------------------------------

def hand_made_stage(path: Path) -> None:
    """What another tool might write: z-up, composed transforms, implicit prims, a mesh, a bound
    UsdPreviewSurface, a sphere light, a distant light, a camera, and things a render must leave out."""
    stage = Usd.Stage.CreateNew(str(path))
    UsdGeom.SetStageUpAxis(stage, UsdGeom.Tokens.z)
    world = UsdGeom.Xform.Define(stage, "/World")
    stage.SetDefaultPrim(world.GetPrim())
    group = UsdGeom.Xform.Define(stage, "/World/Group")
    group.AddTranslateOp().Set(Gf.Vec3d(3, 0, 0))
    ball = UsdGeom.Sphere.Define(stage, "/World/Group/Ball")  # radius 2 at (3, 0, 0)
    ball.CreateRadiusAttr(2.0)
    ball.CreateDisplayColorAttr([Gf.Vec3f(0, 1, 0)])

    box = UsdGeom.Cube.Define(stage, "/World/Box")  # [-0.5, 0.5]^3 around (-3, 0, 0), turned 45 degrees
    box.CreateSizeAttr(1.0)
    box.AddTranslateOp().Set(Gf.Vec3d(-3, 0, 0))
    box.AddRotateZOp().Set(45.0)
    red = UsdShade.Material.Define(stage, "/World/Looks/Red")
    shader = UsdShade.Shader.Define(stage, "/World/Looks/Red/Surface")
    shader.CreateIdAttr("UsdPreviewSurface")
    shader.CreateInput("diffuseColor", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(1, 0, 0))
    shader.CreateInput("roughness", Sdf.ValueTypeNames.Float).Set(0.4)
    red.CreateSurfaceOutput().ConnectToSource(shader.ConnectableAPI(), "surface")
    UsdShade.MaterialBindingAPI.Apply(box.GetPrim()).Bind(red)

    floor = UsdGeom.Mesh.Define(stage, "/World/Floor")  # a pentagon and a quad in z = -3, normal +z
    floor.CreatePointsAttr([(-10, -10, -3), (10, -10, -3), (10, 10, -3), (0, 12, -3), (-10, 10, -3),
                            (-10, -20, -3), (10, -20, -3)])
    floor.CreateFaceVertexCountsAttr([5, 4])
    floor.CreateFaceVertexIndicesAttr([0, 1, 2, 3, 4, 5, 6, 1, 0])
    floor.CreateNormalsAttr([(0, 0, 1)] * 7)
    floor.SetNormalsInterpolation(UsdGeom.Tokens.vertex)

    tube = UsdGeom.Cylinder.Define(stage, "/World/Tube")  # along y, radius 0.5, y from -1 to 1, at x = 8
    tube.CreateAxisAttr("Y")
    tube.CreateRadiusAttr(0.5)
    tube.CreateHeightAttr(2.0)
    tube.AddTranslateOp().Set(Gf.Vec3d(8, 0, 0))
    cone = UsdGeom.Cone.Define(stage, "/World/Cone")  # along x, apex at x = -7, base at x = -9
    cone.CreateAxisAttr("X")
    cone.CreateHeightAttr(2.0)
    cone.CreateRadiusAttr(1.0)
    cone.AddTranslateOp().Set(Gf.Vec3d(-8, 5, 0))

    hidden = UsdGeom.Sphere.Define(stage, "/World/Hidden")
    hidden.AddTranslateOp().Set(Gf.Vec3d(0, 0, 5))
    hidden.CreateVisibilityAttr(UsdGeom.Tokens.invisible)
    guide = UsdGeom.Cube.Define(stage, "/World/Guide")
    guide.AddTranslateOp().Set(Gf.Vec3d(0, 0, 5))
    guide.CreatePurposeAttr(UsdGeom.Tokens.guide)

    key = UsdLux.SphereLight.Define(stage, "/World/Key")
    key.CreateIntensityAttr(0.5)
    key.CreateExposureAttr(1.0)  # 0.5 * 2^1 = 1
    key.CreateColorAttr(Gf.Vec3f(1, 1, 1))
    key.AddTranslateOp().Set(Gf.Vec3d(0, -10, 10))
    sun = UsdLux.DistantLight.Define(stage, "/World/Sun")
    sun.CreateColorAttr(Gf.Vec3f(0.5, 0.5, 0.5))
    sun.AddRotateXOp().Set(-90.0)  # its -z turns to -y: it shines along -y

    camera = UsdGeom.Camera.Define(stage, "/World/Camera")  # at z = 30 looking down -z, y up
    camera.CreateFocalLengthAttr(20.0)
    camera.CreateVerticalApertureAttr(20.0)
    camera.CreateHorizontalApertureAttr(20.0)
    camera.AddTranslateOp().Set(Gf.Vec3d(0, 0, 30))
    stage.GetRootLayer().Save()


@pytest.fixture(scope="module")
def foreign(tmp_path_factory):
    path = tmp_path_factory.mktemp("foreign") / "hand_made.usda"
    hand_made_stage(path)
    return path, load_usd(path)


def ray_hits(scene, start, direction):
    return [(round(h.t, 9), h.entering, h.shape.kind) for h in tracer.hits(scene, start, direction)]


#: The hand-made stage is z-up; the reader turns it into SDL's y-up world: (x, y, z) -> (x, z, -y).
Z_UP = np.array([[1.0, 0.0, 0.0], [0.0, 0.0, 1.0], [0.0, -1.0, 0.0]])


def z_up(point) -> tuple:
    """A point or direction of the z-up stage in the scene we read (exact: the rotation only permutes)."""
    return tuple(float(x) + 0.0 for x in Z_UP @ np.asarray(point, dtype=float))


def z_up_hits(scene, start, direction):
    """ray_hits for a ray given in the z-up stage's coordinates."""
    return ray_hits(scene, z_up(start), z_up(direction))


def test_foreign_stage_objects_are_where_they_should_be(foreign):
    _, scene = foreign
    assert sorted(s.kind for s in scene.shapes()) == ["cone", "cube", "cylinder", "mesh", "sphere"]
    # the sphere of radius 2 under the translated group: z from -2 to 2 at (3, 0)
    assert z_up_hits(scene, (3, 0, 10), (0, 0, -1)) == [(8, True, "sphere"), (12, False, "sphere"), (13, True, "mesh")]
    assert z_up_hits(scene, (5.5, 0, 10), (0, 0, -1)) == [(13, True, "mesh")]
    # the cube of size 1 turned 45 degrees about z at (-3, 0, 0): faces at z = ±0.5, corners at x = -3 ± 0.7071
    assert z_up_hits(scene, (-3, 0, 10), (0, 0, -1))[:2] == [(9.5, True, "cube"), (10.5, False, "cube")]
    hits = tracer.hits(scene, (-10, 0, 0), (1, 0, 0))  # x is x in both frames
    assert [h.shape.kind for h in hits][:2] == ["cube", "cube"]
    assert hits[0].t == pytest.approx(7 - math.sqrt(0.5), abs=1e-12)
    # the hidden sphere and the guide cube are left out: nothing but the floor on the z axis
    assert z_up_hits(scene, (0, 0, 10), (0, 0, -1)) == [(13, True, "mesh")]
    # the pentagon is triangulated: a point near its apex (0, 12) is on it, one beside the apex is not
    assert z_up_hits(scene, (0, 11.5, 10), (0, 0, -1)) == [(13, True, "mesh")]
    assert z_up_hits(scene, (4, 11.5, 10), (0, 0, -1)) == []
    assert z_up_hits(scene, (0, -15, 10), (0, 0, -1)) == [(13, True, "mesh")]  # the quad
    # the cylinder along y: radius 0.5 around x = 8, y from -1 to 1
    assert z_up_hits(scene, (8, 10, 0), (0, -1, 0)) == [(9, True, "cylinder"), (11, False, "cylinder")]
    assert z_up_hits(scene, (0, 0.99, 0.0), (1, 0, 0))[-2:] == [(7.5, True, "cylinder"), (8.5, False, "cylinder")]
    # the cone along x: base (radius 1) at x = -9, apex at x = -7
    assert z_up_hits(scene, (-20, 5, 0), (1, 0, 0)) == [(11, True, "cone"), (13, False, "cone")]
    cone_side = z_up_hits(scene, (-8, 5, 10), (0, 0, -1))  # half way: radius 0.5; then the floor
    assert cone_side == [(9.5, True, "cone"), (10.5, False, "cone"), (13, True, "mesh")]


def test_foreign_stage_materials_lights_and_camera(foreign):
    _, scene = foreign
    by_kind = {s.kind: s for s in scene.shapes()}
    assert by_kind["cube"].material.diffuse == (1.0, 0.0, 0.0)
    assert by_kind["cube"].material.specular_exponent == pytest.approx(2 / 0.4 ** 2 - 2, rel=1e-6)
    assert by_kind["sphere"].material.diffuse == (0.0, 1.0, 0.0)  # displayColor, no material bound
    assert by_kind["mesh"].material == Material()  # nothing said: SDL's defaults
    key, sun = scene.lights
    assert key == Light(z_up((0.0, -10.0, 10.0)), (1.0, 1.0, 1.0), name="Key")  # (named as its prim)
    assert (sun.kind, sun.name, sun.color, sun.angle) == ("sun", "Sun", (0.5, 0.5, 0.5), 0.0)
    # the sun shines along the stage's -y
    np.testing.assert_allclose(Z_UP.T @ np.asarray(sun.direction), (0.0, -1.0, 0.0), atol=1e-12)
    camera = scene.camera  # at the stage's z = 30 looking down its -z, its +y up
    assert camera.eye == z_up((0.0, 0.0, 30.0)) and camera.look == z_up((0.0, 0.0, 29.0))
    assert camera.up == z_up((0.0, 1.0, 0.0))
    assert camera.view_angle == pytest.approx(math.degrees(2 * math.atan(10 / 20)))
    assert scene.warnings == []


def pixel(image, frame: CameraFrame, point, width, height):
    rel = np.asarray(point, dtype=float) - frame.eye
    depth = -np.dot(rel, frame.n)
    x = np.dot(rel, frame.u) / depth / frame.half_width
    y = np.dot(rel, frame.v) / depth / frame.half_height
    col, row_from_bottom = int((x + 1) / 2 * width), int((y + 1) / 2 * height)
    assert depth > 0 and 0 <= col < width and 0 <= row_from_bottom < height, ("not in the picture", point)
    return image[height - 1 - row_from_bottom, col]


def test_foreign_stage_renders_with_the_right_colours(foreign):
    _, scene = foreign
    width, height = 120, 120
    image = tracer.render(scene, width, height).image
    frame = CameraFrame.from_camera(scene.camera, 1.0)
    box = pixel(image, frame, z_up((-3, 0, 0.5)), width, height)
    assert box[0] > 0.3 and box[1] < 0.1 * box[0] + 0.05 and box[1] == pytest.approx(box[2], abs=1e-6)
    ball = pixel(image, frame, z_up((3, 0, 2)), width, height)
    assert ball[1] > 0.3 and ball[0] < 0.2 * ball[1] and ball[2] < 0.2 * ball[1]
    floor = pixel(image, frame, z_up((0, 5, -3)), width, height)
    assert floor[0] == pytest.approx(floor[1], abs=1e-6) == pytest.approx(floor[2], abs=1e-6) and floor[0] > 0.2
    sky = pixel(image, frame, z_up((-12, 14, -3)), width, height)  # past the floor's corner: the background
    assert np.allclose(sky, Settings().background, atol=1 / 255)
    # the floor lit by both lights (SDL shading, no attenuation): 0.8 grey diffuse, 0.1 x 0.1 ambient
    point = np.array([0.0, 5.0, -3.0])
    key = np.array([0.0, -10.0, 10.0]) - point
    expected = 0.1 * 0.1 + 0.8 * (key[2] / np.linalg.norm(key)) * 1.0 + 0.0
    assert floor[0] == pytest.approx(expected, abs=0.02)


STILL_LIFE = ROOT / "scenes" / "usd" / "still_life.usda"


def test_hand_written_stage_renders_and_converts_from_the_command_line(tmp_path):
    """scenes/usd/still_life.usda, written by hand as another tool would (z-up, op stacks, no sdl:
    attributes): each object shows in its material's colour where the camera sees it, and its SDL
    conversion renders the same picture."""
    from PIL import Image

    width, height = 240, 180
    proc = run("render", STILL_LIFE, "-o", tmp_path / "usd.png", "--width", width, "--height", height, "-q")
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    image = np.asarray(Image.open(tmp_path / "usd.png"), dtype=float) / 255
    scene = load_usd(STILL_LIFE)
    assert scene.warnings == []
    frame = CameraFrame.from_camera(scene.camera, width / height)

    def colour(point):  # a point of the z-up stage
        return pixel(image, frame, z_up(point), width, height)

    def dominant(c, k):
        return all(c[k] > 1.5 * c[j] + 0.02 for j in range(3) if j != k)

    assert dominant(colour((-1.6, -0.3, 0.9)), 0)  # the red box
    assert dominant(colour((0.0, -0.3, 1.0)), 1)  # the green ball
    assert dominant(colour((1.6, -0.35, 0.9)), 2)  # the blue can
    hat = colour((0.0, 1.675, 0.75))  # the yellow cone's tip, above the ball
    assert hat[0] > 0.3 and hat[1] > 0.3 and hat[2] < 0.5 * hat[1]
    floor = colour((0.0, -3.0, 0.0))
    assert floor[0] > 0.3 and np.ptp(floor) < 0.02  # grey
    assert np.allclose(colour((0.0, 30.0, 2.0)), Settings().background, atol=1 / 255)  # nothing there
    proc = run("convert", STILL_LIFE, tmp_path / "still_life.sdl")
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    proc = run("render", tmp_path / "still_life.sdl", "-o", tmp_path / "sdl.png", "--width", width,
               "--height", height, "-q")
    assert proc.returncode == 0, proc.stderr
    assert np.max(np.abs(np.asarray(Image.open(tmp_path / "sdl.png"), dtype=float) / 255 - image)) <= 1 / 255


def test_foreign_instances_lefthanded_meshes_and_unsupported_prims(tmp_path):
    stage = Usd.Stage.CreateInMemory()
    proto = UsdGeom.Xform.Define(stage, "/Proto")
    proto.GetPrim().SetSpecifier(Sdf.SpecifierClass)
    tri = UsdGeom.Mesh.Define(stage, "/Proto/Tri")
    tri.CreatePointsAttr([(0, 0, 0), (0, 1, 0), (1, 0, 0)])  # clockwise seen from +z ...
    tri.CreateFaceVertexCountsAttr([3])
    tri.CreateFaceVertexIndicesAttr([0, 1, 2])
    tri.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)  # ... which left-handed makes face +z
    for k in range(2):
        inst = UsdGeom.Xform.Define(stage, f"/Inst{k}")
        inst.AddTranslateOp().Set(Gf.Vec3d(5 * k, 0, 0))
        inst.GetPrim().GetInherits().AddInherit("/Proto")
        inst.GetPrim().SetInstanceable(True)
    UsdGeom.Capsule.Define(stage, "/Pill")
    UsdLux.DomeLight.Define(stage, "/Dome")
    path = tmp_path / "instances.usda"
    stage.GetRootLayer().Export(str(path))
    with pytest.raises(TracerError, match=r"instances\.usda: </Pill>: Capsule is not supported"):
        load_usd(path)  # strict: what cannot be read is an error naming the file and prim
    scene = load_usd(path, strict=False)
    assert len(scene.shapes()) == 2
    for k, shape in enumerate(scene.shapes()):
        hit = tracer.hits(scene, (5 * k + 0.2, 0.2, 5), (0, 0, -1))
        assert len(hit) == 1 and hit[0].t == pytest.approx(5) and hit[0].normal[2] == pytest.approx(1)
    assert any("Capsule" in w for w in scene.warnings) and any("DomeLight" in w for w in scene.warnings)
    assert scene.lights == []


def test_foreign_plane_and_tapered_cylinder(tmp_path):
    stage = Usd.Stage.CreateInMemory()
    plane = UsdGeom.Plane.Define(stage, "/Wall")  # width along x, length along z, normal +y
    plane.CreateAxisAttr("Y")
    plane.CreateWidthAttr(4.0)
    plane.CreateLengthAttr(6.0)
    frustum = stage.DefinePrim("/Frustum", "Cylinder_1")
    frustum.CreateAttribute("radiusBottom", Sdf.ValueTypeNames.Double).Set(2.0)
    frustum.CreateAttribute("radiusTop", Sdf.ValueTypeNames.Double).Set(1.0)
    frustum.CreateAttribute("height", Sdf.ValueTypeNames.Double).Set(4.0)
    UsdGeom.Xformable(frustum).AddTranslateOp().Set(Gf.Vec3d(0, 0, 20))
    path = tmp_path / "plane.usda"
    stage.GetRootLayer().Export(str(path))
    scene = load_usd(path)
    wall, cone = scene.shapes()
    assert wall.kind == "square" and cone.kind == "taperedCylinder" and cone.parameters == (0.5,)
    assert ray_hits(scene, (1.9, 5, 2.9), (0, -1, 0)) == [(5, True, "square"), (5, False, "square")]  # a sheet
    assert ray_hits(scene, (2.1, 5, 0), (0, -1, 0)) == [] and ray_hits(scene, (0, 5, 3.1), (0, -1, 0)) == []
    # the frustum: z from 18 (radius 2) to 22 (radius 1); at z = 20 the radius is 1.5
    assert ray_hits(scene, (-10, 0, 20), (1, 0, 0)) == [(8.5, True, "taperedCylinder"),
                                                         (11.5, False, "taperedCylinder")]
    assert ray_hits(scene, (0, 0, 30), (0, 0, -1)) == [(8, True, "taperedCylinder"), (12, False, "taperedCylinder")]


def test_animated_stages_are_read_at_their_start(tmp_path):
    """Transforms with time samples only: read at the stage's start time code, or where it has no time
    range, at each value's earliest sample (a default-time read would find no transform at all)."""
    for start in (None, 5.0):
        stage = Usd.Stage.CreateInMemory()
        ball = UsdGeom.Sphere.Define(stage, "/Ball")
        move = ball.AddTranslateOp()
        for frame, x in ((1.0, 1.0), (5.0, 2.0), (10.0, 3.0)):
            move.Set(Gf.Vec3d(x, 0, 0), frame)
        if start is not None:
            stage.SetStartTimeCode(start)
            stage.SetEndTimeCode(10.0)
        path = tmp_path / f"animated{start}.usda"
        stage.GetRootLayer().Export(str(path))
        shape, = load_usd(path).shapes()
        assert shape.matrix[0, 3] == (1.0 if start is None else 2.0)


def test_a_stage_we_wrote_and_someone_edited_follows_the_edits(tmp_path):
    scene = tracer.parse_sdl("light 1 2 3  0.5 0.5 0.5  camera 0 0 10  0 0 0  0 1 0  30  sphere")
    path = tmp_path / "edited.usda"
    save_usd(scene, path)
    stage = Usd.Stage.Open(str(path))
    UsdGeom.Sphere(stage.GetPrimAtPath("/SDLScene/Objects/sphere_0")).GetRadiusAttr().Set(3.0)
    UsdLux.SphereLight(stage.GetPrimAtPath("/SDLScene/Lights/light_0")).GetIntensityAttr().Set(2.0)
    UsdGeom.Xformable(stage.GetPrimAtPath("/SDLScene/Camera")).MakeMatrixXform().Set(
        to_gf(translation(0, 0, 20)))
    stage.GetRootLayer().Save()
    back = load_usd(path)
    assert np.array_equal(back.shapes()[0].matrix, scaling(3, 3, 3))
    assert back.lights[0].color == (1.0, 1.0, 1.0)
    assert back.camera.eye == (0.0, 0.0, 20.0) and back.camera.view_angle == pytest.approx(30.0)
    assert any("camera was changed" in w for w in back.warnings)


def test_a_degenerate_sdl_camera_falls_back_to_the_usd_camera(tmp_path):
    """sdl:look edited onto sdl:eye: no camera from those values (its frame would be NaN, which compared
    as 'unchanged'), the USD camera instead, with a warning."""
    path = tmp_path / "camera.usda"
    save_usd(tracer.parse_sdl("camera 0 0 10  0 0 0  0 1 0  30  sphere"), path)
    stage = Usd.Stage.Open(str(path))
    stage.GetPrimAtPath("/SDLScene/Camera").GetAttribute("sdl:look").Set(Gf.Vec3d(0, 0, 10))
    stage.GetRootLayer().Save()
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no NaN arithmetic on the way
        back = load_usd(path)
    assert back.camera.eye == (0.0, 0.0, 10.0) and back.camera.look == (0.0, 0.0, 9.0)
    assert back.camera.view_angle == pytest.approx(30.0)
    assert any("camera values are unusable" in w for w in back.warnings)


@pytest.mark.parametrize("prim, name, type_name, value", [
    ("/SDLScene", "sdl:background", Sdf.ValueTypeNames.String, "blue"),
    ("/SDLScene", "sdl:maxRecursionDepth", Sdf.ValueTypeNames.String, "x"),
    ("/SDLScene/Lights/light_0", "sdl:color", Sdf.ValueTypeNames.Double, 0.5),
    ("/SDLScene/Lights/light_0", "inputs:intensity", Sdf.ValueTypeNames.String, "x"),
    ("/SDLScene/Camera", "sdl:eye", Sdf.ValueTypeNames.Double, 10.0),
    ("/SDLScene/Objects/union_0", "sdl:groups", Sdf.ValueTypeNames.Double, 1.0),
])
def test_values_of_the_wrong_type_are_one_line_errors(tmp_path, prim, name, type_name, value):
    path = tmp_path / "typed.usda"
    save_usd(tracer.parse_sdl("light 1 2 3  1 1 1  camera 0 0 10  0 0 0  0 1 0  30  union sphere cube  cone"),
             path)
    layer = Sdf.Layer.FindOrOpen(str(path))  # (Sdf, not Usd: Usd refuses a schema attribute's wrong type)
    spec = layer.GetPrimAtPath(prim)
    if name in spec.properties:
        spec.RemoveProperty(spec.properties[name])
    Sdf.AttributeSpec(spec, name, type_name).default = value
    layer.Save()
    with pytest.raises(TracerError, match=rf"typed\.usda: <{prim}>: cannot read") as caught:
        load_usd(path)
    assert "\n" not in str(caught.value)
    scene = load_usd(path, strict=False)  # lenient: that prim (or the settings) left out, the rest read
    assert len(scene.warnings) == 1 and prim in scene.warnings[0]
    assert [s.kind for s in scene.shapes()][-1] == "cone"


def test_a_material_without_a_universal_surface_gives_a_warning(tmp_path):
    """A MaterialX-only material (outputs:mtlx:surface) has no UsdPreviewSurface: display colour, warned."""
    stage = Usd.Stage.CreateInMemory()
    ball = UsdGeom.Sphere.Define(stage, "/Ball")
    ball.CreateDisplayColorAttr([(1.0, 0.0, 0.0)])
    material = UsdShade.Material.Define(stage, "/Looks/Red")
    shader = UsdShade.Shader.Define(stage, "/Looks/Red/Surface")
    shader.CreateIdAttr("ND_standard_surface_surfaceshader")
    shader.CreateInput("base_color", Sdf.ValueTypeNames.Color3f).Set(Gf.Vec3f(0.0, 1.0, 0.0))
    material.CreateSurfaceOutput("mtlx").ConnectToSource(shader.ConnectableAPI(), "out")
    UsdShade.MaterialBindingAPI.Apply(ball.GetPrim()).Bind(material)
    path = tmp_path / "mtlx.usda"
    stage.GetRootLayer().Export(str(path))
    scene = load_usd(path)
    assert scene.shapes()[0].material.diffuse == (1.0, 0.0, 0.0)
    assert len(scene.warnings) == 1 and "no universal surface" in scene.warnings[0]


# --- errors and the command line ----------------------------------------------------------------------------

def test_unreadable_usd_files_raise_tracer_errors(tmp_path):
    bad = tmp_path / "bad.usda"
    bad.write_text("#usda 1.0\ndef Xform \"a\" {\n  double x = \n")
    with pytest.raises(TracerError, match=r"bad\.usda:3:3: Expected } ") as caught:  # USD's own words: file:line:column
        load_usd(bad)
    assert "\n" not in str(caught.value) and "pxrInternal" not in str(caught.value)
    with pytest.raises(FileNotFoundError):
        load_usd(tmp_path / "missing.usda")
    with pytest.raises(TracerError, match="not a USD file name"):
        save_usd(Scene(), tmp_path / "scene.obj")


def test_missing_reference_is_an_error_unless_lenient(tmp_path, capfd):
    path = tmp_path / "ref.usda"
    path.write_text('#usda 1.0\ndef Xform "World" {\n  def "Part" (references = @./gone.usda@</P>) {}\n'
                    '  def Sphere "Ball" {\n    double radius = 2\n  }\n}\n')
    with pytest.raises(TracerError, match=r"ref\.usda: .*gone\.usda.*</World/Part>"):
        load_usd(path)
    scene = load_usd(path, strict=False)
    assert [s.kind for s in scene.shapes()] == ["sphere"] and np.array_equal(scene.shapes()[0].matrix,
                                                                             scaling(2, 2, 2))
    assert len(scene.warnings) == 1 and scene.warnings[0].endswith("</World/Part>: read without it")
    assert capfd.readouterr().err == ""  # USD's own multi-line warning is held back


@pytest.mark.parametrize("suffix", [".usda", ".usdc"])
def test_failed_write_leaves_nothing_behind(tmp_path, monkeypatch, suffix):
    target = tmp_path / f"scene{suffix}"
    target.write_text("old")
    monkeypatch.setattr(Sdf.Layer, "Export", lambda self, *a, **k: False, raising=False)

    def refuse(self):  # (text is written from the layer's string: usd-core raises its errors as exceptions)
        raise Tf.ErrorException("refused")

    monkeypatch.setattr(Sdf.Layer, "ExportToString", refuse, raising=False)
    with pytest.raises((TracerError, Tf.ErrorException)):
        save_usd(tracer.parse_sdl("sphere"), target)
    assert target.read_text() == "old"
    assert [p.name for p in tmp_path.iterdir()] == [target.name]


def run(*args, cwd=None):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "PYTHONWARNINGS": "ignore"}
    return subprocess.run([sys.executable, "-m", "tracer", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd or ROOT, env=env, timeout=300)


def test_cli_converts_both_ways_and_renders_usd(tmp_path):
    usd = tmp_path / "csg.usdc"
    proc = run("convert", ROOT / "scenes" / "csg.sdl", usd)
    assert proc.returncode == 0 and proc.stderr == "", proc.stderr
    proc = run("convert", usd, tmp_path / "csg.sdl")
    assert proc.returncode == 0, proc.stderr
    assert_same_scene(tracer.load(ROOT / "scenes" / "csg.sdl"), tracer.load(tmp_path / "csg.sdl"), tol=1e-9,
                      groups=False)
    for name in ("csg.usdc", "csg.sdl"):
        proc = run("render", tmp_path / name, "-o", tmp_path / f"{name}.png", "--width", 40, "--height", 30, "-q")
        assert proc.returncode == 0, proc.stderr
    from PIL import Image
    a, b = (np.asarray(Image.open(tmp_path / f"{n}.png"), dtype=int) for n in ("csg.usdc", "csg.sdl"))
    assert np.max(np.abs(a - b)) <= 1
    proc = run("info", usd, "--json")
    assert proc.returncode == 0 and '"boolean": "difference"' in proc.stdout
    assert sorted(p.name for p in tmp_path.iterdir()) == ["csg.sdl", "csg.sdl.png", "csg.usdc", "csg.usdc.png"]


def test_dot_usd_is_crate_whatever_usd_default_format_says(tmp_path):
    env = {**os.environ, "PYTHONPATH": str(ROOT), "USD_DEFAULT_FILE_FORMAT": "usda"}
    proc = subprocess.run([sys.executable, "-m", "tracer", "convert", ROOT / "scenes" / "csg.sdl",
                           tmp_path / "csg.usd"], capture_output=True, text=True, env=env, timeout=300)
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "csg.usd").read_bytes().startswith(b"PXR-USDC")  # as docs/usd.md promises


def test_cli_errors_are_one_line(tmp_path):
    (tmp_path / "bad.usda").write_text("not usd at all")
    cases = [("info", tmp_path / "bad.usda"), ("render", tmp_path / "missing.usd", "-o", tmp_path / "x.png"),
             ("convert", ROOT / "scenes" / "csg.sdl", tmp_path / "out.obj"),
             ("convert", ROOT / "scenes" / "csg.sdl", tmp_path / "no" / "such" / "folder.usda")]
    for args in cases:
        proc = run(*args)
        assert proc.returncode == 2, (args, proc.stderr)
        lines = proc.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("error: "), proc.stderr
    assert "bad.usda" in run(*cases[0]).stderr
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.usda"]


def test_one_group_name_written_as_a_string_is_one_name(tmp_path):
    """Another tool may write sdl:groups as a plain string: that is one def name, not one per letter."""
    path = tmp_path / "groups.usda"
    save_usd(tracer.parse_sdl("def leg { sphere }  use leg"), path)
    layer = Sdf.Layer.FindOrOpen(str(path))
    stage = Usd.Stage.Open(layer)
    sphere = [p for p in stage.Traverse() if p.HasAttribute("sdl:shape")][0]
    spec = layer.GetPrimAtPath(sphere.GetPath())
    if "sdl:groups" in spec.properties:
        spec.RemoveProperty(spec.properties["sdl:groups"])
    Sdf.AttributeSpec(spec, "sdl:groups", Sdf.ValueTypeNames.String).default = "table_leg"
    layer.Save()
    assert load_usd(path).shapes()[0].groups == ("table_leg",)


def test_our_file_referenced_into_another_stage_keeps_its_settings(written, tmp_path):
    """A layout stage that references our glass scene under /World/Glass: the settings prim moved there."""
    scene = tracer.load(ROOT / "scenes" / "glass.sdl")
    stage = Usd.Stage.CreateNew(str(tmp_path / "layout.usda"))
    UsdGeom.Xform.Define(stage, "/World")
    stage.DefinePrim("/World/Glass").GetReferences().AddReference(str(written["glass"]), "/SDLScene")
    stage.GetRootLayer().Save()
    back = load_usd(tmp_path / "layout.usda")
    assert back.settings.background == scene.settings.background
    assert back.settings.max_recursion_depth == scene.settings.max_recursion_depth
    assert back.settings.min_transparency == scene.settings.min_transparency
    assert len(back.shapes()) == len(scene.shapes())


# --- reliability: every bad stage is one error naming the file; writing and reading agree --------------------

def _lecture_stage(tmp_path) -> Path:
    path = tmp_path / "lecture.usda"
    save_usd(tracer.load(ROOT / "scenes" / "lecture.sdl"), path)
    return path


def test_a_byte_that_is_not_utf8_is_named_with_its_place(tmp_path):
    text = _lecture_stage(tmp_path).read_bytes()
    at = text.index(b"def Xform")
    bad = tmp_path / "latin1.usda"
    bad.write_bytes(text[:at] + b"# caf\xe9\n" + text[at:])
    line = text[:at].count(b"\n") + 1
    with pytest.raises(TracerError, match=rf"latin1\.usda:{line}:6: byte 0xe9 is not UTF-8 text"):
        load_usd(bad)


@pytest.mark.parametrize("authored", ["custom double sdl:maxRecursionDepth = inf", "custom double sdl:texture = inf",
                                      "custom double sdl:texture = 1.5"])
def test_a_number_that_is_no_whole_number_where_one_belongs_is_an_error_naming_the_file(tmp_path, authored):
    name = authored.split()[2]
    text = _lecture_stage(tmp_path).read_text()
    original = "custom int sdl:maxRecursionDepth = 3" if "Depth" in name else "custom int sdl:texture = 0"
    bad = tmp_path / "inf.usda"
    bad.write_text(text.replace(original, authored, 1))
    with pytest.raises(TracerError, match=rf"inf\.usda: <.*>: .*{name} = .* is not a whole number"):
        load_usd(bad)
    scene = load_usd(bad, strict=False)  # lenient: the defaults, or the prim left out, with a warning
    assert any(name in w for w in scene.warnings)


def test_an_inherit_cycle_is_named_without_usd_s_anonymous_layers(tmp_path):
    path = tmp_path / "cycle.usda"
    path.write_text('#usda 1.0\n(\n    defaultPrim = "A"\n)\ndef Xform "A" (\n    inherits = </B>\n)\n{\n}\n'
                    'def Xform "B" (\n    inherits = </A>\n)\n{\n}\n')
    with pytest.raises(TracerError) as raised:
        load_usd(path)
    message = str(raised.value)
    assert message.startswith(f"{path}: ") and "Cycle" in message and "anon:" not in message, message


def test_booleans_nested_too_deep_in_a_stage_are_an_error_naming_the_file(tmp_path):
    depth = 2001
    text = "light 1 2 3 1 1 1\n" + "union " * depth + "sphere " * (depth + 1) + "\n"
    stage = tmp_path / "deep.usda"
    save_usd(tracer.parse_sdl(text), stage)
    with pytest.raises(TracerError, match=r"deep\.usda<.*>: union: booleans nested 2001 deep"):
        tracer.render(load_usd(stage), 8, 6)


def test_deep_booleans_are_written_flat_and_read_back_as_they_were(tmp_path):
    """A tree nested deeper than the writer's CHAIN_DEPTH is written as a chain (USD's costs grow with a
    prim's depth): every boolean, side, operation and def group comes back."""
    from tracer.usd.writer import CHAIN_DEPTH

    rng = np.random.default_rng(5)
    text = "sphere"
    for level in range(300):  # a spine of mixed booleans, its other operands on either side
        op = ("union", "intersection", "difference")[rng.integers(3)]
        other = ("cube", "translate 1 0 0 sphere", "union cube sphere")[rng.integers(3)]
        text = f"{op} {text} {other}" if rng.random() < 0.5 else f"{op} {other} {text}"
    scene = tracer.parse_sdl(f"light 1 2 3 1 1 1\ndef spine {{ {text} }}\nuse spine\n{text}\n")
    for suffix in (".usda", ".usdc"):
        path = tmp_path / f"chain{suffix}"
        save_usd(scene, path)
        assert_same_scene(scene, load_usd(path))
        stage = Usd.Stage.Open(str(path))
        assert max(prim.GetPath().pathElementCount for prim in stage.Traverse()) <= CHAIN_DEPTH + 4


def test_a_stage_may_hold_more_prims_than_composition_may_add(tmp_path):
    """Reading bounds what references add (MAX_USD_PRIMS beyond the prims the layers define), not what a
    file holds: a stage the writer made of more prims than that reads back."""
    from tracer.usd.budget import check_prim_budget

    scene = tracer.parse_sdl("".join(f"push translate {k} 0 0 sphere pop\n" for k in range(300)))
    path = tmp_path / "many.usda"
    save_usd(scene, path)
    check_prim_budget(str(path), budget=100)  # 300 spheres (and their materials) defined: fine
    parts = tmp_path / "parts.usda"
    parts.write_text('#usda 1.0\n(\n    defaultPrim = "P"\n)\ndef Xform "P"\n{\n'
                     + "".join(f'    def Sphere "s{k}"\n    {{\n    }}\n' for k in range(20)) + "}\n")
    many = tmp_path / "refs.usda"
    many.write_text("#usda 1.0\n" + "".join(f'def Xform "r{k}" (\n    references = @./parts.usda@\n)\n{{\n}}\n'
                                            for k in range(10)))
    with pytest.raises(TracerError, match=r"refs\.usda: the stage composes to more than 100 prims beyond"):
        check_prim_budget(str(many), budget=100)  # 10 x 21 prims from 21 defined
    check_prim_budget(str(many), budget=200)
