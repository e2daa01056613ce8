"""Views of a running `SimSystem` for the console's snapshot: map, truth, rovers, tables.

Each function reads one part of the system (the mapper's grid or the server's
map, the world's ground truth, the server's rovers and links, the runtime's
mailboxes and supervision tree, the world's faults and the fault catalogue)
and returns the plain records of `tui.snapshot`. Ground truth is read here only
for the overlay and the rovers' true poses.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from server.protocol import ROLES, inverse
from server.protocol import Pose as FramePose
from server.protocol import compose as compose_pose
from supervisors.system import SimSystem
from world.faults import ACTOR_FAULTS, DEVICE_FAULTS, ROLE_DEVICES
from world.scenario import Scenario
from world.truth import truth_raster

from .snapshot import (
    ActiveFault,
    FaultTarget,
    GridView,
    LinkStats,
    Pose,
    QueueStats,
    RoverView,
    TreeNode,
)

__all__ = ["map_view", "TruthOverlay", "rover_views", "QueueRates", "tree_view", "link_stats",
           "active_faults", "fault_catalogue", "snapshot_pose"]

_MAP_MARGIN_CELLS = 20  # unknown border shown around the known map [cells]


def snapshot_pose(p: FramePose | None) -> Pose | None:
    """A protocol pose as the snapshot's (None stays None)."""
    return None if p is None else Pose(p.x, p.y, p.heading_deg)


def map_view(system: SimSystem) -> GridView | None:
    """The mapper's working grid (cropped to the known room), else the server's map."""
    snap = system.mapper_grid()
    if snap is None:
        grid = system.server.game.map
        if grid is None:
            return None
        return GridView(np.array(grid.cells, np.int8), grid.resolution_cm,
                        tuple(grid.origin_cm))
    snap = snap.crop_known(margin_cells=_MAP_MARGIN_CELLS)  # the room, not 24 m of nothing
    return GridView(np.array(snap.cells, np.int8), snap.resolution_cm, tuple(snap.origin_cm))


class TruthOverlay:
    """Ground truth resampled onto the map's raster (same frame and cells), kept until
    the map's raster changes.

    Args:
        scenario: the room whose truth is drawn.
    """

    def __init__(self, scenario: Scenario) -> None:
        self.scenario = scenario
        self._truth: GridView | None = None
        self._truth_raster: Any = None
        self._truth_key: tuple | None = None

    def view(self, grid: GridView | None, mapper_room: FramePose) -> GridView | None:
        """The truth on ``grid``'s raster; ``mapper_room`` is the map frame's origin in
        the room (the mapper's start)."""
        if grid is None:
            return None
        key = (grid.shape, grid.origin_cm, grid.resolution_cm)
        if key != self._truth_key:
            if self._truth_raster is None:
                self._truth_raster = truth_raster(self.scenario, grid.resolution_cm)
            truth = self._truth_raster
            ny, nx = grid.shape
            x0, y0 = grid.origin_cm
            r = grid.resolution_cm
            xs = x0 + (np.arange(nx) + 0.5) * r
            ys = y0 + (np.arange(ny) + 0.5) * r
            mx, my = np.meshgrid(xs, ys)
            m = mapper_room
            h = math.radians(m.heading_deg)
            rx = m.x + math.cos(h) * mx - math.sin(h) * my
            ry = m.y + math.sin(h) * mx + math.cos(h) * my
            col = np.floor(rx / truth.resolution_cm).astype(int)
            row = np.floor(ry / truth.resolution_cm).astype(int)
            th, tw = truth.occupied.shape
            inside = (row >= 0) & (row < th) & (col >= 0) & (col < tw)
            cells = np.full((ny, nx), 100, np.int8)
            occ = truth.occupied[np.clip(row, 0, th - 1), np.clip(col, 0, tw - 1)]
            cells[inside & ~occ] = 0
            self._truth = GridView(cells, r, grid.origin_cm)
            self._truth_key = key
        return self._truth


def rover_views(system: SimSystem, server: Any, scenario: Scenario, remote: dict[str, Any],
                mapper_room: FramePose) -> tuple[RoverView, ...]:
    """Each role's rover: reported pose, true pose (simulated ones only) and link."""
    to_map = inverse(mapper_room)
    views = {r.role: r for r in server.rovers}
    out = []
    for role in ROLES:
        view = views.get(role)
        if role in remote:  # its true pose is in another world
            out.append(RoverView(role, role, snapshot_pose(view.pose if view else None), None,
                                 link=view.link if view else remote[role].text))
            continue
        t = system.world.true_pose(role)
        true = compose_pose(to_map, FramePose(t.x, t.y, t.heading_deg))
        pose = view.pose if view is not None and view.pose is not None else None
        if pose is None:  # before its first report: where the operator placed it
            start = scenario.starts[role]
            pose = compose_pose(to_map, FramePose(start.x, start.y, start.heading_deg))
        out.append(RoverView(role, role, snapshot_pose(pose), snapshot_pose(true),
                             link=view.link if view else "memory"))
    return tuple(out)


class QueueRates:
    """Mailbox statistics with each queue's receive rate, measured over at least 1 s."""

    def __init__(self) -> None:
        self._rates: dict[str, tuple[float, int, float]] = {}  # name -> (t, received, rate)

    def stats(self, system: SimSystem, now: float) -> tuple[QueueStats, ...]:
        """Every rover actor's mailbox now [s]."""
        out = []
        for name in system.actors.names():
            if "/" not in name:
                continue
            s = system.actors.statistics(name)
            t0, r0, rate = self._rates.get(name, (now, s.received, 0.0))
            if now - t0 >= 1.0:
                rate = (s.received - r0) / (now - t0)
                t0, r0 = now, s.received
            self._rates[name] = (t0, r0, rate)
            out.append(QueueStats(name.split("/")[0], name, s.depth, s.capacity, rate,
                                  s.dropped))
        return tuple(out)


def tree_view(system: SimSystem, exits: dict[str, float]) -> TreeNode:
    """The supervision trees under one ``system`` node; ``exits``: actor -> last exit [s]."""
    def convert(node: Any) -> TreeNode:
        state = str(node.state)
        state = {"starting": "restarting"}.get(state, state)
        return TreeNode(node.name, str(node.kind), state, node.restarts,  # type: ignore[arg-type]
                        None if node.last_exit is None else str(node.last_exit),
                        exits.get(node.name),
                        tuple(convert(c) for c in node.children))
    roots = tuple(convert(n) for n in system.tree_snapshots())
    return TreeNode("system", "supervisor", "running", 0, None, None, roots)


def link_stats(server: Any) -> tuple[LinkStats, ...]:
    """Each rover's link as the server counts it (round trip in ms)."""
    out = []
    for r in server.rovers:
        s = r.stats
        out.append(LinkStats(r.id, s.up, None if s.rtt_s is None else s.rtt_s * 1000.0,
                             s.lost, s.resent, s.bad_frames, s.frames_in, s.frames_out))
    return tuple(out)


def active_faults(system: SimSystem) -> tuple[ActiveFault, ...]:
    """The world's faults in force now."""
    out = []
    for f in system.world.active_faults():
        until = f.start_s + f.duration_s if f.duration_s > 0 else None
        out.append(ActiveFault(f"w{f.id}", f.target, f.kind, f.start_s, until))
    return tuple(out)


def fault_catalogue(system: SimSystem, remote: dict[str, Any]) -> tuple[FaultTarget, ...]:
    """Every target with every fault the catalogue has for it: a device and the
    actor that drives it share a name (``mapper/lidar``) and so one entry."""
    kinds: dict[str, dict[str, dict[str, float]]] = {}
    for role in ROLES:
        if role in remote:
            continue
        for device, device_kinds in DEVICE_FAULTS.items():
            if role in ROLE_DEVICES.get(device, ROLES):
                kinds[f"{role}/{device}"] = dict(device_kinds)
    for name in system.actors.names():
        if "/" in name and name.split("/")[0] not in remote:
            kinds.setdefault(name, {}).update(ACTOR_FAULTS)
    return tuple(FaultTarget(target, tuple(by_kind),
                             {k: dict(p) for k, p in by_kind.items() if p})
                 for target, by_kind in kinds.items())
