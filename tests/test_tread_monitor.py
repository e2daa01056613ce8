"""The tread monitor alone: findings from counts and a modelled lag, no actors."""

from __future__ import annotations

from collections.abc import Callable

from actors.firmware.drivers.motor import MotorTuning
from actors.firmware.drivers.tread_monitor import TreadFault, TreadMonitor, TreadVerdict


def drive(monitor: TreadMonitor, seconds: float,
          counts: tuple[float, float] | Callable[[float], tuple[float, float]],
          moving: bool = True) -> list[tuple[TreadVerdict, TreadFault]]:
    """Drive both treads at full PWM for ``seconds``; each tread counts the given share
    of its modelled travel (``counts``, or ``counts(t)`` at time ``t``). Returns every
    finding, control step by control step."""
    share = counts if callable(counts) else lambda _t: counts
    found = []
    t, owed = 0.0, [0.0, 0.0]
    monitor.begin(0.0)
    monitor.pwm = (1.0, 1.0) if moving else (-1.0, 1.0)
    while t < seconds:
        t += 0.05
        before = list(monitor.modelled)
        monitor.advance(t)
        for tread in (0, 1):
            owed[tread] += (monitor.modelled[tread] - before[tread]) * share(t)[tread]
            while owed[tread] >= 0.5:
                owed[tread] -= 0.5
                monitor.tick(tread, t)
        found += monitor.watch(moving, period_pending=False)
    return found


def monitor(mapper: bool = False) -> TreadMonitor:
    return TreadMonitor(MotorTuning(), 0.5, 30.0, mapper=mapper)


def test_healthy_treads_give_no_finding() -> None:
    assert drive(monitor(), 2.0, (1.0, 1.0)) == []


def test_a_tread_that_never_counts_is_silent() -> None:
    assert drive(monitor(), 1.0, (0.0, 1.0)) == [(TreadVerdict.FAULT, TreadFault.silent(0))]


def test_a_tread_counting_half_in_a_move_counts_short() -> None:
    found = drive(monitor(), 2.0, (1.0, 0.45))
    assert found == [(TreadVerdict.FAULT, TreadFault.short(1))]


def test_both_counting_short_is_one_finding_for_the_mapper() -> None:
    assert drive(monitor(mapper=True), 2.0, (0.4, 0.4)) == [
        (TreadVerdict.FAULT, TreadFault.BOTH_SHORT)]


def test_both_hardly_counting_in_a_move_is_a_push() -> None:
    verdicts = [v for v, _ in drive(monitor(), 2.0, (0.05, 0.05))]
    assert TreadVerdict.PUSH in verdicts


def test_tread_fault_names_read_as_the_payload_bits() -> None:
    assert [int(TreadFault.silent(0)), int(TreadFault.silent(1)), int(TreadFault.short(0)),
            int(TreadFault.short(1)), int(TreadFault.BOTH_SILENT), int(TreadFault.BOTH_SHORT)] \
        == [0, 1, 2, 3, 4, 6]
    assert TreadFault(3).side == "right" and TreadFault(3).counts_short
    assert TreadFault(6).both and TreadFault(4).side == "both" and not TreadFault(4).counts_short


def test_a_fault_names_the_treads_it_reports() -> None:
    """Values 0/2 report the left tread, 1/3 the right, 4/6 both (what the beliefs widen)."""
    assert [TreadFault(v).treads for v in (0, 1, 2, 3, 4, 6)] == [
        (True, False), (False, True), (True, False), (False, True), (True, True), (True, True)]


def turns(monitor: TreadMonitor, n: int, counts: tuple[float, float],
          seconds: float = 0.12) -> list[list[tuple[TreadVerdict, TreadFault]]]:
    """``n`` short turns in a row (each ~2-3 cm of modelled travel per tread, a look's
    20 deg step); the findings of each."""
    return [drive(monitor, seconds, counts, moving=False) for _ in range(n)]


def test_short_turns_too_short_to_judge_alone_are_judged_together() -> None:
    """Both encoders slipping at 0.45 in a run of look turns, each too short for the
    interrupts' lag to let the model tell: the first turn alone says nothing, the run
    says both count short."""
    m = monitor()
    found = turns(m, 4, (0.45, 0.45))
    assert found[0] == []
    assert [(TreadVerdict.FAULT, TreadFault.BOTH_SHORT)] in found[1:]
    travel = max(m.modelled)  # each turn alone was too short for the model to tell
    assert not m.beyond(0.55 * travel, travel)


def test_healthy_short_turns_give_no_finding() -> None:
    assert turns(monitor(), 12, (1.0, 1.0)) == [[]] * 12


def test_a_move_clears_the_carried_turns() -> None:
    """Short slipping turns, then a move: the move is judged on its own travel (a short
    healthy move gives no finding), and the turn after it starts a new run."""
    m = monitor()
    assert turns(m, 1, (0.45, 0.45)) == [[]]
    assert drive(m, 0.12, (1.0, 1.0)) == []
    assert turns(m, 1, (0.45, 0.45)) == [[]]


def test_a_push_after_a_both_short_report_still_ends_the_move() -> None:
    """Both encoders slipping at 0.45 in a hider's move (value 6), then the rover meets a
    wall and the treads hardly count: the push is found all the same (the move ends
    blocked), once."""
    found = drive(monitor(), 3.0, lambda t: (0.45, 0.45) if t < 1.0 else (0.05, 0.05))
    assert found == [(TreadVerdict.FAULT, TreadFault.BOTH_SHORT),
                     (TreadVerdict.PUSH, TreadFault.BOTH_SHORT)]
