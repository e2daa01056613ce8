"""benchmarks.sample: which phase of the game a sample is counted in."""

from __future__ import annotations

from types import SimpleNamespace

from benchmarks.sample import _PhaseWatch
from server.game import Phase


def _system(phase: Phase) -> SimpleNamespace:
    return SimpleNamespace(server=SimpleNamespace(game=SimpleNamespace(phase=phase)))


def test_samples_are_counted_in_the_phase_the_server_game_is_in() -> None:
    watch = _PhaseWatch()
    assert watch.phase() == "start"  # before the system is open
    expected = {Phase.IDLE: "start", Phase.MAPPING: "mapping", Phase.MAP_READY: "hiding",
                Phase.HIDING: "hiding", Phase.HIDDEN: "seeking", Phase.SEEKING: "seeking",
                Phase.FOUND: "end", Phase.NOT_FOUND: "end"}
    for phase, name in expected.items():
        watch.started(_system(phase))
        assert watch.phase() == name, phase
    watch.finished(_system(Phase.FOUND), None)
    assert watch.phase() == "end"  # the system is closing
