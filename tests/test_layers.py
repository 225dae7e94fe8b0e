"""The import layers of tracer/ and addon/ (docs/contributing.md, "Module map and layers"), checked by reading
every module's imports with ast.

Rules:

1. A module imports modules of its own layer or of lower ones (LAYERS, bottom first), never of a higher one;
   the import of a submodule counts as one of its package too, since Python runs the package first.
2. No import circle, among all imports (those inside functions included).
3. An import inside a function (of a tracer or add-on module) is there on purpose, to keep start-up
   light (tracer/startup.py, the command line's import set in tests/test_cli.py, Blender's start): it
   says so in a comment containing ``deferred:`` in the comment lines just above it or beside any import of
   the run of import statements it belongs to.  Cycles are not dodged this way: rule 2 counts deferred imports
   too.
4. The NumPy reference (REFERENCE) imports nothing of the C core (``tracer.native``), and the NumPy
   intersections and textures do not reach it through other modules either.
5. The add-on's ``pure/`` imports no Blender module (``bpy``, ``mathutils``, ...) and no add-on module
   outside ``pure/``; the tracer imports nothing of the add-on or of Blender.

The rules are functions of a module graph (``{module: [Import]}``), so they are tested on planted
violations below as well as on the real code.
"""
from __future__ import annotations

import ast
import fnmatch
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Optional

import pytest

ROOT = Path(__file__).resolve().parent.parent

#: The layers, bottom first: (name, module patterns).  A pattern ``pkg.*`` matches every module below pkg.
LAYERS: tuple[tuple[str, tuple[str, ...]], ...] = (
    ("base", ("tracer.errors", "tracer.shapes", "tracer.numerics", "tracer.threads", "tracer.startup",
              "tracer.bulk", "tracer.atomic", "tracer.userfiles", "tracer.png", "tracer.imageio",
              "tracer.transforms", "tracer.sampling", "tracer.appearance", "tracer.savings", "tracer.signals",
              "tracer.diagnostics", "tracer.instances")),
    ("model", ("tracer.meshdata", "tracer.geometry", "tracer.geometry.*", "tracer.model", "tracer.camera")),
    ("NumPy geometry", ("tracer.intersect", "tracer.intersect.*", "tracer.textures", "tracer.textures.*",
                        "tracer.lights", "tracer.fresnel", "tracer.terminator")),
    # the SDL statement table (both readers', and the C reader's actions in contract.h)
    ("SDL statements", ("tracer.sdl", "tracer.sdl.statements", "tracer.sdl.lights")),
    ("C library", ("tracer.native", "tracer.native.build", "tracer.native.contract")),
    ("readers", ("tracer.meshio", "tracer.sdl", "tracer.sdl.*", "tracer.usd", "tracer.usd.*")),
    ("compile", ("tracer.compile", "tracer.batches", "tracer.skippable", "tracer.query")),
    ("NumPy tracer", ("tracer.raytree", "tracer.trace")),
    ("C tracer", ("tracer.native.flatten", "tracer.native.tracer")),
    ("render", ("tracer.backend", "tracer.edit", "tracer.edit_ledger", "tracer.tiles", "tracer.target",
                "tracer.adaptive", "tracer.render")),
    ("programs", ("tracer", "tracer.__main__", "tracer.cli", "tracer.reporting", "tracer.distributed",
                  "tracer.accuracy", "tracer.extremes")),
    # The add-on: its bpy-free part, then the modules that talk to Blender.  In the add-on the tracer is the
    # vendored ``addon.tracer`` (in the checkout the same modules as ``tracer``): read as ``tracer``.
    ("add-on, no bpy", ("addon.pure", "addon.pure.*")),
    ("add-on", ("addon", "addon.*")),
)
#: The NumPy reference path: imports nothing of the C core.  The first group not even through other modules.
REFERENCE_ALONE = ("tracer.intersect", "tracer.intersect.*", "tracer.textures", "tracer.textures.*", "tracer.lights",
                   "tracer.fresnel", "tracer.terminator")
REFERENCE = REFERENCE_ALONE + ("tracer.trace", "tracer.raytree", "tracer.skippable", "tracer.batches")
C_CORE = ("tracer.native", "tracer.native.*")
BLENDER = ("bpy", "bpy_extras", "mathutils", "gpu", "gpu_extras", "bmesh", "bl_math", "aud", "idprop",
           "addon_utils")
DEFERRED_MARK = "deferred:"


@dataclass(frozen=True)
class Import:
    target: str  # the module imported (for ``from x import name``: x.name when that is a module, else x)
    line: int
    deferred: bool  # inside a function
    commented: bool  # a "deferred:" comment on its line or the line above


def matches(module: str, patterns: Iterable[str]) -> bool:
    return any(module == p or (p.endswith(".*") and module.startswith(p[:-1])) or fnmatch.fnmatchcase(module, p)
               for p in patterns)


def layer_of(module: str, layers=LAYERS) -> Optional[int]:
    for index, (_, patterns) in enumerate(layers):
        if any(module == p for p in patterns):
            return index
    for index, (_, patterns) in enumerate(layers):
        if matches(module, patterns):
            return index
    return None


# -------------------------------------------------------------------------------------- reading the code


def module_files() -> dict[str, Path]:
    files = {}
    for package in ("tracer", "addon"):
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if "__pycache__" in rel.parts or rel.parts[:2] == ("addon", "tracer"):  # (the link to tracer/)
                continue
            parts = list(rel.with_suffix("").parts)
            if parts[-1] == "__init__":
                parts.pop()
            files[".".join(parts)] = path
    return files


def _canonical(name: str) -> str:
    """The add-on's vendored tracer is the tracer."""
    return name[len("addon."):] if name == "addon.tracer" or name.startswith("addon.tracer.") else name


def read_imports(module: str, path: Path, known: set[str]) -> list[Import]:
    source = path.read_text(encoding="utf-8")
    lines = source.splitlines()
    tree = ast.parse(source)
    package = module if path.name == "__init__.py" else module.rpartition(".")[0]
    out = []

    def commented(first: int, last: int) -> bool:
        """The mark on the lines of the run, or in the comment lines just above it."""
        while first > 1 and lines[first - 2].strip().startswith("#"):
            first -= 1
        return any(DEFERRED_MARK in lines[k - 1] for k in range(first, last + 1))

    def add(node, in_function: bool, marked: bool) -> None:
        if isinstance(node, ast.Import):
            for alias in node.names:
                out.append(Import(_canonical(alias.name), node.lineno, in_function, marked))
            return
        if node.level:
            base = package.split(".")
            base = base[:len(base) - (node.level - 1)]
            origin = ".".join(base + ([node.module] if node.module else []))
        else:
            origin = node.module or ""
        origin = _canonical(origin)
        for alias in node.names:
            full = f"{origin}.{alias.name}"
            out.append(Import(full if full in known else origin, node.lineno, in_function, marked))

    def visit(node, in_function: bool) -> None:
        """A run of import statements one after another shares one comment (a function's block of them)."""
        for _, value in ast.iter_fields(node):
            children = value if isinstance(value, list) else [value]
            run: list = []
            for child in children + [None]:
                if isinstance(child, (ast.Import, ast.ImportFrom)):
                    run.append(child)
                    continue
                if run:
                    marked = commented(run[0].lineno, run[-1].end_lineno)
                    for imp in run:
                        add(imp, in_function, marked)
                    run = []
                if isinstance(child, ast.AST):
                    visit(child, in_function or isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef,
                                                                    ast.Lambda)))

    visit(tree, False)
    return out


def contract_sources() -> list[str]:
    """The NumPy modules whose values tracer/native/contract.py writes into contract.h ("tracer.x:NAME"): the
    contract depends on them as on its imports, though it reads them by name."""
    tree = ast.parse((ROOT / "tracer" / "native" / "contract.py").read_text(encoding="utf-8"))
    return sorted({node.value.split(":")[0] for node in ast.walk(tree)
                   if isinstance(node, ast.Constant) and isinstance(node.value, str)
                   and node.value.startswith("tracer.") and ":" in node.value})


def project_graph() -> dict[str, list[Import]]:
    files = module_files()
    known = set(files) | {_canonical(m) for m in files}
    graph = {module: read_imports(module, path, known) for module, path in files.items()}
    graph["tracer.native.contract"] += [Import(source, 0, False, False) for source in contract_sources()]
    return graph


# -------------------------------------------------------------------------------------- the rules


def _parents(module: str) -> list[str]:
    parts = module.split(".")
    return [".".join(parts[:k]) for k in range(1, len(parts))]


def internal_edges(graph: dict[str, list[Import]]) -> dict[str, list[tuple[str, Import]]]:
    """module -> [(project module it loads, the import)]: the target and the packages Python runs first."""
    out = {}
    for module, imports in graph.items():
        edges = []
        for imp in imports:
            # (the module's own packages have run before it: only the others count)
            implied = [p for p in _parents(imp.target) if not module.startswith(p + ".")]
            edges += [(target, imp) for target in implied + [imp.target] if target in graph and target != module]
        out[module] = edges
    return out


def layer_violations(graph, layers=LAYERS) -> list[str]:
    problems = []
    for module, edges in internal_edges(graph).items():
        mine = layer_of(module, layers)
        if mine is None:
            problems.append(f"{module}: in no layer")
            continue
        for target, imp in edges:
            theirs = layer_of(target, layers)
            if theirs is not None and theirs > mine:
                problems.append(f"{module}:{imp.line} imports {target} ({layers[theirs][0]}), above its layer "
                                f"({layers[mine][0]})")
    return sorted(set(problems))


def cycles(graph) -> list[list[str]]:
    """The import circles: strongly connected components of more than one module (Tarjan, iteratively)."""
    edges = {m: sorted({t for t, _ in e}) for m, e in internal_edges(graph).items()}
    index, low, on_stack, stack, found, counter = {}, {}, set(), [], [], [0]
    for root in sorted(edges):
        if root in index:
            continue
        work = [(root, 0)]
        while work:
            node, i = work.pop()
            if i == 0:
                index[node] = low[node] = counter[0]
                counter[0] += 1
                stack.append(node)
                on_stack.add(node)
            successors = edges.get(node, [])
            if i < len(successors):
                work.append((node, i + 1))
                nxt = successors[i]
                if nxt not in index:
                    work.append((nxt, 0))
                elif nxt in on_stack:
                    low[node] = min(low[node], index[nxt])
                continue
            if work:  # report to the caller
                low[work[-1][0]] = min(low[work[-1][0]], low[node])
            if low[node] == index[node]:
                component = []
                while True:
                    w = stack.pop()
                    on_stack.discard(w)
                    component.append(w)
                    if w == node:
                        break
                if len(component) > 1:
                    found.append(sorted(component))
    return sorted(found)


def uncommented_deferred(graph) -> list[str]:
    return sorted({f"{module}:{imp.line} imports {imp.target} inside a function without a '{DEFERRED_MARK}' comment"
                   for module, imports in graph.items() for imp in imports
                   if imp.deferred and not imp.commented and imp.target.split(".")[0] in ("tracer", "addon")})


def reaches(graph, start: str, patterns) -> Optional[list[str]]:
    """A chain of imports from ``start`` to a module matching ``patterns``, or None."""
    edges = {m: [t for t, _ in e] for m, e in internal_edges(graph).items()}
    before, todo = {start: None}, [start]
    while todo:
        node = todo.pop(0)
        for nxt in edges.get(node, []):
            if nxt not in before:
                before[nxt] = node
                if matches(nxt, patterns):
                    chain = [nxt]
                    while before[chain[-1]] is not None:
                        chain.append(before[chain[-1]])
                    return chain[::-1]
                todo.append(nxt)
    return None


def reference_violations(graph) -> list[str]:
    problems = []
    for module, edges in internal_edges(graph).items():
        if matches(module, REFERENCE):
            problems += [f"{module}:{imp.line} imports {t} (the C core)" for t, imp in edges if matches(t, C_CORE)]
        if matches(module, REFERENCE_ALONE):
            chain = reaches(graph, module, C_CORE)
            if chain:
                problems.append(f"{module} reaches the C core: {' -> '.join(chain)}")
    return sorted(set(problems))


def blender_violations(graph) -> list[str]:
    problems = []
    for module, imports in graph.items():
        for imp in imports:
            top = imp.target.split(".")[0]
            if module.startswith("tracer") and (top in BLENDER or top == "addon"):
                problems.append(f"{module}:{imp.line} imports {imp.target}")
            if matches(module, ("addon.pure", "addon.pure.*")) and (
                    top in BLENDER or (top == "addon" and not matches(imp.target, ("addon.pure", "addon.pure.*")))):
                problems.append(f"{module}:{imp.line} imports {imp.target}")
    return sorted(problems)


# -------------------------------------------------------------------------------------- the real code


@pytest.fixture(scope="module")
def graph():
    return project_graph()


def test_every_module_is_in_a_layer_and_imports_no_higher_layer(graph):
    assert len(graph) > 80 and "tracer.compile" in graph and "addon.pure.blocks" in graph
    assert layer_violations(graph) == []


def test_no_import_circle(graph):
    assert cycles(graph) == []


def test_imports_inside_functions_say_why(graph):
    assert uncommented_deferred(graph) == []


def test_the_numpy_reference_imports_nothing_of_the_c_core(graph):
    assert reference_violations(graph) == []


def test_no_blender_in_the_tracer_nor_in_the_pure_addon(graph):
    assert blender_violations(graph) == []


# -------------------------------------------------------------------------------------- planted violations


def _planted(**imports) -> dict[str, list[Import]]:
    """A small graph: {module: [targets]}, a target ending in '!' imported inside a function uncommented."""
    return {module.replace("_", "."): [Import(t.rstrip("!"), 1, t.endswith("!"), False) for t in targets]
            for module, targets in imports.items()}


PLANTED_LAYERS = (("low", ("p.low", "p.low.*")), ("mid", ("p.mid",)), ("high", ("p.high", "p")))


def test_a_planted_upward_import_is_found():
    ok = _planted(p_low=[], p_mid=["p.low"], p_high=["p.mid", "p.low"], p=[])
    assert layer_violations(ok, PLANTED_LAYERS) == []
    bad = _planted(p_low=["p.mid"], p_mid=[], p_high=[], p=[])
    assert layer_violations(bad, PLANTED_LAYERS) == ["p.low:1 imports p.mid (mid), above its layer (low)"]
    # a submodule's package runs first: importing p.low.x from p.low.y is fine, p.low.x importing p runs p
    nested = _planted(p_low=[], p_low_x=["p"], p_mid=[], p_high=[], p=[])
    assert layer_violations(nested, PLANTED_LAYERS) == ["p.low.x:1 imports p (high), above its layer (low)"]
    assert layer_violations(_planted(p_other=[]), PLANTED_LAYERS) == ["p.other: in no layer"]


def test_a_planted_circle_is_found_also_through_a_deferred_import():
    assert cycles(_planted(a=["b"], b=["c"], c=[])) == []
    assert cycles(_planted(a=["b"], b=["c!"], c=["a"], d=["a"])) == [["a", "b", "c"]]


def test_a_planted_uncommented_deferred_import_is_found():
    graph = _planted(tracer_x=["tracer.y!", "numpy!"], tracer_y=[])
    assert uncommented_deferred(graph) == ["tracer.x:1 imports tracer.y inside a function without a 'deferred:' "
                                           "comment"]
    graph["tracer.x"][0] = Import("tracer.y", 1, True, True)
    assert uncommented_deferred(graph) == []


def test_a_planted_reference_import_of_the_c_core_is_found():
    graph = _planted(tracer_intersect_mesh=["tracer.model"], tracer_model=[], tracer_native=[],
                     tracer_trace=["tracer.compile"], tracer_compile=["tracer.native"])
    assert reference_violations(graph) == []  # trace reaches native through compile: allowed
    graph["tracer.intersect.mesh"].append(Import("tracer.model", 2, False, False))
    graph["tracer.model"].append(Import("tracer.native", 3, False, False))
    assert reference_violations(graph) == [
        "tracer.intersect.mesh reaches the C core: tracer.intersect.mesh -> tracer.model -> tracer.native"]
    graph["tracer.trace"].append(Import("tracer.native", 4, True, True))
    assert "tracer.trace:4 imports tracer.native (the C core)" in reference_violations(graph)


def test_a_planted_blender_import_is_found():
    graph = _planted(addon_pure_x=["numpy", "addon.pure.y", "tracer.model"], addon_pure_y=[], addon_engine=["bpy"])
    assert blender_violations(graph) == []
    graph["addon.pure.y"] += [Import("mathutils", 7, True, False), Import("addon.engine", 8, False, False)]
    graph["tracer.model"] = [Import("bpy", 9, False, False)]
    assert blender_violations(graph) == ["addon.pure.y:7 imports mathutils", "addon.pure.y:8 imports addon.engine",
                                         "tracer.model:9 imports bpy"]


def test_the_reader_sees_relative_deferred_and_vendored_imports(tmp_path):
    path = tmp_path / "m.py"
    path.write_text("from . import b\nfrom .b import thing\nfrom ..tracer import model\n\ndef f():\n"
                    "    # deferred: start-up\n    from .c import x\n    import tracer.d\n    y = 1\n"
                    "    import tracer.e\n")
    known = {"addon.pure.b", "addon.pure.c", "tracer.model", "tracer.d"}
    found = read_imports("addon.pure.m", path, known)
    assert [(i.target, i.deferred, i.commented) for i in found] == [
        ("addon.pure.b", False, False), ("addon.pure.b", False, False), ("tracer.model", False, False),
        ("addon.pure.c", True, True), ("tracer.d", True, True), ("tracer.e", True, False)]
