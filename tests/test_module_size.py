"""Small modules, one idea each: no module over 500 lines and no function over 80, in
every package of the project (``tests/`` aside).

Lines are counted as a reader sees them: a module's lines of text, a function's from
its ``def`` line to its last line (decorators aside), docstring included.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGES = ("actors", "benchmarks", "server", "supervisors", "tui", "world")
MAX_MODULE_LINES = 500
MAX_FUNCTION_LINES = 80


def function_lines(source: str) -> list[tuple[int, str]]:
    """``(lines, name)`` of every function and method in ``source``, nested ones too."""
    return [(n.end_lineno - n.lineno + 1, n.name) for n in ast.walk(ast.parse(source))
            if isinstance(n, ast.FunctionDef | ast.AsyncFunctionDef) and n.end_lineno]


def test_every_project_package_is_checked() -> None:
    """The packages checked are every package at the top of the repository but tests."""
    found = {p.parent.name for p in ROOT.glob("*/__init__.py")} - {"tests"}
    assert found == set(PACKAGES)


@pytest.mark.parametrize("package", PACKAGES)
def test_no_module_over_500_lines_nor_function_over_80(package: str) -> None:
    """No module of ``package`` over 500 lines, no function over 80."""
    modules = sorted((ROOT / package).rglob("*.py"))
    assert modules
    texts = {str(p.relative_to(ROOT)): p.read_text() for p in modules}
    long_modules = {p: len(t.splitlines()) for p, t in texts.items()
                    if len(t.splitlines()) > MAX_MODULE_LINES}
    assert long_modules == {}
    long_functions = [f"{p}: {name} ({n} lines)" for p, t in texts.items()
                      for n, name in function_lines(t) if n > MAX_FUNCTION_LINES]
    assert long_functions == []


def test_function_lines_counts_every_function_from_def_to_last_line() -> None:
    """The count sees methods and nested functions, each from ``def`` to its last line."""
    source = ("def f():\n    x = 1\n    return x\n\n\nclass C:\n    async def m(self):\n"
              "        def inner():\n            pass\n        return inner\n")
    assert sorted(function_lines(source)) == [(2, "inner"), (3, "f"), (4, "m")]
