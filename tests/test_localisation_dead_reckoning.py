"""The dead-reckoning set: motions applied when it is read give the particles of motions
applied at once, with the same generators; the queue is bounded."""

from __future__ import annotations

import numpy as np

from actors.firmware.localisation.belief import PoseBelief
from actors.firmware.localisation.dead_reckoning import MAX_PENDING, DeadReckoning
from actors.firmware.localisation.motion_model import MotionNoise, TreadMotion, TreadReport
from server.protocol.pose import Pose


def _motions(count: int) -> list[TreadMotion]:
    rng = np.random.default_rng(8)
    out = []
    for k in range(count):
        left, right = (float(v) for v in rng.normal(5.0, 3.0, 2))
        if k % 7 == 3:  # a reported tread now and then
            out.append(TreadMotion(left, right, None, right * 1.5, TreadReport.OK,
                                   TreadReport.SHORT))
        else:
            out.append(TreadMotion(left, right))
    return out


def _start() -> PoseBelief:
    return PoseBelief.around(Pose(10.0, 20.0, 30.0), np.random.default_rng(1))


def test_motions_applied_when_read_give_the_particles_of_motions_applied_at_once() -> None:
    noise = MotionNoise()
    motions = _motions(40)
    now = _start()
    now_rngs = [np.random.default_rng(5), np.random.default_rng(6)]  # a restart between
    later = DeadReckoning(_start())
    later_rngs = [np.random.default_rng(5), np.random.default_rng(6)]
    for k, m in enumerate(motions):
        now.predict(m, 13.0, noise, now_rngs[k >= 25])
        later.predict(m, 13.0, noise, later_rngs[k >= 25])
        if k == 10:  # read part way: the rest waits again
            assert np.array_equal(later.belief.particles, now.particles)
    assert later.pending == 29
    assert np.array_equal(later.belief.particles, now.particles)
    assert np.array_equal(later.belief.weights, now.weights)
    assert later.pending == 0


def test_a_full_queue_is_applied_at_once() -> None:
    dead = DeadReckoning(_start())
    before = dead.belief.particles.copy()
    rng = np.random.default_rng(3)
    for m in _motions(MAX_PENDING - 1):
        dead.predict(m, 13.0, MotionNoise(), rng)
    assert dead.pending == MAX_PENDING - 1
    dead.predict(TreadMotion(1.0, 1.0), 13.0, MotionNoise(), rng)
    assert dead.pending == 0
    assert not np.array_equal(dead.belief.particles, before)
