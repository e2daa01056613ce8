"""The firmware's shape: parts composed, not inherited; names kept to their class.

Navigation is one actor per rover that owns its parts (localiser, controller,
recovery behaviours, role behaviour; docs/navigation.md), so a class has at most
two project ancestors, and no class reads a private name it does not define.
"""

from __future__ import annotations

import ast
import importlib
import inspect
from pathlib import Path

import pytest

FIRMWARE = Path(__file__).resolve().parents[1] / "actors" / "firmware"
PROJECT = ("actors", "server", "supervisors", "world", "tui", "benchmarks")
MAX_ANCESTORS = 2


def _modules() -> list[Path]:
    return sorted(FIRMWARE.rglob("*.py"))


def _module_name(path: Path) -> str:
    rel = path.relative_to(FIRMWARE.parents[1]).with_suffix("")
    return ".".join(rel.parts).removesuffix(".__init__")


def _project_ancestors(cls: type) -> list[str]:
    return [c.__qualname__ for c in cls.__mro__[1:]
            if c.__module__.split(".")[0] in PROJECT]


def test_no_firmware_class_has_more_than_two_project_ancestors() -> None:
    """Every class defined in ``actors/firmware`` has at most two project classes above
    it (navigation's parts are owned, not mixed in)."""
    deep: list[str] = []
    widest = 0
    for path in _modules():
        module = importlib.import_module(_module_name(path))
        for cls in vars(module).values():
            if inspect.isclass(cls) and cls.__module__ == module.__name__:
                ancestors = _project_ancestors(cls)
                widest = max(widest, len(ancestors))
                if len(ancestors) > MAX_ANCESTORS:
                    deep.append(f"{module.__name__}.{cls.__qualname__}: {ancestors}")
    assert deep == []
    assert widest == MAX_ANCESTORS  # the navigation actors: NavBase, Actor


def test_the_ancestor_count_sees_a_mixin() -> None:
    """The count above is of project classes: a class mixing two project classes into a
    third has three."""
    from actors import Actor  # noqa: PLC0415
    from actors.firmware.nav.base import NavBase  # noqa: PLC0415

    class Mixin:
        pass

    Mixin.__module__ = "actors.firmware.nav.example"
    deep = type("Deep", (Mixin, NavBase), {})
    assert _project_ancestors(deep) == ["test_the_ancestor_count_sees_a_mixin.<locals>.Mixin",
                                        "NavBase", "Actor"]
    assert _project_ancestors(Actor) == []


def _defined(cls: ast.ClassDef) -> set[str]:
    """Names a class body defines: methods, class attributes, attributes it assigns."""
    names: set[str] = set()
    for node in cls.body:
        if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
            names.add(node.name)
        elif isinstance(node, ast.Assign):
            names.update(t.id for t in node.targets if isinstance(t, ast.Name))
        elif isinstance(node, ast.AnnAssign) and isinstance(node.target, ast.Name):
            names.add(node.target.id)
    for node in ast.walk(cls):
        if isinstance(node, ast.Attribute) and isinstance(node.ctx, ast.Store) and \
                isinstance(node.value, ast.Name) and node.value.id == "self":
            names.add(node.attr)
    return names


def foreign_private_reads(source: str) -> list[str]:
    """``Class.name`` for every private attribute (``_x``) a class reads that its own
    body does not define: on ``self`` (one a base defines) or on another object."""
    found: list[str] = []
    for cls in (n for n in ast.walk(ast.parse(source)) if isinstance(n, ast.ClassDef)):
        own = _defined(cls)
        for node in ast.walk(cls):
            if isinstance(node, ast.Attribute) and node.attr.startswith("_") and \
                    not node.attr.startswith("__") and node.attr not in own:
                found.append(f"{cls.name}.{node.attr}")
    return found


def test_no_firmware_class_reads_another_classes_private_names() -> None:
    """A class reads only the private names it defines itself; what its parts and its
    base share is public."""
    reads = {str(p.relative_to(FIRMWARE)): foreign_private_reads(p.read_text())
             for p in _modules()}
    assert {p: r for p, r in reads.items() if r} == {}


@pytest.mark.parametrize("source, reads", [
    ("class A:\n    def f(self):\n        self._x = 1\n        return self._x\n", []),
    ("class B(A):\n    def g(self):\n        return self._x\n", ["B._x"]),
    ("class C:\n    def h(self, nav):\n        return nav._motion\n", ["C._motion"]),
], ids=["own", "inherited", "another-object"])
def test_foreign_private_reads_are_found(source: str, reads: list[str]) -> None:
    """The private-name check finds a read of a base's or another object's private name,
    and lets a class read its own."""
    assert foreign_private_reads(source) == reads
