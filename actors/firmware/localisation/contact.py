"""Contact localisation: where the rover must be, given that a mapped wall stopped it.

Why
    Hider and seeker have no LIDAR: their pose is dead reckoning, and tread
    slip makes it drift sideways by several cm over a few metres. In a passage
    only 15-20 cm wider than the body that is enough to scrape a wall. The
    contact itself is a measurement: the body stopped, so some part of its
    outline is touching something. When the map shows a wall near the
    dead-reckoned pose, the pose nearest to it at which the body's leading
    edge touches that wall (and the body overlaps nothing) is where the rover
    most likely is. Correcting to it lets the next plan re-centre the rover in
    the passage instead of scraping the same wall again.

Method
    Occupied cells within reach are taken as points at their centres (a LIDAR
    hit lands in the cell holding the wall's face, so the face lies anywhere in
    the cell: the centre is its unbiased guess, ``tol_cm`` its spread).
    Candidate poses are the dead-reckoned one shifted sideways by ``s``, along
    the heading by ``u`` and turned by ``a``, on a small grid. A candidate
    explains the block when (1) the body, shrunk by ``tol_cm``, holds no point,
    and (2) the band just ahead of its leading edge (``direction`` of the
    motion; one cell deep, as wide as the body plus ``tol_cm``) holds a point,
    on the side that stalled when that is known. The cheapest candidate wins,
    cost ``|s| + along_weight |u| + turn_weight |a|`` [cm]. When a candidate
    touching with the other side of the body is almost as cheap and the
    stalled side is not known, the contact is ambiguous (a gap missed to the
    left or to the right looks alike) and is reported so, for the caller not
    to act on it. "Almost as cheap" is relative to how far dead reckoning may be
    off: the caller passes ``ambiguity_cm`` (it grows with the distance driven
    since the pose was last known) and ``other_shift_cm``, a sideways window
    wider than the one corrections are taken from, in which the other side is
    looked for. Why: at a gap's edge the true pose may lie beyond the
    correction window (measured: 20 cm off after 6 m of seeking); the
    cheapest candidate inside it is then the wrong edge, and acting on it
    pushed dead reckoning further off on every block. The same holds for a
    head-on contact (the whole leading edge on one wall's face) that needs a
    sideways shift: the faces on both sides of a gap explain it, the nearer
    one is cheapest, and when the other one is within ``ambiguity_cm`` too the
    contact is ambiguous whatever side stalled (a hider 34 cm below a
    corridor's mouth by a 12 deg heading error is otherwise put 8 cm further
    up onto the upper wall's face, away from the mouth).

    The stalled side comes from the heading change during a straight move: the
    tread on the touching side is held, the other one drives on, so the body
    yaws toward the contact (counter-clockwise for a left contact moving
    forward).

Units: [cm], [deg]; poses in the map frame.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from actors.firmware.planning.clearance import occupied_near
from server.protocol.grid_map import GridMap
from server.protocol.pose import Pose

__all__ = ["Contact", "locate_contact", "stalled_side"]


@dataclass(frozen=True, slots=True)
class Contact:
    """The pose that explains a block, and how far it is from dead reckoning."""

    pose: Pose
    """The corrected pose (map frame)."""
    shift_cm: float
    """Sideways correction, positive to the left of the heading [cm]."""
    along_cm: float
    """Correction along the heading [cm]."""
    turn_deg: float
    """Heading correction, counter-clockwise [deg]."""
    ambiguous: bool
    """The other side explains the block about as well: do not act on it."""
    sideways_free: bool = False
    """The same contact shifted ``free_cm`` sideways (either way, same along and turn)
    explains the block as well: a wall's face across the heading (or beside a gap)
    measures where the rover is along its heading, not sideways, so the caller must
    keep its sideways uncertainty (a reset to 3 cm after such a contact shrinks the
    sideways search below what the rover may be off)."""

    @property
    def needed(self) -> bool:
        """The dead-reckoned pose does not already explain the block."""
        return bool(self.shift_cm or self.along_cm or self.turn_deg)


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


def _grid_axis(limit: float, step: float) -> np.ndarray:
    n = int(math.floor(limit / step + 1e-9)) if step > 0 else 0
    return np.arange(-n, n + 1, dtype=float) * step


def locate_contact(grid: GridMap, pose: Pose, *, length_cm: float, width_cm: float,
                   direction: int = 1, side: int = 0, max_shift_cm: float = 14.0,
                   max_along_cm: float = 6.0, max_turn_deg: float = 8.0,
                   shift_step_cm: float = 1.0, along_step_cm: float = 2.0,
                   turn_step_deg: float = 1.0, along_weight: float = 0.5,
                   turn_weight: float = 1.5, tol_cm: float | None = None,
                   ambiguity_cm: float = 3.0,
                   other_shift_cm: float | None = None,
                   free_cm: float = 5.0) -> Contact | None:
    """The pose nearest ``pose`` at which the body touches a mapped wall ahead.

    Args:
        grid: the map (map frame); only its occupied cells count.
        pose: the dead-reckoned pose at the block (map frame).
        length_cm: body length, along the heading [cm].
        width_cm: body width [cm].
        direction: +1 the blocked motion was forward, -1 backward.
        side: the side that stalled (`stalled_side`): +1 left, -1 right, 0 unknown.
        max_shift_cm, max_along_cm, max_turn_deg: the search box [cm], [cm], [deg].
        shift_step_cm, along_step_cm, turn_step_deg: its steps.
        along_weight, turn_weight: cost of 1 cm along / 1 deg of turn, in cm of shift.
        tol_cm: how far a wall face may lie from its cell's centre [cm];
            default half a cell.
        ambiguity_cm: a cheapest explanation on the other side within this much
            cost makes the contact ambiguous (when ``side`` is 0) [cm].
        other_shift_cm: the sideways window searched for that other-side
            explanation [cm]; default (and at least) ``max_shift_cm``. The
            returned pose always lies within ``max_shift_cm``.
        free_cm: the sideways step that tests whether the contact pins the sideways
            position (`Contact.sideways_free`) [cm].

    Returns:
        The cheapest explaining `Contact` (zero corrections when the
        dead-reckoned pose explains the block), or None when no pose in the
        search box does (something the map does not show stopped the rover).

    Raises:
        ValueError: when ``direction`` is not +1 or -1, or a body size is not positive.
    """
    if direction not in (1, -1):
        raise ValueError(f"direction must be 1 or -1, got {direction!r}")
    if not (length_cm > 0 and width_cm > 0):
        raise ValueError(f"body size must be positive, got {length_cm!r} x {width_cm!r}")
    res = grid.resolution_cm
    tol = 0.5 * res if tol_cm is None else float(tol_cm)
    half_l, half_w = 0.5 * length_cm, 0.5 * width_cm
    wide = max(max_shift_cm, other_shift_cm if other_shift_cm is not None else 0.0)
    reach = math.hypot(half_l + res, half_w + tol) + wide + max_along_cm + res
    near = occupied_near(grid, pose, reach)
    if near is None:
        return None
    _, _, fx, fy = near  # occupied cells in the dead-reckoned body frame [cm]

    S, U, A, inside, band_all, by = _candidate_bodies(
        fx, fy, _grid_axis(wide, shift_step_cm), _grid_axis(max_along_cm, along_step_cm),
        _grid_axis(max_turn_deg, turn_step_deg), half_l, half_w, tol, res, direction)
    band = band_all
    if side:
        band = band & ((by * direction * side) > 0)
    explains = ~inside.any(axis=1) & band.any(axis=1)
    ok = explains & (np.abs(S) <= max_shift_cm + 1e-9)
    if not ok.any():
        return None
    cost = np.abs(S) + along_weight * np.abs(U) + turn_weight * np.abs(A)
    any_cost = np.where(explains, cost, np.inf)
    cost = np.where(ok, cost, np.inf)
    best = int(np.argmin(cost))
    sb, ub, ab = float(S[best]), float(U[best]), float(A[best])
    ambiguous = _ambiguous(S, by, band_all, direction, side, best, cost, any_cost, res,
                           ambiguity_cm)
    same = (np.abs(U - ub) < 1e-9) & (np.abs(A - ab) < 1e-9) & explains
    free = any(bool((same & (np.abs(S - (sb + d)) < 1e-9)).any()) for d in (free_cm, -free_cm))
    ch, sh = math.cos(pose.heading_rad), math.sin(pose.heading_rad)
    x = pose.x + ub * ch - sb * sh
    y = pose.y + ub * sh + sb * ch
    return Contact(Pose(x, y, pose.heading_deg + ab), sb, ub, ab, ambiguous, free)


def _candidate_bodies(fx: np.ndarray, fy: np.ndarray, s: np.ndarray, u: np.ndarray,
                      a: np.ndarray, half_l: float, half_w: float, tol: float, res: float,
                      direction: int) -> tuple[np.ndarray, ...]:
    """Every candidate body pose (sideways shift ``S``, along ``U``, turn ``A``, flattened)
    and, per candidate and occupied point, whether the point lies inside the body
    (``inside``), in the band just ahead of its front face (``band``), and its sideways
    coordinate in the candidate's frame (``by``).

    Returns:
        ``(S, U, A, inside, band, by)``.
    """
    S, U, A = np.meshgrid(s, u, a, indexing="ij")
    S, U, A = S.ravel(), U.ravel(), A.ravel()
    ar = np.radians(A)
    ca, sa = np.cos(ar)[:, None], np.sin(ar)[:, None]
    # points in each candidate body frame: translate by (U, S), then rotate by -A
    dx = fx[None, :] - U[:, None]
    dy = fy[None, :] - S[:, None]
    bx = (dx * ca + dy * sa) * direction
    by = (-dx * sa + dy * ca) * direction
    inside = (np.abs(bx) < half_l - tol) & (np.abs(by) < half_w - tol)
    band = (bx >= half_l - tol) & (bx <= half_l + res) & (np.abs(by) <= half_w + tol)
    return S, U, A, inside, band, by


def _ambiguous(S: np.ndarray, by: np.ndarray, band_all: np.ndarray, direction: int,
               side: int, best: int, cost: np.ndarray, any_cost: np.ndarray, res: float,
               ambiguity_cm: float) -> bool:
    """Whether an explanation on the other side costs within ``ambiguity_cm`` of the best.

    With the stalled side unknown, the other side is the one the body touches with.
    Head-on against a face beside a gap, the face across the gap, shifted the other
    way, explains the block as well (the stalled side tells nothing here). So does a
    corner: the stalled side's front corner meets the near wall's end or, shifted the
    other way, the far wall's end; a fix toward the wrong wall makes every later
    sideways offset miss the gap. A shift within a cell is never ambiguous: that small
    a fix cannot push the pose to the wrong wall.
    """
    # the side of the body each candidate touches with: +1 left, -1 right, 0 both (head-on)
    left = (band_all & (by * direction > 0)).any(axis=1)
    right = (band_all & (by * direction < 0)).any(axis=1)
    touch = left.astype(int) - right.astype(int)
    sb = float(S[best])
    if side == 0 and touch[best] != 0:
        other = np.where(touch == -touch[best], any_cost, np.inf)
        return bool(other.min() <= cost[best] + ambiguity_cm)
    if (touch[best] == 0 and sb != 0.0) or (side != 0 and abs(sb) > res):
        other = np.where(S * sb < 0.0, any_cost, np.inf)
        return bool(other.min() <= cost[best] + ambiguity_cm)
    return False
