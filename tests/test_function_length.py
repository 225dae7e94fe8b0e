"""No Python function of tracer/ or addon/ is longer than MAX_LINES lines (docs/contributing.md): a longer one
does several jobs, which read better as functions of their own.  ``python tests/test_function_length.py``
lists the longest ones."""
from __future__ import annotations

import ast
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
MAX_LINES = 100


def function_lengths(source: str, name: str) -> list[tuple[int, str]]:
    """(lines, "name:line qualified.name") of every function and method in ``source``, decorators and
    docstring included, nested ones counted on their own too."""
    out = []

    def visit(node, prefix: str) -> None:
        for child in ast.iter_child_nodes(node):
            if isinstance(child, (ast.FunctionDef, ast.AsyncFunctionDef, ast.ClassDef)):
                qualified = f"{prefix}{child.name}"
                if not isinstance(child, ast.ClassDef):
                    first = min([child.lineno] + [d.lineno for d in child.decorator_list])
                    out.append((child.end_lineno - first + 1, f"{name}:{child.lineno} {qualified}"))
                visit(child, qualified + ".")
            else:
                visit(child, prefix)

    visit(ast.parse(source), "")
    return out


def project_functions() -> list[tuple[int, str]]:
    found = []
    for package in ("tracer", "addon"):
        for path in sorted((ROOT / package).rglob("*.py")):
            rel = path.relative_to(ROOT)
            if "__pycache__" in rel.parts or rel.parts[:2] == ("addon", "tracer"):  # (the link to tracer/)
                continue
            found += function_lengths(path.read_text(encoding="utf-8"), rel.as_posix())
    return sorted(found, reverse=True)


def test_no_function_is_longer_than_the_limit():
    functions = project_functions()
    assert len(functions) > 1000  # (the walk found the code)
    assert [f"{where}: {lines} lines" for lines, where in functions if lines > MAX_LINES] == []


def test_the_lengths_are_counted_as_a_reader_sees_them():
    body = "\n".join(f"    x = {k}" for k in range(MAX_LINES))
    source = (f"@decorated\ndef long():\n{body}\n\n\nclass C:\n    def short(self):\n        def inner():\n"
              f"            return 1\n        return inner\n")
    lengths = dict((where, lines) for lines, where in function_lengths(source, "m.py"))
    assert lengths == {"m.py:2 long": MAX_LINES + 2, f"m.py:{MAX_LINES + 6} C.short": 4,
                       f"m.py:{MAX_LINES + 7} C.short.inner": 2}


if __name__ == "__main__":
    for lines, where in project_functions()[:int(sys.argv[1]) if len(sys.argv) > 1 else 10]:
        print(f"{lines:5d}  {where}")
