"""Views of attached rovers for the console's snapshot, from what they stream to the server.

An attached rover's mailboxes, supervision tree, working map and events are
not in this process: the server holds the newest telemetry of each
(`server.rover_telemetry`). These functions turn it into the same records
`tui.sim_views` makes for simulated rovers, so the Queues, Tree and map panes
show both alike. Telemetry older than `STALE_S` is marked with its age (the
rover's name reads ``mapper (telemetry 12 s old)``). The fault catalogue of an
attached rover is what its hello advertised plus the server's link faults.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from server.link_faults import LINK_FAULTS, LINK_TARGET

from .snapshot import ActiveFault, FaultTarget, GridView, QueueStats, TreeNode

__all__ = ["STALE_S", "attached_queues", "attached_trees", "attached_map",
           "attached_catalogue", "attached_faults", "stale_label"]

STALE_S = 3.0
"""Telemetry older than this is marked with its age [s]."""
_MAP_MARGIN_CELLS = 20  # unknown border shown around the known map [cells]


def _attached(server: Any, remote: dict[str, Any]) -> list[Any]:
    return [r for r in server.rovers if r.role in remote and r.telemetry is not None]


def stale_label(role: str, ages: dict[str, float], stream: str) -> str:
    """``role``, or ``role (telemetry N s old)`` when the stream's newest frame is stale."""
    age = ages.get(stream)
    if age is None or age <= STALE_S:
        return role
    return f"{role} (telemetry {age:.0f} s old)"


def attached_queues(server: Any, remote: dict[str, Any]) -> tuple[QueueStats, ...]:
    """Each attached rover's mailboxes from its newest ``tm_mailboxes``."""
    out = []
    for r in _attached(server, remote):
        tm = r.telemetry
        label = stale_label(r.role, tm.ages, "mailboxes")
        for name, depth, capacity, rate, drops in tm.mailboxes:
            out.append(QueueStats(label, f"{r.role}/{name}", depth, capacity, rate, drops))
    return tuple(out)


def attached_trees(server: Any, remote: dict[str, Any]) -> tuple[TreeNode, ...]:
    """Each attached rover's supervision tree from its newest ``tm_tree`` (a node's
    parent is the longest other path its own extends, else the first node)."""
    out = []
    for r in _attached(server, remote):
        tm = r.telemetry
        if tm.tree:
            out.append(_tree(tm.tree, stale_label(tm.tree[0][0], tm.ages, "tree")))
    return tuple(out)


def _tree(rows: tuple[tuple[Any, ...], ...], root_label: str) -> TreeNode:
    by_path = {row[0]: row for row in rows}
    order = [row[0] for row in rows]
    root = order[0]
    kids: dict[str, list[str]] = {}
    for path in order[1:]:
        parent = max((p for p in order if p != path and path.startswith(p + "/")),
                     key=len, default=root)
        kids.setdefault(parent, []).append(path)

    def build(path: str, name: str | None = None) -> TreeNode:
        _, kind, state, restarts, last_exit = by_path[path]
        return TreeNode(name or path, kind, state, restarts, last_exit, None,
                        tuple(build(c) for c in kids.get(path, ())))
    return build(root, root_label)


def attached_map(server: Any, remote: dict[str, Any]) -> GridView | None:
    """The attached mapper's working map from its ``tm_map`` deltas (None without one)."""
    if "mapper" not in remote:
        return None
    for r in _attached(server, remote):
        if r.role == "mapper" and r.telemetry.map is not None:
            grid = r.telemetry.map
            if not (grid.cells >= 0).any():
                return None
            grid = grid.crop_known(margin_cells=_MAP_MARGIN_CELLS)
            return GridView(np.array(grid.cells, np.int8), grid.resolution_cm,
                            tuple(grid.origin_cm))
    return None


def attached_catalogue(server: Any, remote: dict[str, Any]) -> tuple[FaultTarget, ...]:
    """Each attached rover's advertised faults, then its link's, as catalogue entries."""
    kinds: dict[str, dict[str, dict[str, float]]] = {}
    for r in server.rovers:
        if r.role not in remote:
            continue
        for entry in r.faults:
            target, _, kind = entry.partition("/")
            params = LINK_FAULTS.get(kind, {}) if target == LINK_TARGET else {}
            kinds.setdefault(f"{r.role}/{target}", {})[kind] = dict(params)
        kinds.setdefault(f"{r.role}/{LINK_TARGET}", {k: dict(p) for k, p in LINK_FAULTS.items()})
    return tuple(FaultTarget(t, tuple(by_kind), {k: p for k, p in by_kind.items() if p})
                 for t, by_kind in kinds.items())


def attached_faults(server: Any, remote: dict[str, Any]) -> tuple[ActiveFault, ...]:
    """The link faults in force on attached rovers (``mapper/link``)."""
    out = []
    for role in remote:
        for f in server.link_faults_of(role):
            until = f.start_s + f.duration_s if f.duration_s > 0 else None
            out.append(ActiveFault(f"{role}/{LINK_TARGET}", f"{role}/{LINK_TARGET}", f.kind,
                                   f.start_s, until))
    return tuple(out)
