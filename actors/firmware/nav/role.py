"""The role behaviour of the hider's and seeker's navigation: what sets the goals.

`RoleBehaviour` is the interface `route_nav.RouteNav` calls: the destination
came (`on_goal`), the route arrived, failed or was blocked, a motion outside a
route ended, the timer ticked, the IR sensor decided. Each role (`hider.Hide`,
`seeker.Seek`) is one subclass; what it may use of the actor is its public
names (`goto`, `map_pose`, `report`, ...).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from actors.firmware.nav.route import Motion

if TYPE_CHECKING:
    from actors.firmware.nav.route_nav import RouteNav

__all__ = ["RoleBehaviour"]


class RoleBehaviour:
    """A role's goals and answers (see the module docstring); every hook does nothing
    by default.

    Args:
        nav: the navigation actor it drives.
    """

    def __init__(self, nav: RouteNav) -> None:
        self.nav = nav

    async def on_goal(self, x: float, y: float, heading: float | None) -> None:
        """Map, origin and destination are known: act on the destination (map frame
        [cm, deg])."""

    async def on_arrived(self) -> None:
        """The route reached its goal (and heading)."""

    async def on_route_failed(self, reason: str) -> None:
        """The route's goal could not be reached, for ``reason``."""

    async def on_blocked(self) -> bool:
        """The route is blocked; True when the role handled it (no recovery)."""
        return False

    async def after_other_motion(self, blocked: bool, done: float) -> None:
        """A motion outside a route (a scan's turn, a sweep's leg) ended."""

    async def on_tick(self, now: float) -> None:
        """Navigation's periodic tick [s of Trio time]."""

    async def on_ir(self, in_range: bool, *, pinned: bool = False) -> None:
        """The IR decision; ``pinned``: the sensor sits on an ADC rail and decides
        nothing."""

    def before_command(self, motion: Motion) -> None:
        """``motion`` is about to be commanded."""
