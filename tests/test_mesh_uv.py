"""Mesh texture coordinates (MeshData.corner_uvs; docs/tracer.md, "Mesh texture coordinates"): an image
texture on a mesh that has them is looked up at the (u, v) interpolated with the hit's barycentrics, on both
backends, C = NumPy; quads are fanned like their vertices; the material's repeats apply; a mesh without them
keeps the globe mapping."""
from __future__ import annotations

import numpy as np
import pytest
from PIL import Image

import tracer
from tracer.backend import make_tracer
from tracer.compile import compile_scene
from tracer.errors import SceneError, TracerError
from tracer.model import Camera, Material, MeshData, Scene, Settings, Shape

SIZE = 4  # the picture: 4 x 4 texels of distinct colours
TEXELS = (np.arange(SIZE * SIZE * 3, dtype=np.uint8).reshape(SIZE, SIZE, 3) * 5 + 10)  # row 0 at the top


@pytest.fixture
def picture(tmp_path):
    path = tmp_path / "texels.png"
    Image.fromarray(TEXELS).save(path)
    return str(path)


def texel(i: int, j: int) -> np.ndarray:
    """The colour of texel column i, row j counted from the bottom (v = 0 is the picture's bottom row)."""
    return TEXELS[SIZE - 1 - j, i] / 255.0


def quad(corner_uvs) -> MeshData:
    """The square [-1, 1]^2 at z = 0 facing +z, as one quad (fanned into two triangles)."""
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    return MeshData(vertices, np.array([[0.0, 0.0, 1.0]]), [((0, 1, 2, 3), (0, 0, 0, 0))], "quad",
                    corner_uvs=None if corner_uvs is None else np.asarray(corner_uvs, dtype=float))


#: A map turned a quarter: corner (x, y) gets u = (y + 1) / 2, v = (1 - x) / 2.
TURNED = [(0.0, 1.0), (0.0, 0.0), (1.0, 0.0), (1.0, 1.0)]


def scene_with(mesh: MeshData, picture: str, parameters=()) -> Scene:
    material = Material(ambient=(1.0, 1.0, 1.0), diffuse=(0.0, 0.0, 0.0), texture=1, parameters=parameters)
    return Scene(objects=[Shape("mesh", np.eye(4), material, mesh=mesh, mesh_file="quad.3vn")],
                 camera=Camera((0, 0, 5), (0, 0, 0), (0, 1, 0), 40), pixmaps={1: picture},
                 settings=Settings(global_ambient=(1.0, 1.0, 1.0), background=(0.0, 0.0, 0.0)))


def shade_at(backend, scene, points):
    """Colours of rays straight down -z onto the points (x, y)."""
    xy = np.asarray(points, dtype=float)
    origins = np.c_[xy, np.full(len(xy), 3.0)]
    directions = np.tile([0.0, 0.0, -1.0], (len(xy), 1))
    return make_tracer(compile_scene(scene), backend, threads=1).camera_rays(origins, directions)


def test_texel_centres_come_from_the_interpolated_coordinates(backend, picture):
    scene = scene_with(quad(TURNED), picture)
    centres = [(i, j) for i in range(SIZE) for j in range(SIZE)]
    # texel (i, j)'s centre is at u = (i + 1/2) / 4, v = (j + 1/2) / 4: x = 1 - 2 v, y = 2 u - 1
    points = [(1 - 2 * (j + 0.5) / SIZE, 2 * (i + 0.5) / SIZE - 1) for i, j in centres]
    colours = shade_at(backend, scene, points)
    np.testing.assert_allclose(colours, [texel(i, j) for i, j in centres], rtol=1e-12)
    assert "mesh-uv" in compile_scene(scene).effects


def test_between_centres_the_picture_is_bilinear_and_repeats(backend, picture):
    """At u = 1/4 (between texel columns 0 and 1) the colour is their mean; the material's repeats apply,
    wrapping past the edge."""
    scene = scene_with(quad(TURNED), picture)
    # u = 1/4 is y = -1/2; v = 1/8 (row 0's centre) is x = 3/4
    mean = shade_at(backend, scene, [(0.75, -0.5)])[0]
    np.testing.assert_allclose(mean, (texel(0, 0) + texel(1, 0)) / 2, rtol=1e-12)
    repeated = scene_with(quad(TURNED), picture, parameters=(2.0, 2.0))
    # u = 11/16 twice over is 11/8, past the edge: texel column 1's centre 3/8; v = 5/16 twice is row 2's 5/8
    colour = shade_at(backend, repeated, [(1 - 2 * 5 / 16, 2 * 11 / 16 - 1)])[0]
    np.testing.assert_allclose(colour, texel(1, 2), rtol=1e-12)


def test_c_and_numpy_agree(picture):
    from tracer import native
    if native.load_error is not None:
        pytest.skip(f"C core not available: {native.load_error}")
    rng = np.random.default_rng(3)
    scene = scene_with(quad(rng.uniform(-2, 3, (4, 2))), picture)
    scene.objects[0].matrix = np.array([[1.2, 0.3, 0, 0], [-0.2, 0.9, 0.4, 0], [0, 0.1, 1, 0], [0, 0, 0, 1]])
    c = tracer.render(scene, 64, 48, backend="c")
    n = tracer.render(scene, 64, 48, backend="numpy")
    assert np.array_equal(c.image, n.image)
    assert c.image.std() > 0.05  # the picture is there


def test_a_mesh_without_coordinates_keeps_the_globe_mapping(backend, picture):
    with_uv = shade_at(backend, scene_with(quad(TURNED), picture), [(0.3, 0.6)])
    without = shade_at(backend, scene_with(quad(None), picture), [(0.3, 0.6)])
    assert not np.allclose(with_uv, without)
    assert "mesh-uv" not in compile_scene(scene_with(quad(None), picture)).effects


def test_coordinates_of_the_wrong_shape_are_refused(picture):
    with pytest.raises(SceneError, match="corner_uvs"):
        compile_scene(scene_with(quad(TURNED[:3]), picture))
    with pytest.raises(SceneError, match="not finite"):
        compile_scene(scene_with(quad([(0, 0), (1, 0), (1, np.nan), (0, 1)]), picture))


def test_coordinates_change_the_meshs_identity():
    from tracer.compile import mesh_digest
    assert mesh_digest(quad(TURNED)) != mesh_digest(quad(None))
    assert mesh_digest(quad(TURNED)) != mesh_digest(quad(TURNED[1:] + TURNED[:1]))
    a = Shape("mesh", np.eye(4), Material(), mesh=quad(TURNED))
    b = Shape("mesh", np.eye(4), Material(), mesh=quad(TURNED[1:] + TURNED[:1]))
    assert a != b


def test_usd_keeps_the_coordinates_exactly_and_shows_them_as_st(tmp_path, picture):
    from pxr import Usd, UsdGeom
    from tracer.usd import load_usd, save_usd
    uvs = np.array([(0.1, 0.7), (0.0, 1e-9), (1.0 / 3.0, 0.0), (1.0, 1.0)])
    scene = scene_with(quad(uvs), picture)
    save_usd(scene, tmp_path / "quad.usda")
    again = load_usd(tmp_path / "quad.usda")
    assert np.array_equal(again.shapes()[0].mesh.corner_uvs, uvs)
    stage = Usd.Stage.Open(str(tmp_path / "quad.usda"))
    prim = next(p for p in stage.Traverse() if p.IsA(UsdGeom.Mesh))
    st = UsdGeom.PrimvarsAPI(prim).GetPrimvar("st")
    assert st.GetInterpolation() == UsdGeom.Tokens.faceVarying
    np.testing.assert_allclose(np.array(st.Get()), uvs, rtol=1e-7)


def test_usd_meshes_of_other_tools_bring_their_uv_map(tmp_path):
    """An indexed faceVarying map named as Blender names it, on a left-handed quad (whose corners turn)."""
    from pxr import Sdf, Usd, UsdGeom, Vt
    from tracer.usd import load_usd
    stage = Usd.Stage.CreateNew(str(tmp_path / "foreign.usda"))
    mesh = UsdGeom.Mesh.Define(stage, "/World/Plane")
    mesh.CreatePointsAttr([(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)])
    mesh.CreateFaceVertexCountsAttr([4])
    mesh.CreateFaceVertexIndicesAttr([0, 1, 2, 3])
    mesh.CreateOrientationAttr(UsdGeom.Tokens.leftHanded)
    uv_map = UsdGeom.PrimvarsAPI(mesh).CreatePrimvar("UVMap", Sdf.ValueTypeNames.TexCoord2fArray,
                                                     UsdGeom.Tokens.faceVarying)
    uv_map.Set(Vt.Vec2fArray([(0, 0), (1, 0), (1, 1), (0, 1)]))
    uv_map.SetIndices(Vt.IntArray([0, 1, 2, 3]))
    stage.Save()
    read = load_usd(tmp_path / "foreign.usda").shapes()[0].mesh
    assert read.faces[0][0] == (3, 2, 1, 0)
    np.testing.assert_array_equal(read.corner_uvs, [(0, 1), (1, 1), (1, 0), (0, 0)])
