"""Which side of the body touched, from the yaw while a straight move stalled."""

from __future__ import annotations

from actors.firmware.localisation.contact import stalled_side


def test_stalled_side_from_the_yaw_during_a_straight_move() -> None:
    """Forward: a left contact holds the left tread, the body yaws left (CCW); backward
    the other way round; a yaw under the threshold says nothing."""
    assert stalled_side(4.0, 1) == 1
    assert stalled_side(-4.0, 1) == -1
    assert stalled_side(4.0, -1) == -1
    assert stalled_side(-4.0, -1) == 1
    assert stalled_side(1.0, 1) == 0
