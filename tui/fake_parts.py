"""What the fake system (`tui.fake.FakeSystem`) is made of.

Each rover's workers (its actors) and their mailbox capacities, the faults
each part takes (actor faults on a worker, device faults on a rover's
devices: the catalogue the console offers), and the supervision tree's nodes
with the `TreeNode` view of them a snapshot carries.
"""

from __future__ import annotations

from dataclasses import dataclass

from tui.snapshot import FaultTarget, TreeNode

__all__ = ["ACTOR_FAULTS", "CAPACITY", "DEVICE_FAULTS", "WORKERS", "Node", "fault_catalogue",
           "tree_view"]

WORKERS = {
    "mapper": ("motor", "lidar", "map", "navigation", "wifly"),
    "hider": ("motor", "navigation", "wifly"),
    "seeker": ("motor", "ir", "navigation", "wifly"),
}
CAPACITY = {"motor": 16, "lidar": 64, "map": 8, "navigation": 16, "wifly": 32, "ir": 16}
DEVICE_FAULTS = {
    "lidar": ("dead", "garbage", "stuck", "noisy"),
    "encoder": ("stuck", "slipping"),
    "motor": ("stall", "weak"),
    "ir": ("stuck_high", "stuck_low"),
    "wifly": ("drop", "loss", "corrupt", "latency"),
}
ACTOR_FAULTS = ("crash", "hang", "flood")


@dataclass(slots=True)
class Node:
    """One node of the fake supervision tree: its state, restarts and last exit."""

    state: str = "running"
    restarts: int = 0
    last_exit: str | None = None
    last_exit_s: float | None = None
    wake_s: float | None = None  # when restarting ends, or when a hang is detected
    hung: bool = False


def fault_catalogue() -> tuple[FaultTarget, ...]:
    """Every fault target of the fake and the kinds it takes: actor faults on each worker,
    device faults on each rover's devices (every rover has encoders)."""
    actors = [FaultTarget(f"{r}/{w}", ACTOR_FAULTS) for r, ws in WORKERS.items() for w in ws]
    devices = [FaultTarget(f"{r}.{d}", DEVICE_FAULTS[d])
               for r, ws in WORKERS.items() for d in ("lidar", "encoder", "motor", "ir",
                                                      "wifly")
               if d in ws or d == "encoder"]
    return tuple(actors + devices)


def tree_view(nodes: dict[str, Node]) -> TreeNode:
    """The supervision tree of ``nodes`` (keyed by name: ``system``, ``server``, ``world``,
    each rover id, each ``rover/worker``) as a snapshot shows it."""
    def node(name: str, kind: str, children: tuple[TreeNode, ...] = ()) -> TreeNode:
        n = nodes[name]
        return TreeNode(name, kind, n.state, n.restarts, n.last_exit,  # type: ignore[arg-type]
                        n.last_exit_s, children)

    rovers = tuple(node(rid, "supervisor",
                        tuple(node(f"{rid}/{w}", "worker") for w in ws))
                   for rid, ws in WORKERS.items())
    return node("system", "supervisor",
                (node("server", "worker"), node("world", "worker")) + rovers)
