"""When two points are one place to a rover: the distance navigation's rules share."""

from __future__ import annotations

__all__ = ["SAME_PLACE_CM"]

SAME_PLACE_CM = 30.0
"""Two points this near each other are one place to the rover [cm]: from either, a rover
20 cm long that turns within a 25 cm circle reaches, touches and sees about the same.
A block this near the last one is that block met again (`recovery`: something the map
does not show is there); a nudge series and a route's count of blocks start afresh once
the rover got this far on (`nudge_series`, `route_nav`); a viewpoint this near the
current target is that target, and one this near a blacklisted point is that point
(`exploration`)."""
