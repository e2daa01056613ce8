"""Room geometry shared by scenarios, physics, ray casting and ground truth.

Frame: the room's lower-left corner is (0, 0) [cm], x to the right, y up;
headings [deg] are counter-clockwise from +x. Shapely is the geometry model
(validation and ground truth); physics and the ray caster use the boundary
segments extracted here, so all three see the same walls.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np
import shapely
from shapely.geometry import Point, Polygon, box

#: segments per quarter circle of a round obstacle (a 16-gon: within 1.2 cm of a 60 cm circle)
CIRCLE_QUAD_SEGS = 4


class Pose(NamedTuple):
    """A position and heading in the room frame: x, y [cm], heading [deg]."""

    x: float
    y: float
    heading_deg: float = 0.0


def circle(cx: float, cy: float, r: float) -> Polygon:
    """A round obstacle as the polygon every consumer uses [cm]."""
    return Point(cx, cy).buffer(r, quad_segs=CIRCLE_QUAD_SEGS)


def footprint(pose: Pose, length_cm: float, width_cm: float) -> Polygon:
    """A rover's rectangular body at ``pose`` (length along the heading) [cm]."""
    return Polygon(footprint_corners(pose, length_cm, width_cm))


def footprint_corners(pose: Pose, length_cm: float, width_cm: float) -> np.ndarray:
    """The four corners of a rover body, counter-clockwise, shape (4, 2) [cm]."""
    h = math.radians(pose.heading_deg)
    c, s = math.cos(h), math.sin(h)
    hl, hw = length_cm / 2, width_cm / 2
    local = np.array([(hl, hw), (-hl, hw), (-hl, -hw), (hl, -hw)], dtype=float)
    rot = np.array([[c, -s], [s, c]])
    return local @ rot.T + np.array([pose.x, pose.y])


def room_polygon(width_cm: float, height_cm: float) -> Polygon:
    """The room's floor as a rectangle [cm]."""
    return box(0.0, 0.0, width_cm, height_cm)


def boundary_segments(geoms: list) -> np.ndarray:
    """All boundary edges of polygons as an (N, 4) array of x0, y0, x1, y1 [cm].

    Interiors (holes) are included, so a ray inside a ring obstacle still hits it.
    """
    parts: list[np.ndarray] = []
    for g in geoms:
        polys = getattr(g, "geoms", [g])
        for p in polys:
            for ring in [p.exterior, *p.interiors]:
                xy = np.asarray(ring.coords, dtype=float)
                parts.append(np.hstack([xy[:-1], xy[1:]]))
    if not parts:
        return np.zeros((0, 4))
    return np.vstack(parts)


def room_segments(width_cm: float, height_cm: float) -> np.ndarray:
    """The four walls as segments, shape (4, 4) [cm]."""
    return boundary_segments([room_polygon(width_cm, height_cm)])


def union(geoms: list) -> shapely.Geometry:
    """Union of obstacles (an empty polygon when there are none)."""
    if not geoms:
        return Polygon()
    return shapely.union_all(geoms)
