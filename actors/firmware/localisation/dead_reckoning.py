"""A particle set moved by the counted motions alone, moved when it is read.

Why
    The hider's and seeker's navigation keeps, beside its pose belief, the same
    particles moved by the tread motion model and never weighed (dead reckoning
    alone): a retried destination starts from the mixture of the two. It is read
    only then, or after a restart, yet moving its particles at every pose at rest
    cost as much as moving the belief's. Its motion draws come from a generator of
    its own, which nothing else draws from, so the same motions applied later, in
    the same order, with the same generators, give the same particles: they wait
    in a queue (at most ``MAX_PENDING``; a full queue is applied at once) and are
    applied when the set is read.

Frame and units
    As `belief.PoseBelief`: particles ``x``, ``y`` [cm], ``theta`` [rad], map frame.
"""

from __future__ import annotations

import numpy as np

from actors.firmware.localisation.belief import PoseBelief
from actors.firmware.localisation.motion_model import MotionNoise, TreadMotion

__all__ = ["DeadReckoning", "MAX_PENDING"]

MAX_PENDING = 1024
"""At most this many motions wait to be applied (a bound on the queue) [1]."""


class DeadReckoning:
    """A `PoseBelief` that is only predicted, its predictions applied when read.

    Args:
        belief: the particle set at the start (taken over, not copied).
    """

    def __init__(self, belief: PoseBelief) -> None:
        self._belief = belief
        self._pending: list[tuple[TreadMotion, float, MotionNoise, np.random.Generator]] = []

    def predict(self, motion: TreadMotion, track_width_cm: float, noise: MotionNoise,
                rng: np.random.Generator) -> None:
        """`PoseBelief.predict`, applied when the set is next read. ``rng`` must be drawn
        from by nothing but this set's predictions until then."""
        self._pending.append((motion, track_width_cm, noise, rng))
        if len(self._pending) >= MAX_PENDING:
            self._apply()

    @property
    def belief(self) -> PoseBelief:
        """The particle set moved by every motion given so far."""
        self._apply()
        return self._belief

    @property
    def pending(self) -> int:
        """How many motions wait to be applied."""
        return len(self._pending)

    def _apply(self) -> None:
        pending, self._pending = self._pending, []
        for motion, width, noise, rng in pending:
            self._belief.predict(motion, width, noise, rng)
