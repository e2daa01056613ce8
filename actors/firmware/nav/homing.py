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

from actors.firmware.nav.mapping_options import MappingOptions
from actors.firmware.nav.route import Motion, PathFollower, plan_route, route_points

__all__ = ["Homing", "HOME_BLOCKS"]

HOME_BLOCKS = 3
"""Blocked motions on the way home before uploading from where the rover is (a bound)."""


class Homing:
    """Driving back to the start pose (a mixin of `mapper.MappingNav`, working on its state)."""

    m: MappingOptions

    def _plan_home(self) -> bool:
        """A route back to the start pose (0, 0); False when there or no route is known."""
        assert self.grid is not None
        pose = self.map_pose
        if math.hypot(pose.x, pose.y) <= self.m.home_reach_cm:
            return False
        for radius, margin in self._tiers():
            plan = plan_route(self.grid, (pose.x, pose.y), (0.0, 0.0), radius_cm=radius,
                              margin_cm=margin)
            if plan is not None:
                break
        else:
            return False
        ex = self.ex
        ex.follower = PathFollower(route_points(plan, (pose.x, pose.y)), None, self.o)
        ex.target = (0.0, 0.0)
        ex.steps = 0
        ex.budget = ex.follower.budget(pose)
        return True

    async def _home_step(self) -> None:
        """One ADP step home; uploads once home, or when home cannot be reached."""
        if self.state != "homing" or self.moving or not self.can_move or self.holding:
            return
        ex = self.ex
        pose = self.map_pose
        if ex.follower is None and not self._plan_home():
            await self._finish(self._finish_reason)
            return
        assert ex.follower is not None
        motion = ex.follower.next_motion(pose)
        if motion is None or math.hypot(pose.x, pose.y) <= self.m.home_reach_cm \
                or ex.steps >= ex.budget:
            await self._finish(self._finish_reason)
            return
        if motion.kind == "move":
            motion = self._mind_the_obstacle(motion)
            if motion.kind == "turn":
                ex.follower = None  # turned away from an obstacle: plan again from there
        ex.steps += 1
        await self.command(motion)

    async def _after_home_motion(self, blocked: bool) -> None:
        ex = self.ex
        if not blocked:
            await self._home_step()
            return
        ex.blocks += 1
        ex.follower = None
        if ex.blocks >= HOME_BLOCKS:
            await self._finish(self._finish_reason + "; home blocked")
            return
        await self.command(Motion("move", -self.o.backoff_cm))

