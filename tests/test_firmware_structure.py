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


def _imported(path: Path) -> set[str]:
    """The modules a file imports (top level and inside functions)."""
    names: set[str] = set()
    for node in ast.walk(ast.parse(path.read_text())):
        if isinstance(node, ast.ImportFrom) and node.module:
            names.add(node.module)
        elif isinstance(node, ast.Import):
            names.update(a.name for a in node.names)
    return names


def test_localisation_does_not_import_mapping() -> None:
    """Map Management (``mapping``) uses the localisers (``localisation``), never the
    other way round: the two packages do not import each other both ways."""
    back = {str(p.relative_to(FIRMWARE)): sorted(m for m in _imported(p)
                                                if m.startswith("actors.firmware.mapping"))
            for p in (FIRMWARE / "localisation").rglob("*.py")}
    assert {p: m for p, m in back.items() if m} == {}
    forward = set().union(*(_imported(p) for p in (FIRMWARE / "mapping").rglob("*.py")))
    assert "actors.firmware.localisation.mapper_localiser" in forward


def test_one_notion_of_a_usable_hit() -> None:
    """Scan matching's usable hits are the scan likelihood's (`scan_hits`)."""
    from actors.firmware import scan_hits  # noqa: PLC0415
    from actors.firmware.mapping import scan_match  # noqa: PLC0415
    from actors.firmware.mapping.sensor_model import LogOddsModel  # noqa: PLC0415

    assert scan_match.MIN_POINTS == scan_hits.MIN_POINTS
    assert scan_match.MAX_RANGE_CM == scan_hits.MAX_RANGE_CM == LogOddsModel().max_range_cm
    assert scan_match.MatchOptions().min_range_cm == scan_hits.MIN_RANGE_CM
