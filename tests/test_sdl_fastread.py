"""The C core's SDL reader (tracer.sdl.fastread) against the Python reader: the same scene bit for bit, or a
decline after which the Python reader's scene, errors and warnings are what they always were."""
import math
import random
import struct
import sys
from pathlib import Path

import numpy as np
import pytest

from tracer import shapes, transforms
from tracer.native import contract
from tracer.errors import SDLError
from tracer.model import CSG, Camera, Light, Material, Scene, Settings, Shape, ShapeTable
from tracer.shapes import REGISTRY
from tracer.sdl import fastread, parser, statements
from tracer.sdl.parser import KEYWORDS, load, parse_sdl
from tracer.sdl.writer import write_sdl

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))
from run import sphere_scene  # noqa: E402

pytestmark = pytest.mark.skipif(not fastread.available(), reason="the C core is not loaded")

REGISTRY_CODES = {entry.keyword: code for code, entry in enumerate(REGISTRY)}
SHAPE_WORDS = parser.ANALYTIC_KINDS + parser.POLYHEDRON_KINDS + ("teapot",)


def bits(value) -> bytes:
    """The bytes of a float, or of each float in a tuple: -0.0 and 0.0 differ."""
    values = value if isinstance(value, tuple) else (value,)
    return b"".join(struct.pack("<d", v) if isinstance(v, float) else repr(v).encode() for v in values)


def material_bits(material: Material) -> list:
    return [bits(getattr(material, name)) + type(getattr(material, name)).__name__.encode()
            for name in Material.__dataclass_fields__]


def leaves(objects):
    """The shapes of a scene's objects in order, after checking that their booleans agree (pairs of a CSG's
    op, groups and source, then its operands)."""
    todo = list(reversed(objects))
    while todo:
        node = todo.pop()
        if isinstance(node, CSG):
            yield (node.op, node.groups, node.source)
            todo += (node.right, node.left)
        else:
            yield node


def assert_same_scene(fast: Scene, slow: Scene) -> None:
    """Every field of every shape (matrix and numbers bit for bit), lights, camera, settings, pixmaps and
    warnings; and shapes share a Material exactly where the Python reader's do."""
    assert len(fast.objects) == len(slow.objects)
    first_with = ({}, {})
    fast_leaves, slow_leaves = list(leaves(fast.objects)), list(leaves(slow.objects))
    assert len(fast_leaves) == len(slow_leaves)
    for index, (a, b) in enumerate(zip(fast_leaves, slow_leaves)):
        if isinstance(a, tuple) or isinstance(b, tuple):
            assert a == b
            continue
        assert type(a) is Shape and type(b) is Shape
        assert a.kind == b.kind
        assert a.matrix.dtype == b.matrix.dtype and a.matrix.shape == b.matrix.shape == (4, 4)
        assert a.matrix.tobytes() == b.matrix.tobytes(), (index, a.matrix, b.matrix)
        assert material_bits(a.material) == material_bits(b.material), index
        assert [bits(x) for x in a.parameters] == [bits(x) for x in b.parameters]
        if a.kind == "mesh":  # (read from its file by each read)
            assert a.mesh.origin == b.mesh.origin and np.array_equal(a.mesh.vertices, b.mesh.vertices)
        else:  # a built-in polyhedron's is the one cached MeshData
            assert a.mesh is b.mesh
        assert a.mesh_file == b.mesh_file and a.groups == b.groups
        assert a.source == b.source, index
        assert a.name == b.name
        # the same sharing of Material objects
        for seen, shape in zip(first_with, (a, b)):
            seen.setdefault(id(shape.material), index)
        assert first_with[0][id(a.material)] == first_with[1][id(b.material)]
    assert [(bits(l.position), bits(l.color)) for l in fast.lights] == \
        [(bits(l.position), bits(l.color)) for l in slow.lights]
    if slow.camera is None:
        assert fast.camera is None
    else:
        assert [bits(getattr(fast.camera, f)) for f in ("eye", "look", "up", "view_angle")] == \
            [bits(getattr(slow.camera, f)) for f in ("eye", "look", "up", "view_angle")]
    assert [bits(getattr(fast.settings, f)) for f in Settings.__dataclass_fields__] == \
        [bits(getattr(slow.settings, f)) for f in Settings.__dataclass_fields__]
    assert fast.pixmaps == slow.pixmaps and fast.warnings == slow.warnings and fast.source == slow.source


def outcome(text: str, fast: bool, strict: bool):
    """The scene, or the error's message."""
    try:
        return parse_sdl(text, file="scene.sdl", strict=strict, fast=fast)
    except SDLError as error:
        return f"error: {error}"


def assert_readers_agree(text: str) -> None:
    """Both readers, strict and lenient, give the same (the same error, where there is one)."""
    for strict in (True, False):
        fast, slow = outcome(text, True, strict), outcome(text, False, strict)
        if isinstance(slow, str):
            assert fast == slow
        else:
            assert_same_scene(fast, slow)


def assert_read_fast(text: str) -> Scene:
    """The C reader reads ``text`` (does not decline it) and gets the Python reader's scene."""
    columns = fastread.scan(text)
    assert isinstance(columns, fastread.Columns), columns
    fast = fastread.read(text, "scene.sdl")
    assert fast is not None
    assert_same_scene(fast, parse_sdl(text, file="scene.sdl", fast=False))
    return fast


def assert_declined(text: str, reason: str) -> None:
    """The C reader declines ``text`` for ``reason``, and parse_sdl then gives what the Python reader does."""
    result = fastread.scan(text)
    assert isinstance(result, fastread.Declined) and result.reason == reason, result
    assert fastread.read(text) is None
    assert_readers_agree(text)


# --- what it reads, bit for bit ---------------------------------------------------------------------------

def test_bench_sphere_scenes_are_read_by_the_c_reader():
    for count, seed in ((0, 1), (1, 2), (3000, 3)):
        scene = assert_read_fast(sphere_scene(count, seed))
        assert len(scene.objects) == count + 1


def test_the_shapes_stay_columns_until_asked_for():
    text = "! name: ball\nsphere diffuse 1 0 0 cube translate 1 2 3 taperedCylinder 0.5"
    scene = fastread.read(text, "scene.sdl")
    assert isinstance(scene.objects, ShapeTable) and len(scene.objects) == 3
    columns = scene.objects.columns
    assert columns is not None  # nothing made yet
    assert columns.kinds.tolist() == [REGISTRY_CODES[k] for k in ("sphere", "cube", "taperedCylinder")]
    assert columns.material_ids.tolist() == [0, 1, 1] and len(columns.materials) == 2
    assert columns.parameters[:, 0].tolist() == [0.0, 0.0, 0.5]  # (only the tapered cylinder reads one)
    assert columns.affines[2].tolist() == [1.0, 0.0, 0.0, 1.0, 0.0, 1.0, 0.0, 2.0, 0.0, 0.0, 1.0, 3.0]
    assert (columns.lines.tolist(), columns.columns.tolist()) == ([2, 2, 2], [1, 22, 43])
    assert columns.names == {0: "ball"} and columns.file == "scene.sdl"
    assert_same_scene(scene, parse_sdl(text, file="scene.sdl", fast=False))


def test_big_texts_go_to_the_c_reader_by_default(monkeypatch):
    text = sphere_scene(2000)
    assert len(text) >= parser.FAST_MIN_CHARS
    calls = []
    real = fastread.read
    monkeypatch.setattr(fastread, "read", lambda *args: calls.append(args) or real(*args))
    parse_sdl(text)
    parse_sdl("sphere")  # small: the Python reader alone
    parse_sdl(text, fast=False)
    assert calls == [(text, None)]


def test_load_reads_a_big_file_with_the_c_reader(tmp_path):
    path = tmp_path / "spheres.sdl"
    path.write_text(sphere_scene(2000))
    fast = load(path)
    slow = load(path, fast=False)
    assert_same_scene(fast, slow)
    assert fast.objects[5].source.file == str(path)


def test_every_statement_of_the_subset():
    text = """
        light 1 2 3 0.5 0.25 1  light -4 5e2 .5 1 1 1
        globalAmbient 0.2 0.3 0.4  background 1 0 0.5  minReflectivity 0.25  minTransparency 0.75
        maxRecursionDepth 7 maxRecursionDepth 64 maxRecursionDepth 0 maxRecursionDepth -0
        camera 0 0 10 0 0 0 0 1 0 45  camera 1 2 3 0 0 0 0 0 1 30.5
        ambient 0.1 0.2 0.3 diffuse 0.4 0.5 0.6 specular 1 1 1 emissive 0 0.1 0
        specularExponent 20 reflectivity 0.3 transparency 0.2 speedOfLight 0.9 specularFraction 0.5
        surfaceRoughness 0.1 texture -1 parameters 3 1 2 3 sphere
        texture 2147483647 parameters 10 1 2 3 4 5 6 7 8 9 10 cube texture -2147483648 parameters 0 cube
        defaultMaterials square
        translate 1 2 3 scale 2 3 4 rotate 30 1 2 3 plane push rotate 90 0 0 1 cylinder pop cone
        identityAffine torus taperedCylinder 0.25 paraboloid
        tetrahedron octahedron dodecahedron icosahedron buckyball diamond teapot
    """
    scene = assert_read_fast(text)
    assert [s.kind for s in scene.objects][:4] == ["sphere", "cube", "cube", "square"]


def test_every_shape_keyword_of_the_registry():
    text = " ".join(f"translate 1 0 0 {kind}" + " 0.5" * len(shapes.KINDS[kind].parameters) for kind in SHAPE_WORDS)
    scene = assert_read_fast(text)
    assert len(scene.objects) == len(SHAPE_WORDS)


def test_name_comments_name_the_next_shape():
    text = ("! name: first\nsphere\n! name: lost\n! name:   second one  \r\ncube ! not a name\n"
            "translate 1 ! name: third\n 2 3 cone !name:fourth\n taperedCylinder !  name:  fifth\r\n 0.5 "
            "sphere ! name:\ncube\n!name: sixth {with} braces and \x0b odd spaces\x1c \n teapot\n! name: never")
    scene = assert_read_fast(text)
    assert [s.name for s in scene.objects] == ["first", "second one", "third", "fourth", "fifth", None,
                                               "sixth {with} braces and \x0b odd spaces"]


def test_places_of_shapes_on_odd_lines():
    text = ("sphere\r\n\tcube\x0c square\x1d\x1e plane\v\r\n\n   torus!c\ncone!comment sphere\n" +
            "push pop " * 40 + "sphere\n" + "\x1f" * 5 + "cube")
    scene = assert_read_fast(text)
    assert [s.source.line for s in scene.objects] == [1, 2, 2, 2, 4, 5, 6, 7]


def test_numbers_at_the_edges_of_the_grammar():
    numbers = ["-0", "-0.0", "+0", "0e999", "1e-400", "4.9e-324", "2.4703282292062328e-324", "1.7976931348623157e308",
               "-1.7976931348623157e308", "123456789012345678901234567890", "0.1", "1.", ".5", "+.5e+2",
               "-5.E-3", "00012.5000", "3.14159265358979323846264338327950288", "9007199254740993",
               "2.2250738585072011e-308", "1e22", "1e23", "8.5e-15"]
    text = "".join(f"light {n} 0 0 {n} 1 1\n" for n in numbers)
    scene = assert_read_fast(text)
    assert bits(scene.lights[0].position[0]) == bits(-0.0)


def test_rotations_by_any_angle_about_any_axis():
    rng = random.Random(13)
    statements = []
    for _ in range(300):
        angle = rng.choice([rng.uniform(-720, 720), rng.choice([0, 90, -90, 180, 270, 360, 450, -0.0, 1e20, 9e20,
                                                                    1e-300, 45, 30, 60])])
        axis = [rng.choice([0.0, -0.0, rng.uniform(-3, 3), rng.choice([1e-150, 1e150, 1.0, -1.0])]) for _ in range(3)]
        if not any(axis):
            axis[rng.randrange(3)] = 1.0
        statements.append(f"rotate {angle!r} {axis[0]!r} {axis[1]!r} {axis[2]!r} sphere")
        if rng.random() < 0.2:
            statements.append("identityAffine")
    assert_read_fast("\n".join(statements))


def test_materials_are_interned_by_value_first_value_kept():
    text = ("diffuse 0 0 0 sphere diffuse -0 0 0 cube diffuse 0 -0.0 0 square "
            "parameters 2 1 -0 sphere parameters 2 1 0 cube parameters 3 1 0 0 cube parameters 0 cube "
            "texture -0 sphere texture 0 cube defaultMaterials sphere")
    scene = assert_read_fast(text)
    assert bits(scene.objects[1].material.diffuse) == bits((0.0, 0.0, 0.0))
    assert scene.objects[0].material is scene.objects[1].material is scene.objects[2].material


def test_texts_of_the_writer():
    rng = np.random.default_rng(5)
    objects = []
    for index in range(60):
        linear = rng.normal(size=(3, 3))
        matrix = np.eye(4)
        matrix[:3, :3] = linear
        matrix[:3, 3] = rng.normal(size=3) * 10
        kind = SHAPE_WORDS[index % len(SHAPE_WORDS)]
        material = Material(diffuse=tuple(rng.uniform(0, 1, 3)), reflectivity=float(rng.uniform(0, 1)),
                            parameters=tuple(rng.uniform(0, 1, index % 4)), texture=-(index % 3))
        objects.append(Shape(kind, matrix, material, parameters=(0.5,) * len(shapes.KINDS[kind].parameters),
                             mesh=parser.builtin_mesh(kind) if kind in parser.POLYHEDRON_KINDS + ("teapot",)
                             else None, name=f"object {index}" if index % 2 else None))
    scene = Scene(objects=objects, lights=[Light((1.0, 2.0, 3.0), (1.0, 1.0, 1.0))],
                  camera=Camera((0.0, 1.0, 9.0), (0.0, 0.0, 0.0)), settings=Settings(max_recursion_depth=5))
    text = write_sdl(scene)
    assert "! name: object 1" in text
    assert_read_fast(text)


def random_statement(rng: random.Random) -> str:
    """One statement of the C reader's subset, with numbers of every form (sometimes one it declines)."""
    def number():
        return rng.choice([f"{rng.uniform(-10, 10):.{rng.randrange(1, 18)}g}", str(rng.randrange(-5, 6)),
                           rng.choice(["-0", "0.0", "1e-320", "3e300", "-2.5e-8", ".125", "7."]),
                           repr(rng.uniform(-1e6, 1e6))])

    def numbers(count):
        return " ".join(number() for _ in range(count))

    def moderate():  # (for transforms: a product of many extreme ones is declined as not clearly invertible)
        return rng.choice([f"{rng.uniform(-10, 10):.{rng.randrange(1, 18)}g}", "-0", "0.0", ".125", "7.",
                           repr(rng.uniform(-3, 3))])
    choice = rng.randrange(16)
    if choice == 0:
        return f"light {numbers(6)}"
    if choice == 1:
        return rng.choice(["globalAmbient", "background"]) + " " + numbers(3)
    if choice == 2:
        return rng.choice(["minReflectivity", "minTransparency"]) + " " + number()
    if choice == 3:
        return rng.choice(list(parser.COLOR_MATERIAL)) + " " + numbers(3)
    if choice == 4:
        return rng.choice(list(parser.FLOAT_MATERIAL)) + " " + number()
    if choice == 5:
        count = rng.randrange(0, 11)
        return f"parameters {count} {numbers(count)}"
    if choice == 6:
        return f"texture {rng.randrange(-3, 16)}"
    if choice == 7:
        return f"translate {moderate()} {moderate()} {moderate()}"
    if choice == 8:
        factors = ['1', '2', '0.5', '-1', '3e-3', '1.5', '-0.25', '0.75']
        return f"scale {' '.join(rng.choice(factors) for _ in range(3))}"
    if choice == 9:
        return f"rotate {number()} {rng.choice(['1 0 0', '0 1 0', '0 0 1', numbers(3), '-0 0 1e-150'])}"
    if choice == 10:  # (pops follow pushes, nearly always: a pop too many is declined, so rare here)
        return rng.choice(["push", "push pop", "push", "identityAffine", "defaultMaterials",
                           "pop" * (rng.random() < 0.1)])
    if choice == 11:
        return rng.choice([f"! name: shape {rng.randrange(100)}\n", "! caf\u00e9 \u2603 \U0001F600 \u00a0\n"])
    if choice == 12:
        return f"camera {numbers(9)} {rng.uniform(1, 179):.3f}"
    if choice == 13:
        return f"maxRecursionDepth {rng.randrange(0, 65)}"
    kind = rng.choice(SHAPE_WORDS)
    return " ".join([kind] + [number() for _ in shapes.KINDS[kind].parameters])


@pytest.mark.parametrize("seed", range(40))
def test_random_statement_sequences(seed):
    """Texts the C reader reads must give the Python reader's scene; texts it declines (a pop too many, a
    singular transform, a bad camera) the Python reader's outcome, strict and lenient."""
    rng = random.Random(seed)
    separators = [" ", "\n", "\r\n", "\t", "  ", "\n\n"]
    text = "".join(random_statement(rng) + rng.choice(separators) for _ in range(rng.randrange(1, 300)))
    if isinstance(fastread.scan(text), fastread.Columns) and fastread.read(text) is not None:
        assert_read_fast(text)
    assert_readers_agree(text)


def test_random_sequences_are_mostly_read():
    """(So that the test above tests the C reader, not only its declines.)"""
    read = 0
    for seed in range(40):
        rng = random.Random(seed)
        text = " ".join(random_statement(rng) for _ in range(rng.randrange(1, 300)))
        read += isinstance(fastread.scan(text), fastread.Columns)
    assert read >= 10


# --- bundled and regression files --------------------------------------------------------------------------

@pytest.mark.parametrize("path", sorted((ROOT / "scenes").glob("*.sdl")) +
                         sorted((ROOT / "tests" / "fuzz" / "regressions").glob("*.sdl")), ids=lambda p: p.name)
def test_bundled_and_regression_files(path):
    for strict in (True, False):
        outcomes = []
        for fast in (True, False):
            try:
                outcomes.append(load(path, strict=strict, fast=fast))
            except SDLError as error:
                outcomes.append(f"error: {error}")
        if isinstance(outcomes[1], str):
            assert outcomes[0] == outcomes[1]
        else:
            assert_same_scene(*outcomes)


# --- what it declines --------------------------------------------------------------------------------------

@pytest.mark.parametrize("text, reason", [
    ("sphere def a { cube } use a", "word"),
    ("sphere use a", "word"),
    ("union sphere cube", "word"),
    ("intersection sphere cube", "word"),
    ("difference sphere cube", "word"),
    ("mesh pawn.3vn", "word"),
    ("makePixmap 1 picture.ppm", "word"),
    ("sphere Sphere", "word"),
    ("sphere 1", "word"),
    ("sphere { cube }", "brace"),
    ("sphere }", "brace"),
    ("translate 1 2 { 3", "brace"),
    ("translate 1 two 3 sphere", "number"),
    ("translate 1 sphere", "number"),
    ("light 1 2 3 1 1 inf", "number"),
    ("light 1 2 3 1 1 nan", "number"),
    ("light 1 2 3 1 1 1e400", "number"),
    ("light 1 2 3 1 1 0x10", "number"),
    ("light 1 2 3 1 1 1_0", "number"),
    ("translate 1 2", "end"),
    ("taperedCylinder", "end"),
    ("parameters 3 1 2", "end"),
    ("maxRecursionDepth 65", "value"),
    ("maxRecursionDepth 2.5", "value"),
    ("maxRecursionDepth -1", "value"),
    ("texture 1.5 sphere", "value"),
    ("texture 2147483648 sphere", "value"),
    ("texture -2147483649 sphere", "value"),
    ("parameters 11 1 2 3 4 5 6 7 8 9 10 11 sphere", "value"),
    ("parameters 1.5 1 sphere", "value"),
    ("parameters -1 sphere", "value"),
    ("push pop pop sphere", "pop"),
    ("rotate 30 0 0 0 sphere", "axis"),
    ("rotate 30 1e-200 0 0 sphere", "axis"),
    ("rotate 30 1e200 0 0 sphere", "axis"),
    ("scale 1 1 0 sphere", "transform"),
    ("scale 1e300 1e300 1e300 scale 1e300 1 1 sphere", "transform"),
    ("scale 1e-90 1e-90 1e-90 sphere", "transform"),
    ("scale 1 1 1e-12 sphere", "transform"),
    ("translate 1e301 0 0 sphere", "transform"),
    ("sph\u00e8re", "ascii"),
])
def test_declines(text, reason):
    assert_declined(text, reason)


def test_declined_cameras_are_read_by_the_python_reader():
    for text in ("camera 0 0 0 0 0 0 0 1 0 45 sphere", "camera 0 0 5 0 0 0 0 0 1 45 sphere",
                 "camera 0 0 5 0 0 0 0 1 0 180 sphere", "camera 0 0 5 0 0 0 0 1 0 45 camera 0 0 5 0 0 0 0 0 0 45"):
        assert isinstance(fastread.scan(text), fastread.Columns)
        assert fastread.read(text) is None
        assert_readers_agree(text)


def test_a_def_is_declined_where_it_stands():
    text = "def a { sphere }\n" + sphere_scene(2000)
    declined = fastread.scan(text)
    assert declined == fastread.Declined("word", 0)
    assert_readers_agree(text)


def test_every_keyword_of_the_python_reader_is_read_or_declined():
    """A keyword reaches the C reader only through its statement's action (tracer/sdl/statements.py): until
    it has one it is declined, so the Python reader keeps reading it."""
    assert fastread.available()
    vocabulary = statements.vocabulary()
    assert set(vocabulary) | fastread.DECLINED == KEYWORDS
    assert not set(vocabulary) & fastread.DECLINED
    for keyword in KEYWORDS - set(vocabulary):
        assert fastread.scan(f"sphere {keyword} 1 2 3") == fastread.Declined("word", 7)


def test_the_declined_text_costs_one_scan_up_to_the_decline():
    text = "sphere " * 10 + "def a { cube }" + " sphere" * 1000
    assert fastread.scan(text) == fastread.Declined("word", 70)


def test_rotation_is_rodrigues_with_a_left_to_right_length():
    m = transforms.rotation(30.0, 1.0, 2.0, 2.0)
    x, y, z = 1 / 3, 2 / 3, 2 / 3
    c, s = math.cos(math.radians(30.0)), math.sin(math.radians(30.0))
    assert m[0, 1] == x * y * (1.0 - c) - z * s
    assert np.allclose(m[:3, :3] @ m[:3, :3].T, np.eye(3), atol=1e-15)


def test_without_a_shared_libm_only_right_angles_are_read(monkeypatch):
    """(Windows: Python's cos and sin may not be the C core's.)"""
    monkeypatch.setattr(fastread, "SHARED_LIBM", False)
    assert_read_fast("rotate 90 0 0 1 sphere rotate -270 1 1 0 cube rotate 0 1 0 0 rotate 720 0 1 0 cone")
    assert_declined("rotate 90 0 0 1 sphere rotate 30 0 1 0 cube", "angle")
    assert_declined("rotate 9e20 0 1 0 cube", "angle")


#: Characters a mutation puts into a text: the ones the lexer treats specially, digits, letters, and
#: characters beyond ASCII (white space to str.split, or not).
MUTATION_BYTES = " \t\n\r\x0b\x0c\x1c\x1f!{}+-.eE0123456789aZ\x00~:#\u00e9\u00a0\u2028\u3000\U0001F600\ufffd"


@pytest.mark.parametrize("seed", range(25))
def test_mutated_texts(seed):
    """Bad input anywhere (a byte changed, dropped or added, a cut, a repeated piece): the C reader reads or
    declines, never crashes, and parse_sdl's outcome (scene, error or warnings) is the Python reader's."""
    rng = random.Random(1000 + seed)
    text = sphere_scene(rng.randrange(1, 40), seed) if seed % 2 else \
        "".join(random_statement(rng) + " " for _ in range(rng.randrange(1, 80)))
    chars = list(text)
    for _ in range(rng.randrange(1, 6)):
        at = rng.randrange(len(chars) + 1)
        change = rng.randrange(4)
        if change == 0 and at < len(chars):
            chars[at] = rng.choice(MUTATION_BYTES)
        elif change == 1 and at < len(chars):
            del chars[at]
        elif change == 2:
            chars.insert(at, rng.choice(MUTATION_BYTES))
        else:
            end = min(len(chars), at + rng.randrange(1, 30))
            chars[at:at] = chars[at:end]
    if rng.random() < 0.3:
        chars = chars[:rng.randrange(len(chars) + 1)]
    assert_readers_agree("".join(chars))


def test_the_text_is_handed_to_c_without_a_copy_in_cpython():
    import ctypes
    for text in ("sphere cube " * 1000, "sphere ! \u2603\ncube " * 1000):
        utf8 = fastread._Utf8.of(text)
        assert utf8.size == len(text.encode("utf-8"))
        if sys.implementation.name == "cpython":
            assert isinstance(utf8.data, int)
            assert ctypes.string_at(utf8.data, utf8.size) == text.encode("utf-8")
        else:
            assert utf8.data == text.encode("utf-8")


# --- text beyond ASCII: read inside plain comments, declined anywhere else ------------------------------------

@pytest.mark.parametrize("comment", [
    "caf\u00e9",  # 2 bytes in UTF-8
    "\u2603 snow",  # 3
    "\U0001F600",  # 4
    "\ufffd\ufffd",  # what read_text makes of bytes that are not UTF-8
    "\u00a0\u0085\u2028\u3000",  # white space to str.split, line breaks to str.splitlines: inside a comment still
    "! name: \u00e9 ! \u2603",  # not a name comment: the first '!' starts it
])
@pytest.mark.parametrize("newline", ["\n", "\r\n"])
def test_comments_beyond_ascii_are_read_by_the_c_reader(comment, newline):
    lines = [f"! {comment}", "! name: first", f"sphere ! {comment}", f"  diffuse 1 0 0 cube !{comment}",
             f"\t! {comment}", "! name: second", f"translate 1 2 3 taperedCylinder 0.5 ! {comment}", f"!{comment}"]
    text = newline.join(lines)
    assert_read_fast(text)
    columns = fastread.scan(text)
    # the places of the Python reader's tokens (compared in assert_read_fast), spelled out
    assert (columns.lines.tolist(), columns.columns.tolist()) == ([3, 4, 7], [1, 17, 17])
    assert columns.names == {0: "first", 2: "second"}
    assert_readers_agree(text)


def test_a_utf8_file_with_and_without_a_byte_order_mark_is_read_by_the_c_reader(tmp_path):
    body = sphere_scene(3000, 5).replace("\n", " ! caf\u00e9 \u2603 \U0001F600\r\n", 40)
    assert len(body) >= parser.FAST_MIN_CHARS
    for name, data in (("plain.sdl", body.encode("utf-8")), ("marked.sdl", b"\xef\xbb\xbf" + body.encode("utf-8")),
                       ("latin.sdl", body.encode("utf-8") + "! caf\u00e9\n".encode("latin-1"))):
        path = tmp_path / name
        path.write_bytes(data)
        fast = load(path)
        assert isinstance(fast.objects, ShapeTable), name  # (the Python reader's is a list)
        assert_same_scene(fast, load(path, fast=False))


@pytest.mark.parametrize("space", ["\u00a0", "\u0085", "\u1680", "\u2000", "\u2028", "\u3000", "\ufeff", "\u00e9"])
def test_a_character_beyond_ascii_outside_a_comment_is_declined_where_it_stands(space):
    """str.split takes some of them for white space (so 'sphere\u00a0cube' is two shapes to the Python reader);
    the C reader leaves them all to it."""
    for text in (f"sphere ! \u2603\ncube{space}sphere", f"sphere ! \u2603\ntranslate 1 2{space}3 cube",
                 f"sphere\n{space}cube ! \u2603"):
        assert fastread.scan(text) == fastread.Declined("ascii", text.index(space, text.index("\n")))
        assert_declined(text, "ascii")


@pytest.mark.parametrize("text, name", [
    ("! name: caf\u00e9\nsphere", "caf\u00e9"),
    ("! name: ball \u2603\U0001F600 \nsphere", "ball \u2603\U0001F600"),
    ("! name: ball\u3000\nsphere", "ball"),  # (U+3000 and U+00A0 are white space to \s)
    ("! name:\u00a0\u3000ball \u00e9\u00a0\r\nsphere", "ball \u00e9"),
    ("! \u2603\n! name: ball ! \U0001F600\nsphere", "ball ! \U0001F600"),
    ("! name: first\n! name: \u00e9 second\n! name: \t\nsphere", "\u00e9 second"),  # (the latest non-empty one)
])
def test_a_name_comment_beyond_ascii_is_read(text, name):
    assert fastread.scan(text).names == {0: name}
    assert assert_read_fast(text).objects[0].name == name


@pytest.mark.parametrize("text", [
    "!\u3000name: ball\nsphere",  # (a name comment to the Python reader)
    "!\u00e9 name: ball\nsphere",  # (not one: declined all the same)
    "! name: \u00e9\nsphere",  # (no ASCII in the name: it could be all white space to \s, naming nothing)
    "! name: ball\n! name: \u3000\nsphere",
])
def test_a_name_comment_whose_name_beyond_ascii_may_be_empty_is_declined(text):
    assert_declined(text, "ascii")


def test_an_error_after_a_comment_beyond_ascii_has_the_python_readers_place():
    text = "sphere ! caf\u00e9 \U0001F600\r\ncube ! \u2603\n  translate 1 two 3 sphere"
    assert fastread.scan(text).reason == "number"
    assert_readers_agree(text)
    with pytest.raises(SDLError, match="^scene.sdl:3:15: expected a number after 'translate'"):
        parse_sdl(text, file="scene.sdl", fast=True)


def test_a_lone_surrogate_is_declined_without_an_exception():
    """(A str made in Python: read_text replaces bytes that are not UTF-8 with U+FFFD.)"""
    text = "sphere ! \ud800\ncube"
    assert fastread.scan(text) == fastread.Declined("ascii", 9)
    assert_declined(text, "ascii")
    assert len(parse_sdl(text).objects) == 2


def test_the_decline_offset_counts_characters_after_a_comment_beyond_ascii():
    text = "sphere ! \U0001F600\u2603\u00e9\ncube def a { sphere }"
    assert fastread.scan(text) == fastread.Declined("word", text.index("def"))


def test_one_statement_table_drives_both_readers():
    """tracer/sdl/statements.py is the one list of statements: the Python reader's usage texts and handlers,
    the C reader's vocabulary and its table of actions (generated into contract.h) all come from it."""
    assert set(parser.USAGE) == set(statements.BY_KEYWORD) == KEYWORDS
    reader = parser._Reader("", None, None, True)
    for s in statements.STATEMENTS:
        assert reader.handlers[s.keyword].__name__ == s.handler
        assert parser.USAGE[s.keyword] == s.usage
    header = contract.HEADER.read_text()
    assert "#define RT_SDL_ACTIONS(X) " + " ".join(f"X({k}, {a})" for k, a in enumerate(statements.ACTIONS)) in header
    source = (contract.HEADER.parent / "sdl_read.h").read_text()
    for action in statements.ACTIONS:  # each a function of the C reader
        assert f"static int {action}(SdlReader *r, int32_t argument, int32_t count)" in source
    # one shape action for every kind, told how many parameters follow the keyword (the registry's)
    vocabulary = statements.vocabulary()
    for code, entry in enumerate(shapes.REGISTRY):
        if not entry.file_argument:
            assert vocabulary[entry.keyword] == (statements.ACTIONS.index("sdl_shape"), code, len(entry.parameters))
