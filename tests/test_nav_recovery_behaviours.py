"""The recovery behaviours of a blocked route, each through its one entry point
(`decide(view) -> action`), tried in the order of `recovery.RECOVERIES`."""

from __future__ import annotations

from dataclasses import dataclass, field

import pytest

from actors.firmware.nav.recovery import (
    RECOVERIES,
    REPLAN_LIMIT,
    STALL_HOLDS,
    Action,
    BackOff,
    BackOffAndReplan,
    GiveUp,
    GiveUpRoute,
    Hold,
    NudgeSideways,
    Relocalise,
    Replan,
    ReplanWedged,
    WaitOutStall,
)


@dataclass
class View:
    """What `recovery.BlockView` answers, set by the test; ``asked`` records the order
    of the questions that have side effects or cost (the contact update first)."""

    why: str = "blocked"
    replans: int = 1
    stall_holds: int = 0
    tread_hold_s: float = 12.0
    backoff_cm: float = 6.0
    length_cm: float = 20.0
    obstacle_cm: float = 7.5
    here: tuple[float, float, float] = (100.0, 50.0, 0.0)
    last_block: tuple[float, float, float] | None = None
    anchored: bool = False
    ahead: tuple[float, float] = (120.5, 50.0)
    is_stalled: bool = False
    stuck: bool = False
    moved: bool = False
    passage: bool = False
    mouth: bool = False
    asked: list[str] = field(default_factory=list)

    @property
    def blocked(self) -> bool:
        return self.why == "blocked"

    def stalled(self) -> bool:
        return self.is_stalled

    def backoff_stuck(self) -> bool:
        return self.stuck

    def contact_moved(self) -> bool:
        self.asked.append("contact")
        return self.blocked and self.moved

    def in_passage(self) -> bool:
        self.asked.append("passage")
        return self.blocked and self.passage

    def at_mouth(self) -> bool:
        return self.in_passage() and self.mouth


def first_action(view: View) -> Action:
    """The action of the first behaviour that answers, as `RouteNav.blocked_route` takes it."""
    for recovery in RECOVERIES:
        action = recovery.decide(view)  # type: ignore[arg-type]
        if action is not None:
            return action
    raise AssertionError("no behaviour answered")


def test_the_behaviours_are_tried_in_order() -> None:
    """Stall, give up, wedged, passage, contact, back off."""
    assert [type(r) for r in RECOVERIES] == [WaitOutStall, GiveUp, ReplanWedged,
                                             NudgeSideways, Relocalise, BackOff]


def test_a_stalled_back_off_holds_uncounted_each_hold_twice_as_long() -> None:
    """The first ``STALL_HOLDS`` stalls of a route hold 12, 24, 48 s and give back the two
    blocks; after them a stall is an ordinary block."""
    holds = [first_action(View(is_stalled=True, stall_holds=k)) for k in range(STALL_HOLDS)]
    assert holds == [Hold(12.0 * 2 ** k, uncount=2) for k in range(STALL_HOLDS)]
    assert first_action(View(is_stalled=True, stall_holds=STALL_HOLDS)) == \
        BackOffAndReplan(6.0, mark=True)


def test_too_many_blocks_give_the_route_up_with_the_reason() -> None:
    """One block more than ``REPLAN_LIMIT``: given up, saying why and how often; a stall
    still holds first."""
    view = View(replans=REPLAN_LIMIT + 1)
    assert first_action(view) == GiveUpRoute(f"blocked {REPLAN_LIMIT + 1} times")
    assert first_action(View(why="no progress", replans=REPLAN_LIMIT + 1)) == GiveUpRoute(
        f"no progress {REPLAN_LIMIT + 1} times")
    assert isinstance(first_action(View(replans=REPLAN_LIMIT + 1, is_stalled=True)), Hold)


def test_a_back_off_that_did_not_move_replans_where_it_stands() -> None:
    """After the stall holds, a back-off that did not move (wedged) replans; one that did
    backs off again."""
    assert first_action(View(stuck=True, stall_holds=STALL_HOLDS)) == Replan()
    assert isinstance(first_action(View(stall_holds=STALL_HOLDS)), BackOffAndReplan)


def test_the_contact_update_comes_before_the_passage_is_judged() -> None:
    """The contact weighs the belief, so the passage is judged from the corrected pose."""
    view = View(passage=True)
    first_action(view)
    assert view.asked[:2] == ["contact", "passage"]


@pytest.mark.parametrize("moved, passage, mouth, anchored, expected", [
    (False, True, False, False, BackOffAndReplan(6.0, probe=True)),
    (False, True, True, False, BackOffAndReplan(6.0, probe=True, mouth=True)),
    (True, True, True, True, BackOffAndReplan(6.0, probe=True, mouth=True)),
    (True, True, True, False, BackOffAndReplan(6.0, anchor=True)),
    (True, False, False, False, BackOffAndReplan(6.0)),
], ids=["passage-unchanged", "mouth-unchanged", "mouth-again", "mouth-contact", "contact"])
def test_a_passage_probes_sideways_and_a_contact_relocalises(
        moved: bool, passage: bool, mouth: bool, anchored: bool,
        expected: BackOffAndReplan) -> None:
    """A passage met with the pose unchanged, or its mouth met again once a series is
    anchored, probes sideways; a contact that moved the pose backs off and replans from
    it, anchoring a probe series at a mouth."""
    view = View(moved=moved, passage=passage, mouth=mouth, anchored=anchored)
    assert first_action(view) == expected


def test_a_second_block_near_the_first_learns_an_obstacle_and_backs_off_further() -> None:
    """Nothing explains a block: it is remembered; a second within 30 cm of the first
    learns an obstacle as wide as the body's front ahead and backs off a body length."""
    assert first_action(View()) == BackOffAndReplan(6.0, mark=True)
    near = View(last_block=(110.0, 60.0, 0.0))
    assert first_action(near) == BackOffAndReplan(20.0, mark=True,
                                                  obstacle=(120.5, 50.0, 7.5))
    assert first_action(View(last_block=(200.0, 50.0, 0.0))) == BackOffAndReplan(
        6.0, mark=True)
    assert first_action(View(why="no progress")) == BackOffAndReplan(6.0)
