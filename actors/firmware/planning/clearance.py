"""Clearance tests on a map: does the rover fit at a spot, and what is ahead of it.

Algorithm
    `check_spot`: the rover may turn in place at its spot, so the space it
    needs is the disc swept by its body while turning, of radius
    ``hypot(length / 2, width / 2) + margin``; that disc covers every heading,
    which is why the requested heading does not change the answer. The test is
    exact on the grid: the distance from the spot to the nearest point of each
    cell's square is compared with the radius (the same test as a shapely disc
    intersecting the cells' boxes, without polygon approximation). Any
    occupied cell touched fails the spot; then any unknown cell within the
    body's own turning disc (without the margin) fails it ("unknown ground":
    nobody has seen the ground the rover would stand and turn on). Unknown
    cells only in the margin band are accepted: the margin guards against
    mapping error at known obstacles, and the few cells a LIDAR leaves unseen
    next to a free spot (shadows behind furniture legs) are no reason to
    refuse it. The disc with its margin must lie inside the map.

    `obstacle_ahead`: the nearest occupied cell whose centre lies ahead of the
    rover (forward distance in (beyond, distance]) inside the cone of
    ``half_angle_deg`` or the corridor of the rover's half width plus margin,
    whichever is wider there: the corridor covers the body close in, the cone
    the sides further out.

Reference
    Configuration-space obstacles for a disc robot: Lozano-Perez, "Spatial
    Planning: A Configuration Space Approach", IEEE Trans. Computers C-32(2), 1983.

Frame and units
    The rover frame [cm], headings [deg] counter-clockwise from +x; grids as in
    `actors.firmware.mapping.occupancy` (row 0 is the lowest y).
"""

from __future__ import annotations

import math
import numbers
from dataclasses import dataclass

import numpy as np

from server.protocol.grid_map import OCCUPIED, UNKNOWN, GridMap
from server.protocol.pose import Pose, angle_diff_deg

__all__ = ["check_spot", "turning_radius_cm", "Obstacle", "obstacle_ahead", "occupied_near",
           "passage_width", "cross_section", "first_occupied"]


def turning_radius_cm(length_cm: float, width_cm: float) -> float:
    """Half-diagonal of the rover body: the radius it sweeps turning in place [cm]."""
    return math.hypot(0.5 * length_cm, 0.5 * width_cm)


def _square_gaps(x: float, y: float, res: float, ox: float, oy: float,
                 rows: np.ndarray, cols: np.ndarray) -> np.ndarray:
    """Distance [cm] from (x, y) to the nearest point of each cell (rows, cols)."""
    cx = ox + (cols + 0.5) * res
    cy = oy + (rows + 0.5) * res
    dx = np.maximum(np.abs(x - cx) - 0.5 * res, 0.0)
    dy = np.maximum(np.abs(y - cy) - 0.5 * res, 0.0)
    return np.hypot(dx, dy)


def occupied_near(grid: GridMap, pose: Pose, reach_cm: float
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
    """Occupied cells within a square of half-side ``reach_cm`` around ``pose``.

    Returns:
        (px, py, fwd, lat): the cell centres relative to the pose in the map's axes,
        and the same in the pose's body frame (forward, left) [cm]; None when the
        square holds no occupied cell.
    """
    res = grid.resolution_cm
    k = math.ceil(reach_cm / res) + 1
    r, c = grid.world_to_cell(pose.x, pose.y)
    ny, nx = grid.shape
    r0, r1, c0, c1 = max(0, r - k), min(ny, r + k + 1), max(0, c - k), min(nx, c + k + 1)
    if r0 >= r1 or c0 >= c1:
        return None
    rows, cols = np.nonzero(grid.cells[r0:r1, c0:c1] == OCCUPIED)
    if rows.size == 0:
        return None
    ox, oy = grid.origin_cm
    px = ox + (cols + c0 + 0.5) * res - pose.x
    py = oy + (rows + r0 + 0.5) * res - pose.y
    h = pose.heading_rad
    ch, sh = math.cos(h), math.sin(h)
    return px, py, px * ch + py * sh, -px * sh + py * ch


def check_spot(
    grid_cells: np.ndarray,
    resolution_cm: float,
    origin_cm: tuple[float, float],
    x: float,
    y: float,
    heading_deg: float,
    length_cm: float,
    width_cm: float,
    margin_cm: float,
) -> tuple[bool, str]:
    """Whether the rover fits at (x, y) @ heading with ``margin_cm`` all round for turning.

    Args:
        grid_cells: the map, (ny, nx): -1 unknown, 0..49 free, 50..100 occupied.
        resolution_cm: cell side [cm].
        origin_cm: lower-left corner of cell [0, 0] [cm].
        x: spot [cm].
        y: spot [cm].
        heading_deg: heading at the spot [deg] (checked finite; a disc suits all headings).
        length_cm: rover body length [cm].
        width_cm: rover body width [cm].
        margin_cm: clearance kept on all sides [cm].

    Returns:
        ``(True, "ok")``, or ``(False, reason)`` where the reason starts with
        ``"bad spot"``, ``"outside the map"``, ``"obstacle"`` or ``"unknown ground"``.

    Raises:
        ValueError: for a malformed map (cells, resolution or origin) or
            non-positive rover dimensions or a negative margin.
    """
    grid = GridMap(GridMap.split(grid_cells), resolution_cm, origin_cm)
    if not (length_cm > 0 and width_cm > 0 and margin_cm >= 0):
        raise ValueError(f"length_cm and width_cm must be > 0 and margin_cm >= 0, got "
                         f"{length_cm}, {width_cm}, {margin_cm}")
    for name, v in (("x", x), ("y", y), ("heading", heading_deg)):
        if not isinstance(v, numbers.Real) or not math.isfinite(v):
            return False, f"bad spot: {name} must be a finite number, got {v!r}"
    radius = turning_radius_cm(length_cm, width_cm) + margin_cm
    res = grid.resolution_cm
    ox, oy = grid.origin_cm
    ny, nx = grid.shape
    x_ok = ox + radius <= x <= ox + nx * res - radius
    y_ok = oy + radius <= y <= oy + ny * res - radius
    if not (x_ok and y_ok):
        return False, (f"outside the map: the rover needs {radius:.1f} cm all round and the map "
                       f"spans x {ox:g}..{ox + nx * res:g}, y {oy:g}..{oy + ny * res:g} cm")
    k = math.ceil(radius / res) + 1
    r, c = grid.world_to_cell(x, y)
    r0, r1, c0, c1 = max(0, r - k), min(ny, r + k + 1), max(0, c - k), min(nx, c + k + 1)
    rows, cols = np.mgrid[r0:r1, c0:c1]
    gaps = _square_gaps(x, y, res, ox, oy, rows, cols)
    inside = gaps < radius
    window = grid.cells[r0:r1, c0:c1]
    occ = inside & (window == OCCUPIED)
    if occ.any():
        nearest = float(gaps[occ].min())
        return False, (f"obstacle {nearest:.1f} cm from the spot; the rover needs {radius:.1f} cm "
                       f"to turn")
    body = radius - margin_cm
    unk = (gaps < body) & (window == UNKNOWN)
    if unk.any():
        return False, f"unknown ground: {int(unk.sum())} unmapped cells within {body:.1f} cm"
    return True, "ok"


@dataclass(frozen=True, slots=True)
class Obstacle:
    """The nearest occupied cell ahead."""

    distance_cm: float
    """From the rover's centre to the cell's centre [cm]."""
    forward_cm: float
    """Along the heading [cm]."""
    bearing_deg: float
    """Direction relative to the heading, counter-clockwise [deg]."""
    point_cm: tuple[float, float]
    """Cell centre (x, y) in the rover frame [cm]."""


def obstacle_ahead(
    grid: GridMap,
    pose: Pose,
    distance_cm: float,
    *,
    half_angle_deg: float,
    half_width_cm: float,
    beyond_cm: float = 0.0,
) -> Obstacle | None:
    """The nearest occupied cell ahead of ``pose`` within ``distance_cm``, or None.

    Args:
        grid: the map snapshot.
        pose: the rover pose.
        distance_cm: how far ahead to look (forward distance) [cm].
        half_angle_deg: half-angle of the cone ahead [deg].
        half_width_cm: half-width of the corridor ahead (body half-width plus a
            margin) [cm].
        beyond_cm: only cells whose centre lies more than this far ahead count (the
            body's half length: a cell beside the body is not ahead of it) [cm].

    Raises:
        ValueError: for a non-positive distance, or a half-angle outside [0, 90).
    """
    if not (distance_cm > 0 and math.isfinite(distance_cm)):
        raise ValueError(f"distance_cm must be positive, got {distance_cm!r}")
    if not 0 <= half_angle_deg < 90:
        raise ValueError(f"half_angle_deg must be in [0, 90), got {half_angle_deg!r}")
    if not 0 <= beyond_cm < distance_cm:
        raise ValueError(f"beyond_cm must be in [0, distance_cm), got {beyond_cm!r}")
    reach = math.hypot(distance_cm, max(half_width_cm,
                                        distance_cm * math.tan(math.radians(half_angle_deg))))
    near = occupied_near(grid, pose, reach)
    if near is None:
        return None
    px, py, fwd, lat = near
    width = np.maximum(half_width_cm, fwd * math.tan(math.radians(half_angle_deg)))
    ahead = (fwd > beyond_cm) & (fwd <= distance_cm) & (np.abs(lat) <= width)
    if not ahead.any():
        return None
    dist = np.hypot(px, py)
    dist[~ahead] = np.inf
    i = int(np.argmin(dist))
    bearing = angle_diff_deg(math.degrees(math.atan2(py[i], px[i])), pose.heading_deg)
    return Obstacle(float(dist[i]), float(fwd[i]), bearing,
                    (float(px[i] + pose.x), float(py[i] + pose.y)))


def passage_width(grid: GridMap, x: float, y: float, heading_deg: float, *,
                  max_cm: float = 40.0, step_cm: float = 1.0) -> float | None:
    """Free width across the heading at (x, y): the distance between the first occupied
    cells met walking to the left and to the right [cm] (`cross_section`'s two sides).

    Why: a block in a passage with mapped walls close on both sides is most likely
    the rover's own drift into one of them (which one, dead reckoning cannot tell),
    not an obstacle the map does not show.

    Returns:
        The width [cm], or None when either side has no occupied cell within ``max_cm``.
    """
    sides = cross_section(grid, x, y, heading_deg, max_cm=max_cm, step_cm=step_cm)
    return None if sides is None else sides[0] + sides[1]


def cross_section(grid: GridMap, x: float, y: float, heading_deg: float, *,
                  max_cm: float = 40.0, step_cm: float = 1.0
                  ) -> tuple[float, float] | None:
    """How far the first occupied cell lies to the left and to the right of (x, y),
    across the heading [cm] (`first_occupied` either side).

    Returns:
        (left, right) [cm], or None when either side has no occupied cell within
        ``max_cm``.
    """
    h = math.radians(heading_deg)
    nx_, ny_ = -math.sin(h), math.cos(h)  # the left normal
    left = _ray(grid, x, y, nx_, ny_, max_cm, step_cm)
    if left is None:
        return None
    right = _ray(grid, x, y, -nx_, -ny_, max_cm, step_cm)
    return None if right is None else (left, right)


def first_occupied(grid: GridMap, x: float, y: float, direction_deg: float, *,
                   max_cm: float = 40.0, step_cm: float = 1.0) -> float | None:
    """How far the first occupied cell lies from (x, y) along ``direction_deg`` [cm].

    Args:
        grid: the map; unknown cells and the grid's edge count as no wall.
        x, y: the point [cm].
        direction_deg: the direction to look in [deg].
        max_cm: how far to look [cm].
        step_cm: sampling step [cm].

    Returns:
        The distance [cm], or None when no occupied cell lies within ``max_cm``.
    """
    h = math.radians(direction_deg)
    return _ray(grid, x, y, math.cos(h), math.sin(h), max_cm, step_cm)


def _ray(grid: GridMap, x: float, y: float, ux: float, uy: float, max_cm: float,
         step_cm: float) -> float | None:
    """`first_occupied` along the unit vector (ux, uy)."""
    d = np.arange(0.0, max_cm + 1e-9, step_cm)
    px = x + ux * d
    py = y + uy * d
    ox, oy = grid.origin_cm
    cols = np.floor((px - ox) / grid.resolution_cm).astype(int)
    rows = np.floor((py - oy) / grid.resolution_cm).astype(int)
    ny, nx = grid.shape
    inside = (rows >= 0) & (rows < ny) & (cols >= 0) & (cols < nx)
    occ = np.zeros(d.shape, dtype=bool)
    occ[inside] = grid.cells[rows[inside], cols[inside]] == OCCUPIED
    hit = np.flatnonzero(occ)
    return None if hit.size == 0 else float(d[hit[0]])
