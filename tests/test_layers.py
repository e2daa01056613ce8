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


#: the modules outside tui/ that join world and server into a system: the
#: simulated system tree, the remote-rover wiring and its fault port (faults
#: over the link into its world), the test harness and the recorder (a module,
#: or every module under a package path ending in ``/``)
WIRING = ("supervisors/system.py", "supervisors/remote.py", "supervisors/rover_fault_port.py",
          "supervisors/harness/", "supervisors/recording/")

#: the one firmware module the world may import: the device contract it implements
DEVICE_CONTRACT = "actors.firmware.hardware"

#: the OTP supervisor itself: domain-free, these modules import the actor runtime
#: and each other only
DOMAIN_FREE_SUPERVISORS = ("supervisors/__init__.py", "supervisors/supervisor.py",
                           "supervisors/children.py", "supervisors/restart.py",
                           "supervisors/spec.py", "supervisors/state.py", "supervisors/dynamic.py")


def _is_domain_free_supervisor(module: str) -> bool:
    """Whether ``module`` (or the name imported from it) is one of `DOMAIN_FREE_SUPERVISORS`."""
    package_module = "/".join(module.split(".")[:2])
    return module == "supervisors" or f"{package_module}.py" in DOMAIN_FREE_SUPERVISORS


def is_wiring(rel: str) -> bool:
    """Whether the file at repository path ``rel`` is one of the `WIRING` modules."""
    return any(rel == w or (w.endswith("/") and rel.startswith(w)) for w in WIRING)


def violation(layer: str, module: str, wiring: bool = False,
              domain_free: bool = False) -> str | None:
    """Why ``layer`` may not import ``module``, or None when it may.

    Args:
        layer: the importing file's layer (`layer_of`).
        module: the absolute module name imported.
        wiring: the importing file is one of the `WIRING` modules.
        domain_free: the importing file is one of `DOMAIN_FREE_SUPERVISORS`.
    """
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
        if target in ("world", "supervisors"):
            return f"firmware never imports {target}"
        if target == "server" and not (
            module == "server" or module == "server.protocol"
            or module.startswith("server.protocol.")
        ):
            return "firmware imports of server are only the pure codec server.protocol"
    if layer == "server" and target in ("world", "firmware", "supervisors"):
        return f"the server never imports {target}"
    if layer == "world":
        if target in ("server", "supervisors"):
            return f"the world never imports {target}"
        if target == "firmware" and not (module == DEVICE_CONTRACT
                                         or module.startswith(DEVICE_CONTRACT + ".")):
            return f"of the firmware the world imports only the device contract {DEVICE_CONTRACT}"
    if layer == "supervisors":
        if domain_free and target != "runtime" and not _is_domain_free_supervisor(module):
            return "the supervisor itself is domain-free: it imports the actor runtime only"
        if target in ("world", "server") and not wiring:
            return f"only {', '.join(WIRING)} join {target} into a system"
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
        rel = path.relative_to(ROOT).as_posix()
        why = violation(layer, module, is_wiring(rel), rel in DOMAIN_FREE_SUPERVISORS)
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
        ("world", "actors.firmware.hardware", True),
        ("world", "actors.firmware", False),
        ("world", "actors.firmware.drivers.isr", False),
        ("world", "actors.firmware.hardwarex", False),
        ("world", "server.protocol", False),
        ("firmware", "supervisors.rover", False),
        ("supervisors", "tui.app", False),
        ("tui", "world.scenario", True),
        ("supervisors", "world.physics", False),
        ("supervisors", "server.store", False),
        ("supervisors", "actors.firmware.drivers.motor", True),
    ],
)
def test_rule_checker_itself(layer: str, module: str, allowed: bool) -> None:
    """The checker flags what the rules forbid and lets pass what they allow."""
    assert (violation(layer, module) is None) is allowed


@pytest.mark.parametrize(
    ("rel", "wiring"),
    [
        ("supervisors/system.py", True),
        ("supervisors/remote.py", True),
        ("supervisors/harness/headless.py", True),
        ("supervisors/recording/mcap.py", True),
        ("supervisors/rover.py", False),
        ("supervisors/supervisor.py", False),
        ("supervisors/systemx.py", False),
    ],
)
def test_only_the_named_wiring_modules_join_world_and_server(rel: str, wiring: bool) -> None:
    """The wiring allowance names its modules; the rover tree is not one of them."""
    assert is_wiring(rel) is wiring
    assert (violation("supervisors", "world.world", is_wiring(rel)) is None) is wiring


def test_the_supervisor_itself_imports_only_the_runtime() -> None:
    assert violation("supervisors", "actors.mailbox", domain_free=True) is None
    assert violation("supervisors", "actors.firmware.commands", domain_free=True) is not None
