"""The layer rules of DESIGN.md section 1, checked on every module's imports."""

from __future__ import annotations

import ast
import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parent.parent
PACKAGES = ("actors", "supervisors", "world", "server", "tui")


def layer_of(path: pathlib.Path) -> str:
    rel = path.relative_to(ROOT).parts
    if rel[:2] == ("actors", "firmware"):
        return "firmware"
    if rel[0] == "actors":
        return "runtime"
    return rel[0]


def imported_modules(path: pathlib.Path) -> list[tuple[int, str]]:
    """Absolute module names imported by a file (relative imports resolved)."""
    tree = ast.parse(path.read_text(), filename=str(path))
    package = list(path.relative_to(ROOT).with_suffix("").parts[:-1])
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - node.level + 1]
                mod = ".".join(base + ([node.module] if node.module else []))
            else:
                mod = node.module or ""
            found.append((node.lineno, mod))
            # `from server import protocol` imports server.protocol
            found += [(node.lineno, f"{mod}.{a.name}") for a in node.names]
    return found


#: the modules outside tui/ that wire world, server and rovers together
#: (a path ending in "/" names every module of that package)
WIRING_MODULES = ("supervisors/system.py", "supervisors/harness/headless.py",
                  "supervisors/harness/campaign/", "supervisors/harness/shrink/",
                  "supervisors/harness/invariants.py",
                  "supervisors/remote.py")


def violation(layer: str, module: str, wiring: bool = False) -> str | None:
    """Why ``layer`` may not import ``module``, or None when it may."""
    top = module.split(".")[0]
    if top not in PACKAGES:
        return None
    target = "firmware" if module.startswith("actors.firmware") else (
        "runtime" if top == "actors" else top)
    if target == "tui" and layer != "tui":
        return "nothing but tui imports tui"
    if layer == "runtime" and target != "runtime":
        return "the actor runtime imports nothing of the project"
    if layer == "firmware":
        if target == "world":
            return "firmware never imports world"
        if target == "server" and not (
            module == "server" or module == "server.protocol"
            or module.startswith("server.protocol.")
        ):
            return "firmware imports of server are only the pure codec server.protocol"
    if layer == "server" and target in ("world", "firmware", "supervisors"):
        return f"the server never imports {target}"
    if layer == "world" and target in ("firmware", "server", "supervisors"):
        return f"the world never imports {target}"
    if layer == "supervisors" and target in ("world", "server") and not wiring:
        return f"only {' and '.join(WIRING_MODULES)} wire {target} into the system"
    return None


def all_modules() -> list[pathlib.Path]:
    return sorted(p for pkg in PACKAGES for p in (ROOT / pkg).rglob("*.py"))


@pytest.mark.parametrize("path", all_modules(), ids=lambda p: str(p.relative_to(ROOT)))
def test_module_respects_layer_rules(path: pathlib.Path) -> None:
    """No module imports a layer it must not."""
    layer = layer_of(path)
    bad = []
    for lineno, module in imported_modules(path):
        if module in ("server", "actors"):  # bare package: judged by its imported names
            continue
        rel = str(path.relative_to(ROOT))
        wiring = any(rel == w or (w.endswith("/") and rel.startswith(w)) for w in WIRING_MODULES)
        why = violation(layer, module, wiring)
        if why:
            bad.append(f"{path.relative_to(ROOT)}:{lineno} imports {module}: {why}")
    assert not bad, "\n".join(bad)


@pytest.mark.parametrize(
    ("layer", "module", "allowed"),
    [
        ("firmware", "world.physics", False),
        ("firmware", "server.protocol", True),
        ("firmware", "server.game", False),
        ("server", "world", False),
        ("runtime", "supervisors", False),
        ("world", "actors.mailbox", True),
        ("world", "actors.firmware.hardware", False),
        ("supervisors", "tui.app", False),
        ("tui", "world.scenario", True),
        ("supervisors", "world.physics", False),
    ],
)
def test_rule_checker_itself(layer: str, module: str, allowed: bool) -> None:
    """The checker flags what the rules forbid and lets pass what they allow."""
    assert (violation(layer, module) is None) is allowed
