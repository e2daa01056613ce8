"""Hiding navigation: check the spot, drive there around obstacles, report arrival.

Flow (`Hide` is the role behaviour of `route_nav.RouteNav`, which handles map,
origin and destination)::

    idle --start--> waiting_map (map_request) --map--> ready
    ready --destination--> check_spot
        invalid: ``invalid_spot {reason}``, ready again
        valid:   driving (A* + ADP loop, replanning when blocked)
                 --at the spot, turned to the heading--> hidden: ``arrived {pose}``
                 --cannot reach--> ``invalid_spot {reason}``, ready again

The spot check is `clearance.check_spot` on the server's map: the disc swept
by the body turning in place, plus ``spot_margin_cm``, must touch no occupied
and no unknown cell. The route ends within ``goal_tol_cm`` of the spot and
``heading_tol_deg`` of the heading, by dead reckoning.

Near enough
    The map is the mapper's, made by dead reckoning and scan matching; a spot a
    few cm from a wall can fall on a wall cell, or next to a few unmapped cells,
    though the rover fits there ("32 unmapped cells within 12.5 cm", "obstacle
    0.0 cm from the spot" on a smeared map). And a
    hider that reached its spot's surroundings may be stopped a few cm short by
    its own dead-reckoning error. Neither must end the game unhidden. A spot that
    does not fit moves to the nearest place within ``hide_within_cm`` that does
    (and can be planned to); a hider blocked for good within ``hide_within_cm`` of
    its spot, with nothing mapped between, hides where it stands. Either way
    ``arrived`` carries where the hider believes it stopped, as always, so the
    server knows; 30 cm is half the seeker's IR reach (60 cm), so a seeker at the
    spot still has it in range.

Frame: destination and reports in the map frame [cm, deg].
"""

from __future__ import annotations

import math

from actors.firmware.nav.role import RoleBehaviour
from actors.firmware.planning.clearance import check_spot
from server.protocol.grid_map import OCCUPIED

__all__ = ["Hide"]

_SHIFT_STEP_CM = 5.0  # rings around a spot that does not fit, this far apart [cm]
_SHIFT_BEARINGS = 16  # places tried on each ring
_SHIFT_TRIES = 4  # fitting places planned to, nearest first, before giving up


class Hide(RoleBehaviour):
    """The hider's role behaviour (its actor is registered as ``hider/nav``)."""

    def _spot_fits(self, x: float, y: float, heading: float | None) -> tuple[bool, str]:
        assert self.nav.map is not None
        return check_spot(self.nav.map.cells, self.nav.map.resolution_cm, self.nav.map.origin_cm,
                          x, y, 0.0 if heading is None else heading,
                          self.nav.length_cm, self.nav.width_cm, self.nav.o.spot_margin_cm)

    def near_spots(self, x: float, y: float, heading: float | None) -> list[tuple[float, float]]:
        """Places within ``hide_within_cm`` of (x, y) where the rover fits: the nearest ring
        first (every ``_SHIFT_STEP_CM``), on a ring the place nearest the rover first."""
        out: list[tuple[float, float]] = []
        here = (self.nav.map_pose.x, self.nav.map_pose.y)
        r = _SHIFT_STEP_CM
        while r <= self.nav.o.hide_within_cm + 1e-9:
            ring = []
            for k in range(_SHIFT_BEARINGS):
                a = 2.0 * math.pi * k / _SHIFT_BEARINGS
                p = (x + r * math.cos(a), y + r * math.sin(a))
                if self._spot_fits(*p, heading)[0]:
                    ring.append(p)
            out += sorted(ring, key=lambda q: math.dist(q, here))
            r += _SHIFT_STEP_CM
        return out

    async def on_goal(self, x: float, y: float, heading: float | None) -> None:
        assert self.nav.map is not None
        ok, reason = self._spot_fits(x, y, heading)
        if ok:
            if not await self.nav.goto((x, y), heading):
                await self._refuse(x, y, f"no path from here to ({x:.0f}, {y:.0f})")
            return
        for p in self.near_spots(x, y, heading)[:_SHIFT_TRIES]:
            if await self.nav.goto(p, heading):
                self.nav.counters["spot_moved"] = self.nav.counters.get("spot_moved", 0) + 1
                await self.nav.status(self.nav.state,
                                      f"({x:.0f}, {y:.0f}) does not fit ({reason}); "
                                  f"hiding {math.dist(p, (x, y)):.0f} cm from it at "
                                  f"({p[0]:.0f}, {p[1]:.0f})")
                return
        await self._refuse(x, y, reason)

    async def _refuse(self, x: float, y: float, reason: str) -> None:
        self.nav.answered()
        await self.nav.report("invalid_spot", {"reason": reason})
        await self.nav.set_state("ready", f"refused ({x:.0f}, {y:.0f}): {reason}")

    async def on_arrived(self) -> None:
        await self._hide_here("at the spot")

    async def _hide_here(self, detail: str) -> None:
        """Hidden where it stands: ``arrived`` with the pose it believes it has."""
        self.nav.answered()
        await self.nav.report("arrived", self.nav.pose_data())
        await self.nav.set_state("hidden", detail)

    def near_enough(self) -> bool:
        """Within ``hide_within_cm`` of the goal by dead reckoning, and no occupied cell of
        the map on the line between (a spot behind a wall is not near)."""
        if self.nav.goal is None or self.nav.map is None:
            return False
        p = self.nav.map_pose
        d = math.dist((p.x, p.y), self.nav.goal)
        if d > self.nav.o.hide_within_cm:
            return False
        grid = self.nav.map
        gx, gy = self.nav.goal
        n = max(1, math.ceil(d / (0.5 * grid.resolution_cm)))
        for i in range(n + 1):
            t = i / n
            r, c = grid.world_to_cell(p.x + t * (gx - p.x), p.y + t * (gy - p.y))
            if grid.contains(r, c) and grid.cells[r, c] >= OCCUPIED // 2:
                return False
        return True

    async def on_route_failed(self, reason: str) -> None:
        if self.near_enough():
            assert self.nav.goal is not None
            p = self.nav.map_pose
            await self._hide_here(f"{reason}; hiding here, "
                                  f"{math.dist((p.x, p.y), self.nav.goal):.0f} cm from the spot")
            return
        reason = f"cannot reach the spot: {reason}"
        self.nav.answered()
        await self.nav.report("invalid_spot", {"reason": reason})
        await self.nav.set_state("ready", reason)
