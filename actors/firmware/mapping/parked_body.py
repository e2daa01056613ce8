"""The mapper's own body in the map it uploads: it stays parked there.

Why
    The mapper's LIDAR sees every body in the room but its own: hider and
    seeker, parked at their starts while it maps, are in its map as obstacles,
    and the mapper is not. After mapping it stands at its home for the rest of
    the game, an obstacle hider and seeker cannot see coming (they have no
    range sensor). Missing from their map, it is a place their planners route
    through and a contact their belief explains by the nearest mapped wall:
    a seeker that searched beside it pushed it, counted its treads short for
    the whole push and left with its belief tens of centimetres and degrees
    off. Marked in the map, it is planned round like any obstacle, and a
    contact against it is explained by where it stands.

What is marked
    Every cell whose centre lies within the body's rectangle (``length`` along
    the heading x ``width``) grown by half a cell on each side: the cells the
    body covers, as the LIDAR would have marked them had it seen the body from
    outside. Cells off the map are left out (the crop holds the home, which
    the mapper mapped all round).
"""

from __future__ import annotations

import math

import numpy as np

from server.protocol.grid_map import OCCUPIED, GridMap
from server.protocol.pose import Pose

__all__ = ["with_parked_body"]


def with_parked_body(grid: GridMap, pose: Pose, length_cm: float, width_cm: float) -> GridMap:
    """``grid`` with the cells under a ``length_cm`` x ``width_cm`` body at ``pose`` (map
    frame) occupied (a new map; ``grid`` is unchanged)."""
    res = grid.resolution_cm
    half_l, half_w = 0.5 * length_cm + 0.5 * res, 0.5 * width_cm + 0.5 * res
    reach = math.hypot(half_l, half_w)
    r0, c0 = grid.world_to_cell(pose.x - reach, pose.y - reach)
    r1, c1 = grid.world_to_cell(pose.x + reach, pose.y + reach)
    ny, nx = grid.shape
    r0, r1, c0, c1 = max(r0, 0), min(r1 + 1, ny), max(c0, 0), min(c1 + 1, nx)
    cells = grid.cells.copy()
    if r0 < r1 and c0 < c1:
        rows, cols = np.mgrid[r0:r1, c0:c1]
        ox, oy = grid.origin_cm
        dx = ox + (cols + 0.5) * res - pose.x
        dy = oy + (rows + 0.5) * res - pose.y
        h = math.radians(pose.heading_deg)
        along = dx * math.cos(h) + dy * math.sin(h)
        across = -dx * math.sin(h) + dy * math.cos(h)
        under = (np.abs(along) <= half_l) & (np.abs(across) <= half_w)
        cells[rows[under], cols[under]] = OCCUPIED
    cells.flags.writeable = False
    return GridMap(cells, res, grid.origin_cm)
