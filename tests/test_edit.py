"""Editing a compiled scene in place (tracer.edit.EditableScene) gives what compiling the edited scene from
scratch gives: the same primitive and object rows, the same image byte for byte and the same ray counts on
each backend, the same first hits — after every kind of edit, on every kind of object (plain shapes, a
boolean, textured shapes, instances of one mesh, an unbounded plane), and after random sequences of edits.
"""
from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from helpers import Camera, Light, rotation, scaling, shape, translation
from tracer.compile import compile_scene
from tracer.edit import EditableScene
from tracer.errors import TracerError
from tracer.meshio import read_3vn
from tracer.model import CSG, Material, MeshData, Scene, Settings, Shape, ShapeTable
from tracer.render import render
from tracer.trace import first_hits

ROOT = Path(__file__).resolve().parent.parent
PAWN = ROOT / "scenes" / "meshes" / "pawn.3vn"
WIDTH, HEIGHT = 24, 18

# ------------------------------------------------------------------------------------------------ the scene


def _octahedron() -> MeshData:
    vertices = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], dtype=float)
    faces = [(0, 2, 4), (2, 1, 4), (1, 3, 4), (3, 0, 4), (2, 0, 5), (1, 2, 5), (3, 1, 5), (0, 3, 5)]
    return MeshData(vertices=vertices, normals=vertices.copy(), faces=[(f, f) for f in faces])


def _pawn() -> MeshData:
    return read_3vn(PAWN)


GLASS = Material(ambient=(0, 0, 0), diffuse=(0.1, 0.1, 0.1), specular=(0.5, 0.5, 0.5), transparency=0.8,
                 speed_of_light=0.7, specular_exponent=40)
MIRROR = Material(diffuse=(0.2, 0.2, 0.2), reflectivity=0.6)
MARBLE = Material(ambient=(0.3, 0.3, 0.3), diffuse=(0.8, 0.8, 0.8), texture=-3, parameters=(0,))
CHECKER = Material(ambient=(1, 1, 1), diffuse=(0.8, 0.8, 0.8), texture=-1, parameters=(4, 1, 0.9, 0.9, 0.9, 0.2, 0.2, 0.25))
RED = Material(diffuse=(0.9, 0.1, 0.1), specular=(0.3, 0.3, 0.3), specular_exponent=20)
DARK = Material(ambient=(0.2, 0.2, 0.2), diffuse=(0, 0, 0), specular=(0, 0, 0))


def mixed_scene() -> tuple[Scene, list]:
    """A scene with one object of every kind an edit must survive, and its keys."""
    octahedron = _octahedron()
    objects = [
        Shape("plane", translation(0, -1, 0) @ rotation(-90, 1, 0, 0), CHECKER),  # unbounded
        Shape("sphere", translation(-1.5, 0, 0), RED),
        Shape("sphere", translation(1.2, 0.2, 0.5) @ scaling(0.7, 0.7, 0.7), GLASS),
        CSG("difference", Shape("cube", translation(0, 0, -2), MIRROR),
            Shape("sphere", translation(0.5, 0.5, -1.5) @ scaling(0.9, 0.9, 0.9), RED)),
        Shape("cylinder", translation(2.5, -1, -1) @ rotation(-90, 1, 0, 0), MARBLE),
        Shape("mesh", translation(-2.5, 0, -1) @ scaling(0.5, 0.5, 0.5), RED, mesh=octahedron),
        Shape("mesh", translation(-0.5, 1.3, -0.5) @ scaling(0.4, 0.4, 0.4), MIRROR, mesh=octahedron),
        Shape("mesh", translation(0.8, -0.6, 1.5) @ scaling(0.3, 0.3, 0.3), DARK, mesh=octahedron),
        Shape("torus", translation(-1, -0.6, 1.2) @ scaling(0.5, 0.5, 0.5), RED),
    ]
    keys = ["plane", "red", "glass", "csg", "marble", "oct1", "oct2", "oct3", "torus"]
    scene = Scene(objects=objects, lights=[Light((4, 5, 6), (1, 1, 1)), Light((-5, 3, 2), (0.5, 0.5, 0.6))],
                  camera=Camera(eye=(0, 2, 8), look=(0, 0, 0), view_angle=50),
                  settings=Settings(max_recursion_depth=3, background=(0.1, 0.1, 0.3)))
    return scene, keys


# ------------------------------------------------------------------------------------------------ checks


def from_scratch(editable: EditableScene) -> Scene:
    """The edited scene as a new Scene object (compile_scene compiles it anew)."""
    return dataclasses.replace(editable.scene, objects=list(editable.scene.objects),
                               lights=list(editable.scene.lights))


def _grid_rays(n: int = 9):
    xs = np.linspace(-3.5, 3.5, n)
    origins = np.array([[x, y, 8.0] for x in xs for y in xs])
    directions = np.array([[0.05 * x, -0.2 - 0.02 * y, -1.0] for x in xs for y in xs])
    return origins, directions


def assert_same_rows(edited, fresh) -> None:
    """The edited compiled scene's primitive rows are the fresh compile's, number for number."""
    a, b = edited.table, fresh.table
    for name in ("kind", "parameters", "inverses", "inverse_error", "inverse_norms", "generic_size", "spheres", "boxes"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    ma, mb = edited.materials, fresh.materials
    for name in ("ambient", "diffuse", "specular", "reflectivity", "transparency", "texture"):
        assert np.array_equal(getattr(ma, name)[a.material_ids], getattr(mb, name)[b.material_ids]), name
    assert edited.effects == fresh.effects
    assert np.array_equal(edited.objects.primitive_index, fresh.objects.primitive_index)
    assert np.array_equal(edited.light_positions, fresh.light_positions)


def assert_renders_alike(editable: EditableScene, backend: str) -> None:
    fresh = compile_scene(from_scratch(editable))
    assert_same_rows(editable.compiled, fresh)
    size = (WIDTH, HEIGHT) if backend == "c" else (WIDTH // 2, HEIGHT // 2)
    got = render(editable.compiled, *size, backend=backend, threads=2)
    want = render(fresh, *size, backend=backend, threads=2)
    assert got.backend == want.backend == backend
    assert np.array_equal(got.image, want.image)
    assert got.rays == want.rays
    origins, directions = _grid_rays()
    if backend == "numpy":
        h0, h1 = first_hits(editable.compiled, origins, directions), first_hits(fresh, origins, directions)
        pairs = [(h0.t, h1.t), (h0.normal, h1.normal), (h0.shape, h1.shape), (h0.obj, h1.obj)]
    else:
        from tracer.native.tracer import NativeTracer
        h0 = NativeTracer(editable.compiled, threads=2).first_hits(origins, directions)
        h1 = NativeTracer(fresh, threads=2).first_hits(origins, directions)
        pairs = [(h0[k], h1[k]) for k in ("t", "normal", "shape", "obj", "entering")]
    for x, y in pairs:
        assert np.array_equal(x, y)


# ------------------------------------------------------------------------------------------------ edits


def _moved(key):
    return {"plane": translation(0, -1.2, 0) @ rotation(-80, 1, 0, 0),
            "csg": translation(0.3, 0.2, 0.1)}.get(key, translation(0.4, -0.3, 0.6) @ rotation(25, 0, 1, 0)
                                                    @ scaling(0.8, 1.1, 0.9))


EDITS = {
    "move": lambda e, key: e.set_transform(key, _moved(key) @ _first_matrix(e, key)),
    "material": lambda e, key: e.set_material(key, Material(diffuse=(0.2, 0.7, 0.3), reflectivity=0.3)),
    "glass": lambda e, key: e.set_material(key, GLASS),
    "texture": lambda e, key: e.set_material(key, CHECKER),
    "dark": lambda e, key: e.set_material(key, DARK),
    "remesh": lambda e, key: e.replace_mesh(key, _pawn()),
    "remove": lambda e, key: e.remove_objects(key),
    "replace": lambda e, key: e.replace_objects(key, [Shape("cube", translation(0, 2, -1) @ scaling(0.5, 0.5, 0.5), RED),
                                                     Shape("sphere", translation(1, 2, -1) @ scaling(0.3, 0.3, 0.3), MIRROR)]),
}


def _first_matrix(e: EditableScene, key) -> np.ndarray:
    obj = e.objects_of(key)[0]
    while isinstance(obj, CSG):
        obj = obj.left
    return obj.matrix


KEYS = mixed_scene()[1]


@pytest.mark.parametrize("edit", sorted(EDITS))
@pytest.mark.parametrize("key", KEYS)
def test_every_edit_of_every_kind_of_object_renders_as_from_scratch(edit, key, backend):
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    render(editable.compiled, 8, 6, backend=backend)  # (traced once before the edit, as a viewport would)
    EDITS[edit](editable, key)
    assert_renders_alike(editable, backend)


def test_adding_objects_renders_as_from_scratch(backend):
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    render(editable.compiled, 8, 6, backend=backend)
    octahedron = editable.objects_of("oct1")[0].mesh  # (another instance of a mesh in use)
    editable.add_objects("new", [Shape("mesh", translation(0, 1.5, 1), GLASS, mesh=octahedron),
                                 CSG("union", Shape("sphere", translation(-2, 1.5, 0) @ scaling(0.4, 0.4, 0.4), MARBLE),
                                     Shape("cube", translation(-2, 2, 0) @ scaling(0.3, 0.3, 0.3), RED))])
    editable.add_objects("plane2", [Shape("plane", translation(0, 0, -4), MIRROR)])
    assert_renders_alike(editable, backend)


def test_moving_lights_renders_as_from_scratch(backend):
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    render(editable.compiled, 8, 6, backend=backend)
    editable.set_lights([Light((1.2, 0.2, 0.5), (1, 1, 1))])  # inside the glass sphere: no longer sealed
    assert_renders_alike(editable, backend)
    editable.set_lights([])
    assert_renders_alike(editable, backend)


def test_a_shared_material_edited_changes_every_shape_that_uses_it(backend):
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    render(editable.compiled, 8, 6, backend=backend)
    editable.replace_material(RED, dataclasses.replace(RED, diffuse=(0.1, 0.1, 0.9), reflectivity=0.7))
    assert all(s.material is not RED for obj in editable.scene.objects
               for s in ([obj.left, obj.right] if isinstance(obj, CSG) else [obj]))
    assert_renders_alike(editable, backend)


def test_keys_survive_removals():
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    glass = editable.objects_of("glass")
    editable.remove_objects("red")
    assert "red" not in editable and editable.objects_of("glass") == glass
    assert editable.positions_of("glass") == [1]
    assert editable.keys() == [k for k in keys if k != "red"]
    with pytest.raises(TracerError, match="'red'"):
        editable.set_transform("red", np.eye(4))


@pytest.mark.parametrize("matrix, problem", [(np.zeros((4, 4)), "not a finite affine"),
                                             (np.diag([1.0, 0.0, 1.0, 1.0]), "singular"),
                                             (np.full((4, 4), np.nan), "not a finite affine"),
                                             (np.eye(3), "not a finite affine")])
def test_a_bad_matrix_is_refused_naming_the_object_and_changes_nothing(matrix, problem):
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    before = [o.matrix.copy() for o in editable.scene.objects if isinstance(o, Shape)]
    with pytest.raises(TracerError, match=f"'glass'.*{problem}"):
        editable.set_transform("glass", matrix)
    assert all(np.array_equal(a, o.matrix) for a, o in
               zip(before, [o for o in editable.scene.objects if isinstance(o, Shape)]))


def test_parts_of_one_key_are_edited_together(backend):
    octahedron = _octahedron()
    parts = [Shape("mesh", translation(0, 0, 0), RED, mesh=octahedron),
             Shape("mesh", translation(0, 0, 0) @ scaling(0.5, 2, 0.5), MIRROR, mesh=_pawn())]
    scene = Scene(objects=parts + [Shape("sphere", translation(2, 0, 0), GLASS)],
                  lights=[Light((4, 5, 6), (1, 1, 1))], camera=Camera(eye=(0, 2, 8), look=(0, 0, 0)))
    editable = EditableScene(scene, ["blender object", "blender object", "ball"])
    editable.set_transform("blender object", translation(-1, 0.5, 0))
    assert [o.matrix.tolist() for o in editable.objects_of("blender object")] == [translation(-1, 0.5, 0).tolist()] * 2
    assert_renders_alike(editable, backend)


# ------------------------------------------------------------------------------------------------ sequences

_EDIT_NAMES = sorted(set(EDITS) - {"remove"})


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.lists(st.tuples(st.sampled_from(_EDIT_NAMES + ["remove", "add", "lights", "frame", "shared", "batch"]),
                          st.sampled_from(KEYS)), min_size=1, max_size=8))
def test_random_edit_sequences_render_as_from_scratch(steps):
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    render(editable.compiled, 8, 6, backend="c")
    for number, (edit, key) in enumerate(steps):
        if edit == "add":
            editable.add_objects(f"added {number}", [Shape("sphere", translation(number * 0.3 - 1, 1.6, 0), RED)])
        elif edit == "lights":
            editable.set_lights([Light((number - 2.0, 4, 5), (1, 1, 1))])
        elif edit == "frame":  # (every object moved at once)
            editable.set_transforms((k, translation(0.05, 0.02 * number, 0) @ _first_matrix(editable, k))
                                    for k in editable.keys())
        elif edit == "shared":  # (one shared material edited, wherever it is now)
            old = next((s.material for obj in editable.scene.objects
                        for s in ([obj.left, obj.right] if isinstance(obj, CSG) else [obj])), None)
            if old is not None:
                editable.replace_material(old, dataclasses.replace(old, diffuse=(0.1 * (number % 10), 0.5, 0.5)))
        elif edit == "batch":
            with editable.batch():
                for k in editable.keys()[:3]:
                    EDITS["move"](editable, k)
        elif key in editable:
            EDITS[edit](editable, key)
        if number % 3 == 2:  # (and along the way, on the C core)
            assert_renders_alike(editable, "c")
    assert_renders_alike(editable, "c")
    assert_renders_alike(editable, "numpy")


# ------------------------------------------------------------------------------------------------ in place


def many_spheres(n: int = 400, seed: int = 1) -> Scene:
    rng = np.random.default_rng(seed)
    objects = [Shape("sphere", translation(*rng.uniform(-4, 4, 3)) @ scaling(*rng.uniform(0.05, 0.3, 3)),
                     Material(diffuse=tuple(rng.uniform(0, 1, 3)), reflectivity=0.6 if k % 7 == 0 else 0.0))
               for k in range(n)]
    objects.append(Shape("plane", translation(0, -4.5, 0) @ rotation(-90, 1, 0, 0), CHECKER))
    return Scene(objects=objects, lights=[Light((4, 5, 6), (1, 1, 1))],
                 camera=Camera(eye=(0, 2, 12), look=(0, 0, 0), view_angle=45))


def _pair_boxes(tracer) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The C core's object hierarchy: per pair, its children's boxes (lo, hi: (P, 2, 3)), children and counts."""
    raw, items, root = tracer.object_tree()
    record = np.dtype([("b", "<f4", (3, 2, 2)), ("child", "<i4", 2), ("count", "<i4", 2)])
    pairs = np.frombuffer(raw, dtype=record)
    boxes = pairs["b"].transpose(0, 3, 2, 1)  # [pair, child, lo/hi, axis]
    return boxes, pairs["child"], pairs["count"], items


def assert_hierarchy_holds_every_object(editable: EditableScene) -> None:
    """Every pair's child box holds the boxes of the objects below it (what a refit must keep true)."""
    from tracer.native.tracer import NativeTracer
    tracer = NativeTracer(editable.compiled, threads=1)
    boxes, child, count, items = _pair_boxes(tracer)
    flat = editable.compiled._flat_cache[1]
    object_box = flat.arrays["object_box"].reshape(-1, 6)

    def objects_below(p: int, c: int) -> list[int]:
        if count[p, c] < 0:  # (a leaf whose objects were all removed)
            return []
        if count[p, c]:
            return items[child[p, c]:child[p, c] + count[p, c]].tolist()
        return objects_below(child[p, c], 0) + objects_below(child[p, c], 1)

    for p in range(len(boxes)):
        for c in range(2):
            below = object_box[objects_below(p, c)]
            assert (boxes[p, c, 0] <= below[:, :3]).all() and (boxes[p, c, 1] >= below[:, 3:]).all()


def test_moving_a_few_of_many_objects_refits_the_hierarchy_in_place(backend):
    editable = EditableScene(many_spheres())
    compiled = editable.compiled
    render(compiled, 8, 6, backend="c")  # (the C core's scene made: edits now reach it)
    core = compiled._flat_cache[1].core
    for k in (3, 50, 51, 399):
        editable.set_transform(k, translation(3 - k / 100, 1.5, 2) @ scaling(0.4, 0.4, 0.4))
    with editable.batch():  # (one refit for all of them)
        for k in range(100, 110):
            editable.set_transform(k, translation(-3, -1 + k / 50, 1) @ scaling(0.2, 0.3, 0.2))
    assert editable.compiled is compiled and compiled._flat_cache[1].core is core
    assert editable.done["refit"] == 5 and editable.done["rebuild"] == editable.done["flat"] == 0
    assert_hierarchy_holds_every_object(editable)
    assert_renders_alike(editable, backend)


def test_moving_most_objects_rebuilds_the_hierarchy():
    editable = EditableScene(many_spheres(60))
    render(editable.compiled, 8, 6, backend="c")
    with editable.batch():
        for k in range(45):
            editable.set_transform(k, translation(k / 10 - 2, 0, 0) @ scaling(0.1, 0.1, 0.1))
    assert editable.done["rebuild"] == 1 and editable.done["refit"] == 0
    assert_hierarchy_holds_every_object(editable)
    assert_renders_alike(editable, "c")


def test_edits_change_the_rows_they_concern_and_no_other():
    editable = EditableScene(many_spheres(50))
    render(editable.compiled, 8, 6, backend="c")
    flat = editable.compiled._flat_cache[1]
    before = {name: array.copy() for name, array in flat.arrays.items()}
    editable.set_transform(7, translation(1, 1, 1))
    changed = {name for name, array in flat.arrays.items()
               if array.shape != before[name].shape or not np.array_equal(array, before[name])}
    assert changed == {"prim_inverse", "prim_sphere", "prim_rounding", "object_box"}
    for name in changed:
        width = {"prim_inverse": 16, "prim_sphere": 4, "prim_rounding": 4, "object_box": 6}[name]
        rows = np.flatnonzero((flat.arrays[name].reshape(-1, width) != before[name].reshape(-1, width)).any(axis=1))
        assert rows.tolist() == [7], name


# ------------------------------------------------------------------------------------------------ live effects

BRICKS = ROOT / "scenes" / "images" / "bricks.png"
PLAIN = Material(ambient=(0.2, 0.2, 0.2), diffuse=(0, 0, 0), specular=(0, 0, 0))


def plain_scene() -> Scene:
    """Shapes that call for no effect but their kinds: unlit (no light), nothing reflects or is textured."""
    scene = Scene(objects=[Shape("sphere", translation(-1, 0, 0), PLAIN), Shape("cube", translation(1.5, 0, 0), PLAIN),
                           Shape("plane", translation(0, -1, 0) @ rotation(-90, 1, 0, 0), PLAIN)],
                  camera=Camera(eye=(0, 2, 8), look=(0, 0, 0)), settings=Settings(max_recursion_depth=3))
    scene.pixmaps = {1: str(BRICKS)}
    return scene


EFFECT_STEPS = [  # (what the edit does, the effect it switches on)
    (lambda e: e.set_lights([Light((3, 4, 5), (1, 1, 1))]), None),  # (a light, but nothing lit yet)
    (lambda e: e.set_material(0, RED), "lighting"),
    (lambda e: e.set_material(1, MIRROR), "reflection"),
    (lambda e: e.set_material(2, GLASS), "refraction"),
    (lambda e: e.set_material(0, Material(diffuse=(1, 1, 1), texture=1, parameters=(2, 2))), "textures"),
    (lambda e: e.set_material(1, Material(specular=(0.9, 0.9, 0.9), specular_fraction=0.6, surface_roughness=0.3)),
     "cook-torrance"),
    (lambda e: e.set_material(2, dataclasses.replace(GLASS, fresnel="dielectric")), "fresnel"),
    (lambda e: e.set_lights([Light((3, 4, 5), (1, 1, 1), kind="sphere", radius=0.5, samples=4)]), "soft-shadows"),
]


def test_effects_switch_on_and_off_as_edits_call_for_them(backend):
    editable = EditableScene(plain_scene())
    render(editable.compiled, 8, 6, backend=backend)
    assert editable.compiled.effects == {"shape:sphere", "shape:cube", "shape:plane"}
    for step, effect in EFFECT_STEPS:
        step(editable)
        if effect is not None:
            assert effect in editable.compiled.effects
        assert_renders_alike(editable, backend)
    for key in (0, 1, 2):  # and off again, one by one
        editable.set_material(key, PLAIN)
        assert_renders_alike(editable, backend)
    editable.set_lights([])
    assert editable.compiled.effects == {"shape:sphere", "shape:cube", "shape:plane"}
    assert_renders_alike(editable, backend)


def test_a_picture_is_loaded_once_when_a_material_first_asks_for_it(monkeypatch):
    from tracer import edit
    loaded = []
    real = edit.load_image
    monkeypatch.setattr(edit, "load_image", lambda path: loaded.append(path) or real(path))
    editable = EditableScene(plain_scene())
    render(editable.compiled, 8, 6, backend="c")
    bricks = Material(diffuse=(1, 1, 1), texture=1)
    editable.set_material(0, bricks)
    editable.set_material(1, dataclasses.replace(bricks, parameters=(3, 1)))
    editable.set_material(0, PLAIN)
    editable.set_material(0, bricks)
    assert loaded == [str(BRICKS)]
    assert_renders_alike(editable, "c")


@pytest.mark.parametrize("material, problem", [
    (Material(texture=2), "texture 2 is used but the scene has no 'makePixmap 2 file'"),
    (Material(texture=-7), "texture -7 is not a known solid texture")])
def test_an_unusable_texture_is_refused_naming_the_object_and_changes_nothing(material, problem):
    editable = EditableScene(plain_scene())
    render(editable.compiled, 8, 6, backend="c")
    before = list(editable.scene.objects)
    with pytest.raises(TracerError, match=f"object 1: {problem}"):
        editable.set_material(1, material)
    assert editable.scene.objects == before
    assert_renders_alike(editable, "c")


def test_a_physical_light_over_unlit_shapes_renders_on_the_c_core():
    """(The C core refused a sphere light where nothing was lit: it read 'no physical-lights effect' as an
    unknown light kind.)"""
    scene = plain_scene()
    scene.lights = [Light((3, 4, 5), (1, 1, 1), kind="sphere", radius=0.5, samples=4)]
    c, numpy = render(scene, 16, 12, backend="c"), render(scene, 16, 12, backend="numpy")
    assert c.backend == "c" and np.abs(c.image - numpy.image).max() <= 1 / 255


def test_an_animation_frame_moves_every_object_at_once(backend):
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    render(editable.compiled, 8, 6, backend="c")
    frame = {key: translation(0.1 * k, 0.05, -0.1) @ _first_matrix(editable, key) for k, key in enumerate(keys)}
    frame["csg"] = translation(0.2, 0, 0)  # (a boolean's leaves all get it)
    editable.set_transforms(frame.items())
    for key, matrix in frame.items():
        for obj in editable.objects_of(key):
            for leaf in ([obj.left, obj.right] if isinstance(obj, CSG) else [obj]):
                assert np.array_equal(leaf.matrix, matrix)
    assert editable.done["rebuild"] == 1  # (every object moved: built anew, not refitted)
    assert_renders_alike(editable, backend)
    with pytest.raises(TracerError, match="'torus'.*singular"):
        editable.set_transforms([("red", np.eye(4)), ("torus", np.diag([1.0, 1.0, 0.0, 1.0]))])
    assert np.array_equal(editable.objects_of("red")[0].matrix, frame["red"])  # (nothing changed)


def test_a_scene_read_as_columns_is_edited_as_its_shapes(backend):
    """A ShapeTable (the C reader's columns: a tapered cylinder, a polyhedron, the teapot) becomes its list of
    Shapes once, and is edited like any list."""
    from tracer.sdl.parser import parse_sdl
    text = ("light 5 5 5 1 1 1\ncamera 0 2 8 0 0 0 0 1 0 40\ndiffuse 1 0 0\ntranslate 1 0 0 sphere\n"
            "push scale 0.5 1 0.5 rotate 30 0 0 1 cube pop\nreflectivity 0.6 diffuse 0 1 0\n"
            "push translate -1 0 0 taperedCylinder 0.25 pop\npush translate 0 1 0 scale 0.5 0.5 0.5 octahedron pop\n"
            "push translate -2 0 0 scale 0.3 0.3 0.3 teapot pop\n")
    scene = parse_sdl(text, file="table.sdl")
    scene.objects = ShapeTable.of_shapes(scene.objects)
    editable = EditableScene(scene)
    assert isinstance(editable.scene.objects, list) and len(editable) == 5
    render(editable.compiled, 8, 6, backend=backend)
    editable.set_transform(2, translation(-1.5, 0.2, 0) @ scaling(1, 1.5, 1))
    editable.set_material(3, GLASS)
    editable.remove_objects(4)
    assert_renders_alike(editable, backend)


def test_a_key_whose_parts_change_in_number_is_replaced_whole(backend):
    """A Blender mesh edited to use one material more: its parts are replaced (removed, added at the end)."""
    octahedron, pawn = _octahedron(), _pawn()
    scene = Scene(objects=[Shape("mesh", np.eye(4), RED, mesh=octahedron), Shape("sphere", translation(2, 0, 0), GLASS)],
                  lights=[Light((4, 5, 6), (1, 1, 1))], camera=Camera(eye=(0, 2, 8), look=(0, 0, 0)))
    editable = EditableScene(scene, ["mesh object", "ball"])
    render(editable.compiled, 8, 6, backend=backend)
    parts = [Shape("mesh", translation(-1, 0, 0), RED, mesh=octahedron),
             Shape("mesh", translation(-1, 0, 0) @ scaling(0.3, 0.6, 0.3), MIRROR, mesh=pawn)]
    editable.replace_objects("mesh object", parts)
    assert editable.objects_of("mesh object") == parts and editable.positions_of("mesh object") == [1, 2]
    assert_renders_alike(editable, backend)
    editable.replace_objects("mesh object", parts[1:])
    assert_renders_alike(editable, backend)


def test_adding_and_removing_among_many_objects_keeps_the_hierarchy(backend):
    editable = EditableScene(many_spheres(300))
    render(editable.compiled, 8, 6, backend="c")
    core = editable.compiled._flat_cache[1].core
    for k in (0, 17, 18, 150, 299):  # (the hierarchy renumbered, the leaves that lost them refitted)
        editable.remove_objects(k)
    for k in range(12):  # (added outside the hierarchy)
        editable.add_objects(("new", k), [Shape("sphere", translation(k / 3 - 2, 2.5, 1) @ scaling(0.2, 0.2, 0.2), RED)])
    editable.set_transform(("new", 3), translation(0, -2, 2) @ scaling(0.3, 0.3, 0.3))  # (moved while outside)
    editable.set_transform(5, translation(2, -2, 2) @ scaling(0.3, 0.3, 0.3))  # (refitted in its renumbered leaf)
    assert editable.done["restructure"] == 17 and editable.done["rebuild"] == 0
    assert editable.compiled._flat_cache[1].core is core
    assert_hierarchy_holds_every_object(editable)
    assert_renders_alike(editable, backend)
    with editable.batch():  # (more than are kept outside: built again)
        for k in range(70):
            editable.add_objects(("more", k), [Shape("sphere", translation(k / 20 - 2, -3, 0) @ scaling(0.1, 0.1, 0.1),
                                                     MIRROR)])
    assert_hierarchy_holds_every_object(editable)
    assert_renders_alike(editable, backend)


def test_removing_many_objects_one_by_one_empties_leaves_safely():
    """Leaves lose all their objects (they then list none) while others are added and moved; the image stays
    the rebuilt scene's."""
    rng = np.random.default_rng(7)
    editable = EditableScene(many_spheres(240))
    render(editable.compiled, 8, 6, backend="c")
    for step in range(150):
        keys = editable.keys()
        editable.remove_objects(keys[int(rng.integers(len(keys) - 1))])  # (never the plane, last)
        if step % 5 == 0:
            editable.add_objects(("new", step), [Shape("sphere", translation(*rng.uniform(-3, 3, 3)) @
                                                       scaling(0.2, 0.2, 0.2), RED)])
        if step % 7 == 0:
            key = keys[int(rng.integers(len(keys) - 1))]
            if key in editable:
                editable.set_transform(key, translation(*rng.uniform(-3, 3, 3)) @ scaling(0.25, 0.25, 0.25))
        if step % 50 == 49:
            assert_hierarchy_holds_every_object(editable)
            assert_renders_alike(editable, "c")
    assert editable.done["restructure"] >= 150


def test_settings_edited_in_place_render_as_from_scratch(backend):
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    render(editable.compiled, 8, 6, backend=backend)
    editable.set_settings(Settings(background=(0.3, 0.2, 0.1), global_ambient=(0.3, 0.3, 0.3), max_recursion_depth=2))
    assert_renders_alike(editable, backend)
    editable.set_settings(Settings(min_reflectivity=0.9, min_transparency=0.9, max_recursion_depth=3))
    assert "reflection" not in editable.compiled.effects and "refraction" not in editable.compiled.effects
    assert_renders_alike(editable, backend)
    editable.set_settings(Settings(max_recursion_depth=0))
    assert_renders_alike(editable, backend)


def test_pictures_swapped_in_place_render_as_from_scratch(backend):
    editable = EditableScene(plain_scene())
    render(editable.compiled, 8, 6, backend=backend)
    editable.set_lights([Light((3, 4, 5), (1, 1, 1))])
    editable.set_material(0, Material(diffuse=(1, 1, 1), texture=1))
    editable.set_pixmaps({1: str(ROOT / "scenes" / "images" / "uvgrid.bmp")})
    assert_renders_alike(editable, backend)
    with pytest.raises(TracerError, match="texture 1 is used"):
        editable.set_pixmaps({2: str(BRICKS)})
    assert editable.scene.pixmaps == {1: str(ROOT / "scenes" / "images" / "uvgrid.bmp")}


def test_a_picture_on_a_mesh_with_texture_coordinates_follows_mesh_and_material_edits(backend):
    vertices = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    quad = MeshData(vertices, np.array([[0.0, 0.0, 1.0]]), [((0, 1, 2, 3), (0, 0, 0, 0))], "quad",
                    corner_uvs=np.array([(0.0, 1.0), (0.0, 0.0), (1.0, 0.0), (1.0, 1.0)]))
    plain_quad = MeshData(vertices, np.array([[0.0, 0.0, 1.0]]), [((0, 1, 2, 3), (0, 0, 0, 0))], "quad")
    scene = plain_scene()
    scene.objects.append(Shape("mesh", translation(0, 1.5, 0), PLAIN, mesh=quad))
    editable = EditableScene(scene)
    render(editable.compiled, 8, 6, backend=backend)
    editable.set_lights([Light((3, 4, 5), (1, 1, 1))])
    editable.set_material(3, Material(ambient=(1, 1, 1), diffuse=(0.5, 0.5, 0.5), texture=1))
    assert "mesh-uv" in editable.compiled.effects
    assert_renders_alike(editable, backend)
    editable.replace_mesh(3, plain_quad)
    assert "mesh-uv" not in editable.compiled.effects
    assert_renders_alike(editable, backend)
    editable.replace_mesh(3, quad)
    editable.set_transform(3, translation(0.5, 1.5, 0.5))
    assert "mesh-uv" in editable.compiled.effects
    assert_renders_alike(editable, backend)


def test_a_c_tracer_made_before_an_edit_traces_the_edited_scene():
    """The C core reads the edited rows where they lie, and gets the sealed-lights table again: a tracer made
    before an edit shades and skips as one made after it."""
    from tracer.native.tracer import NativeTracer
    scene, keys = mixed_scene()
    editable = EditableScene(scene, keys)
    before = NativeTracer(editable.compiled, threads=2)
    before.camera_rays(*_grid_rays(5))  # (the sealed-lights table sent)
    editable.set_transform("glass", translation(-5, 3, 2) @ scaling(1.5, 1.5, 1.5))  # (a light inside it now)
    editable.set_transform("oct2", translation(-0.5, 1.3, -0.5) @ scaling(0.7, 0.7, 0.7))
    editable.remove_objects("red")
    editable.add_objects("ball", [Shape("sphere", translation(1.5, 0.5, 0) @ scaling(0.5, 0.5, 0.5), GLASS)])
    before.counts = type(before.counts)()
    origins, _ = _grid_rays(15)
    targets = np.array([-5.0, 3.0, 2.0]) + 0.1 * (origins - origins.mean(axis=0))  # (the glass, round a light now)
    directions = targets - origins
    colours = before.camera_rays(origins, directions)  # (before any tracer made after the edits)
    after = NativeTracer(editable.compiled, threads=2)
    assert np.array_equal(colours, after.camera_rays(origins, directions))
    assert before.counts == after.counts
