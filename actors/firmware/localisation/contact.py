"""Which side of the body touched, from the yaw while a straight move stalled.

The tread on the touching side is held, the other one drives on, so the body
yaws toward the contact (counter-clockwise for a left contact moving forward).
The contact model (`contact_model`) takes only that half of the leading edge
when the side is known.

Units: [deg].
"""

from __future__ import annotations

__all__ = ["stalled_side"]


def stalled_side(turned_deg: float, direction: int, threshold_deg: float = 1.5) -> int:
    """The side of the body that touched: +1 left, -1 right, 0 unknown.

    Args:
        turned_deg: heading change during a straight move that ended blocked [deg].
        direction: +1 the move was forward, -1 backward.
        threshold_deg: smaller changes say nothing (motor noise) [deg].
    """
    if abs(turned_deg) < threshold_deg:
        return 0
    return (1 if turned_deg > 0 else -1) * (1 if direction >= 0 else -1)
