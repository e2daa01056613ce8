"""The mapper's way home once mapping completes by itself.

Homing
    A mapper left where its last frontier was can block the only passage the
    hider needs (a corridor barely wider than a rover: the hider pushes it and
    gives up). So when mapping completes by itself, the mapper first drives
    back to its start pose, the LIDAR still scanning (scan matching keeps its
    pose honest), bounded by ``home_budget_s`` and ``HOME_BLOCKS``; then it
    uploads. A motion blocked in the open (nothing mapped in its way: both encoders
    stuck, most likely) is not one of those blocks: it holds for odometry
    (`sensor_watch`). A stop from the server or the time budget uploads at once.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING

from actors.firmware.nav.route import Motion, PathFollower, plan_route, route_points

if TYPE_CHECKING:
    from actors.firmware.nav.mapper import MappingNav

__all__ = ["Homing", "HOME_BLOCKS"]

HOME_BLOCKS = 3
"""Blocked motions on the way home before uploading from where the rover is (a bound)."""


class Homing:
    """Driving back to the start pose, a part of the mapper's navigation actor.

    Args:
        nav: the mapper's navigation actor.
    """

    def __init__(self, nav: MappingNav) -> None:
        self.nav = nav

    def plan_home(self) -> bool:
        """A route back to the start pose (0, 0); False when there or no route is known."""
        assert self.nav.grid is not None
        pose = self.nav.map_pose
        if math.hypot(pose.x, pose.y) <= self.nav.m.home_reach_cm:
            return False
        for radius, margin in self.nav.explorer.tiers():
            plan = plan_route(self.nav.grid, (pose.x, pose.y), (0.0, 0.0), radius_cm=radius,
                              margin_cm=margin)
            if plan is not None:
                break
        else:
            return False
        ex = self.nav.ex
        ex.follower = PathFollower(route_points(plan, (pose.x, pose.y)), None, self.nav.o)
        ex.target = (0.0, 0.0)
        ex.steps = 0
        ex.budget = ex.follower.budget(pose)
        return True

    async def home_step(self) -> None:
        """One ADP step home; uploads once home, or when home cannot be reached."""
        nav = self.nav
        if nav.state != "homing" or nav.moving or not nav.can_move or nav.holding:
            return
        ex = self.nav.ex
        pose = self.nav.map_pose
        if ex.follower is None and not self.plan_home():
            await self.nav.finish(self.nav.finish_reason)
            return
        assert ex.follower is not None
        motion = ex.follower.next_motion(pose)
        if motion is None or math.hypot(pose.x, pose.y) <= self.nav.m.home_reach_cm \
                or ex.steps >= ex.budget:
            await self.nav.finish(self.nav.finish_reason)
            return
        if motion.kind == "move":
            motion = self.nav.explorer.mind_the_obstacle(motion)
            if motion.kind == "turn":
                ex.follower = None  # turned away from an obstacle: plan again from there
        ex.steps += 1
        await self.nav.command(motion)

    async def after_home_motion(self, blocked: bool) -> None:
        ex = self.nav.ex
        if not blocked:
            await self.home_step()
            return
        ex.blocks += 1
        ex.follower = None
        if ex.blocks >= HOME_BLOCKS:
            await self.nav.finish(self.nav.finish_reason + "; home blocked")
            return
        await self.nav.command(Motion("move", -self.nav.o.backoff_cm))

