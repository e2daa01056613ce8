"""The firmware's tunables: few, each a physical quantity or a noise level with its unit,
each documented (issue 17's bound). Read from the source (ast), nothing imported."""

from __future__ import annotations

import ast
import re
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
FIRMWARE = ROOT / "actors" / "firmware"
DOCS = [ROOT / "docs" / name for name in ("navigation.md", "mapping.md", "localisation.md")]
MAX_TUNABLES = 60
_OPTION_CLASS = re.compile(r"(Options|Tuning|Noise)$")


def _option_classes() -> dict[str, ast.ClassDef]:
    """Every dataclass of the firmware named ``*Options``, ``*Tuning`` or ``*Noise``."""
    out: dict[str, ast.ClassDef] = {}
    for path in sorted(FIRMWARE.rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.ClassDef) and _OPTION_CLASS.search(node.name) and any(
                    "dataclass" in ast.unparse(d) for d in node.decorator_list):
                out[f"{path.relative_to(ROOT)}:{node.name}"] = node
    return out


def _fields(cls: ast.ClassDef) -> list[tuple[str, str, str]]:
    """(name, annotation, docstring) of each field of ``cls``."""
    out = []
    for i, stmt in enumerate(cls.body):
        if isinstance(stmt, ast.AnnAssign) and isinstance(stmt.target, ast.Name):
            nxt = cls.body[i + 1] if i + 1 < len(cls.body) else None
            doc = nxt.value.value if isinstance(nxt, ast.Expr) and isinstance(
                nxt.value, ast.Constant) and isinstance(nxt.value.value, str) else ""
            out.append((stmt.target.id, ast.unparse(stmt.annotation), doc))
    return out


def test_the_firmware_has_at_most_60_tunables() -> None:
    """Fields of the firmware's option classes, all together: at most 60."""
    classes = _option_classes()
    assert len(classes) >= 10  # the scan found the option classes
    counts = {name: len(_fields(cls)) for name, cls in classes.items()}
    assert sum(counts.values()) <= MAX_TUNABLES, counts


def test_every_tunable_states_its_unit() -> None:
    """Each field's docstring names its unit in brackets (``[cm]``, ``[1]``); a field that
    holds another option class (a group of noise levels) is exempt."""
    nested = {cls.name for cls in _option_classes().values()}
    missing = [f"{where}.{name}" for where, cls in _option_classes().items()
               for name, annotation, doc in _fields(cls)
               if annotation not in nested and not re.search(r"\[[^\]]+\]", doc)]
    assert missing == []


def test_every_tunable_is_in_a_parameter_table_of_the_docs() -> None:
    """Each field is named in docs/navigation.md, docs/mapping.md or
    docs/localisation.md."""
    text = "\n".join(p.read_text(encoding="utf-8") for p in DOCS)
    missing = [f"{where}.{name}" for where, cls in _option_classes().items()
               for name, _, _ in _fields(cls)
               if not re.search(rf"`[^`\n]*\b{re.escape(name)}\b[^`\n]*`", text)]
    assert missing == []
