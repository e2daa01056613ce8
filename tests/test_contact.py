"""Contact localisation: which pose explains a block against a mapped wall."""

from __future__ import annotations

import numpy as np
import pytest

from actors.firmware.localisation.contact import locate_contact, stalled_side
from server.protocol.grid_map import OCCUPIED, GridMap
from server.protocol.pose import Pose

BODY = {"length_cm": 20.0, "width_cm": 15.0}


def boxes_map(*boxes: tuple[float, float, float, float], w: float = 700.0, h: float = 450.0,
              res: float = 5.0) -> GridMap:
    """A map whose cells overlapping any box (x, y, w, h) [cm] are occupied."""
    ny, nx = int(h / res), int(w / res)
    cells = np.zeros((ny, nx), np.int8)
    xs = (np.arange(nx) + 0.5) * res
    ys = (np.arange(ny) + 0.5) * res
    for x0, y0, bw, bh in boxes:
        mx = (xs + res / 2 > x0) & (xs - res / 2 < x0 + bw)
        my = (ys + res / 2 > y0) & (ys - res / 2 < y0 + bh)
        cells[np.ix_(my, mx)] = OCCUPIED
    return GridMap(cells, res, (0.0, 0.0))


CORRIDOR = boxes_map((250, 0, 200, 135), (250, 165, 200, 135))  # 30 cm wide, axis y = 150
GAP = boxes_map((400, 0, 15, 300), (400, 335, 15, 115))  # gap y 300..335, middle 317.5


def test_stalled_side_from_the_yaw_during_a_straight_move() -> None:
    """Forward: a left contact holds the left tread, the body yaws left (CCW); backward
    the other way round; a yaw under the threshold says nothing."""
    assert stalled_side(4.0, 1) == 1
    assert stalled_side(-4.0, 1) == -1
    assert stalled_side(4.0, -1) == -1
    assert stalled_side(-4.0, -1) == 1
    assert stalled_side(1.0, 1) == 0


def test_a_scrape_on_the_left_moves_the_pose_toward_the_left_wall() -> None:
    """Dead reckoning says mid-corridor, the left tread stalled: the rover is where its
    left side touches the wall at y = 165, 7.5 cm + up to a cell from the axis."""
    c = locate_contact(CORRIDOR, Pose(300, 150, 0), side=1, **BODY)
    assert c is not None and c.needed and not c.ambiguous
    assert 5.0 <= c.shift_cm <= 12.0
    assert c.pose.y == pytest.approx(150 + c.shift_cm)
    right = locate_contact(CORRIDOR, Pose(300, 150, 0), side=-1, **BODY)
    assert right is not None and right.shift_cm == pytest.approx(-c.shift_cm)


def test_a_contact_that_either_side_explains_is_ambiguous() -> None:
    """Mid-corridor with no yaw to tell the side: left and right explain it alike."""
    c = locate_contact(CORRIDOR, Pose(300, 150, 0), **BODY)
    assert c is not None and c.ambiguous


def test_a_missed_gap_is_placed_on_the_side_that_stalled() -> None:
    """In front of the gap's middle by dead reckoning, stopped: the body must be ~10 cm
    (half the gap minus half the body) off the middle, on the stalled side."""
    for side in (1, -1):
        c = locate_contact(GAP, Pose(390, 317.5, 0), side=side, **BODY)
        assert c is not None and not c.ambiguous
        assert 8.0 <= side * c.shift_cm <= 14.0


def test_a_block_the_pose_already_explains_needs_no_correction() -> None:
    """Nose against the wall by dead reckoning: nothing to correct."""
    c = locate_contact(GAP, Pose(388, 200, 0), **BODY)
    assert c is not None and not c.needed


def test_a_block_on_open_floor_is_not_a_mapped_wall() -> None:
    """Nothing mapped within reach: another rover or an unmapped thing (None)."""
    assert locate_contact(GAP, Pose(200, 200, 0), **BODY) is None


def test_backing_into_a_wall_uses_the_rear_edge() -> None:
    """Facing +x, reversing into the wall whose face is at x = 415: the rear edge (10 cm
    behind the centre) touches, so the pose moves back along the heading, not sideways;
    driving forward from there, nothing mapped is ahead."""
    c = locate_contact(GAP, Pose(432, 200, 0), direction=-1, **BODY)
    assert c is not None
    assert c.shift_cm == 0.0 and c.needed
    assert 422.0 <= c.pose.x <= 428.0
    assert locate_contact(GAP, Pose(432, 200, 0), direction=1, **BODY) is None


def test_bad_arguments_are_refused() -> None:
    with pytest.raises(ValueError, match="direction"):
        locate_contact(GAP, Pose(390, 317.5, 0), direction=0, **BODY)
    with pytest.raises(ValueError, match="body size"):
        locate_contact(GAP, Pose(390, 317.5, 0), length_cm=0.0, width_cm=15.0)


def test_the_other_edge_beyond_the_correction_window_makes_a_gap_contact_ambiguous() -> None:
    """Dead reckoning 20 cm below the truth at the gap: the rover's left front touched the
    upper wall's face (x = 400) while dead reckoning puts it 5 cm into the gap, 5 cm
    above its lower edge. Inside the 14 cm window only the lower edge explains it (the
    wrong one). Searching the other side 20 cm wider with an ambiguity as large as the
    drift (20 cm) finds the upper face: ambiguous, so navigation does not act on it."""
    dr = Pose(395.0, 312.5, 0.0)
    narrow = locate_contact(GAP, dr, **BODY)
    assert narrow is not None and not narrow.ambiguous and narrow.shift_cm < 0
    wide = locate_contact(GAP, dr, ambiguity_cm=20.0, other_shift_cm=34.0, **BODY)
    assert wide is not None and wide.ambiguous
    assert abs(wide.shift_cm) <= 14.0  # the pose offered stays within the correction window


def test_a_wider_search_alone_does_not_make_a_clear_contact_ambiguous() -> None:
    """Nose against a plain wall face: the wider window finds no other edge to blame."""
    c = locate_contact(GAP, Pose(388, 200, 0), ambiguity_cm=20.0, other_shift_cm=34.0, **BODY)
    assert c is not None and not c.needed and not c.ambiguous


def test_a_wall_face_across_the_heading_does_not_pin_the_sideways_position() -> None:
    """Nose against the long face of the gap's wall, far from the gap: the block says how
    far along the heading the rover is, not where along the face (any sideways shift
    explains it as well); at the gap's lower edge a shift either way does not (into
    the gap nothing is touched, away from it the body overlaps the wall)."""
    face = locate_contact(GAP, Pose(390, 200, 0), **BODY)
    assert face is not None and not face.needed and face.sideways_free
    edge = locate_contact(GAP, Pose(395, 312.5, 0), side=1, **BODY)
    assert edge is not None and edge.needed and not edge.sideways_free


def test_searching_as_far_along_as_the_drift_keeps_a_wall_end_contact_open() -> None:
    """Dead reckoning puts the body over the corner of the gap's lower wall. Searched only
    6 cm along the heading, a 1 cm sideways shift off the corner explains the block, and
    navigation would take it as pinning its sideways position; searched 15 cm (as far as
    a large drift reaches, ``NavOptions.contact_max_along_cm``), a pose further back
    along the heading explains it as well: ambiguous, so the sideways doubt is kept
    (cutting it would leave 3 cm of doubt with the rover 24 cm off)."""
    dr = Pose(398.0, 302.0, 0.0)
    short = locate_contact(GAP, dr, ambiguity_cm=20.0, other_shift_cm=34.0, **BODY)
    assert short is not None and short.needed
    assert not short.ambiguous and not short.sideways_free
    far = locate_contact(GAP, dr, ambiguity_cm=20.0, other_shift_cm=34.0, max_along_cm=15.0,
                         **BODY)
    assert far is not None and far.ambiguous


def test_a_head_on_contact_beside_a_gap_is_ambiguous_within_the_drift() -> None:
    """Dead reckoning puts the body in the corridor's mouth, nose at the walls' face, and
    the right side stalled: the cheapest explanation with the right side touching is
    the upper wall's face, 11 cm up, head-on (both sides touch, so the stalled side
    tells nothing). The lower wall's face, 15 cm down, explains it as well: with a
    drift of 30 cm that is ambiguous, with 3 cm it is not (a hider on the
    lower face must not be put on the upper one)."""
    dr = Pose(240.0, 157.0, 0.0)
    far = locate_contact(CORRIDOR, dr, side=-1, ambiguity_cm=30.0, other_shift_cm=44.0, **BODY)
    assert far is not None and far.shift_cm > 8.0 and far.ambiguous
    near = locate_contact(CORRIDOR, dr, side=-1, **BODY)
    assert near is not None and near.shift_cm > 8.0 and not near.ambiguous


def test_a_stalled_corner_at_a_gap_is_ambiguous_within_the_drift() -> None:
    """In the gap's mouth by dead reckoning, 4.5 cm below its middle, the right tread
    stalled: the cheapest right-side contact is the lower wall's end, 6 cm down. The
    right front corner on the upper wall's end, 20-odd cm up (dead reckoning that far
    below the truth), explains it as well; the stalled side does not tell the two walls
    apart, so with a drift of 20 cm the contact is ambiguous, with 3 cm it is not
    (moved 11 cm the wrong way, no later offset of the probe would reach the gap)."""
    dr = Pose(394.0, 313.0, 0.0)
    near = locate_contact(GAP, dr, side=-1, **BODY)
    assert near is not None and near.shift_cm <= -5.0 and not near.ambiguous
    far = locate_contact(GAP, dr, side=-1, ambiguity_cm=20.0, other_shift_cm=34.0,
                         max_along_cm=15.0, **BODY)
    assert far is not None and far.shift_cm == pytest.approx(near.shift_cm) and far.ambiguous
