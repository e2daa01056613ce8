"""Hiding navigation: check the spot, drive there around obstacles, report arrival.

Flow (see `nav_common.RouteNav` for map, origin and destination handling)::

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

Frame: destination and reports in the map frame [cm, deg].
"""

from __future__ import annotations

from actors.firmware.clearance import check_spot
from actors.firmware.nav_common import RouteNav

__all__ = ["HidingNav"]


class HidingNav(RouteNav):
    """The hider's navigation actor (registered as ``hider/nav``)."""

    role = "hider"

    async def on_goal(self, x: float, y: float, heading: float | None) -> None:
        assert self.map is not None
        ok, reason = check_spot(self.map.cells, self.map.resolution_cm, self.map.origin_cm,
                                x, y, 0.0 if heading is None else heading,
                                self.length_cm, self.width_cm, self.o.spot_margin_cm)
        if not ok:
            self.answered()
            await self.report("invalid_spot", {"reason": reason})
            await self.set_state("ready", f"refused ({x:.0f}, {y:.0f}): {reason}")
            return
        if not await self.goto((x, y), heading):
            reason = f"no path from here to ({x:.0f}, {y:.0f})"
            self.answered()
            await self.report("invalid_spot", {"reason": reason})
            await self.set_state("ready", reason)

    async def on_arrived(self) -> None:
        self.answered()
        await self.report("arrived", self.pose_data())
        await self.set_state("hidden", "at the spot")

    async def on_route_failed(self, reason: str) -> None:
        reason = f"cannot reach the spot: {reason}"
        self.answered()
        await self.report("invalid_spot", {"reason": reason})
        await self.set_state("ready", reason)
