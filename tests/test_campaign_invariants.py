"""Campaign invariants: the pure checks, the probes, and a tapped run keeping its trace hash."""

from __future__ import annotations

import dataclasses
import json
from collections import Counter
from types import SimpleNamespace

import msgspec
import numpy as np
import pytest
import trio

from actors import EventKind, Trace, virtual_clock
from server.protocol import GridMap, Reason, encode_frame, make_frame, map_chunks
from supervisors.harness import invariants as inv
from supervisors.harness.campaign import (
    CampaignConfig,
    plan_game,
    play_checked,
    seed_game_scheduler,
)
from supervisors.harness.headless import Budget, run_game

# ---------------------------------------------------------------------------- pure checks


def test_ended_accepts_found_and_not_found_only():
    assert inv.check_ended("found", "") == []
    assert inv.check_ended("not_found", "") == []
    assert inv.check_ended("failed", "mapping did not finish within 60 s") == [
        inv.Violation("liveness.ended", "mapping did not finish within 60 s")]


def test_actors_alive_names_the_dead_firmware_actors():
    states = {"mapper/nav": "running", "hider/motor": "stopped", "seeker/ir": "restarting",
              "mapper": "stopped"}  # a supervisor's own name is not a firmware actor
    assert inv.check_actors_alive(states) == [
        inv.Violation("liveness.actor_dead", "hider/motor stopped, seeker/ir restarting")]
    assert inv.check_actors_alive({"mapper/nav": "running"}) == []


def test_escalation_breaks_liveness_only_for_a_single_fault():
    gave_up = ["mapper at 12.0 s"]
    assert inv.check_no_escalation(gave_up, faults_fired=1)[0].name == "liveness.gave_up"
    assert inv.check_no_escalation(gave_up, faults_fired=0)[0].name == "liveness.gave_up"
    assert inv.check_no_escalation(gave_up, faults_fired=2) == []
    assert inv.check_no_escalation([], faults_fired=1) == []


def _delivery(due, sent, delivered):
    return inv.Delivery(set(due), set(sent), Counter(delivered))


def test_exactly_once_finds_lost_duplicate_and_phantom_frames():
    per_role = {
        "hider": _delivery({"1|arrived|a", "2|arrived|b"}, {"1|arrived|a", "2|arrived|b"},
                           {"1|arrived|a": 1}),
        "seeker": _delivery({"1|found|x"}, {"1|found|x"}, {"1|found|x": 2, "9|found|y": 1}),
    }
    got = inv.check_exactly_once(per_role)
    assert [v.name for v in got] == ["no_loss.lost", "no_loss.duplicate", "no_loss.phantom"]
    assert got[0].detail.startswith("hider: 1 of 2 reliable frames never delivered")


def test_exactly_once_lets_late_frames_be_in_flight():
    """A frame sent after the cut may still be on its way; one sent before may not."""
    late = _delivery(set(), {"5|not_found|r"}, {})
    assert inv.check_exactly_once({"seeker": late}) == []


def _grid(cells, res=5.0, origin=(0.0, 0.0)):
    return GridMap(np.array(cells, dtype=np.int8), res, origin)


def test_maps_equal_compares_cells_and_placement():
    a = _grid([[0, 100], [-1, 0]])
    assert inv.check_maps_equal(a, _grid([[0, 100], [-1, 0]])) == []
    assert inv.check_maps_equal(None, None) == []
    assert inv.check_maps_equal(a, _grid([[0, 0], [-1, 0]])) == [
        inv.Violation("no_loss.map", "stored map differs from the uploaded one: 1 cells")]
    assert inv.check_maps_equal(a, _grid([[0, 100], [-1, 0]], origin=(5.0, 0.0)))[0].name == \
        "no_loss.map"
    assert inv.check_maps_equal(None, a) == [inv.Violation("no_loss.map",
                                                           "the server stored no map")]


def test_determinism_compares_hashes():
    assert inv.check_determinism("abc", None) == []
    assert inv.check_determinism("abc", "abc") == []
    assert inv.check_determinism("abc", "abd")[0].name == "determinism"


class _Live:
    """A world object with state (its class pretends to live in the world package)."""


_Live.__module__ = "world.fake"


@dataclasses.dataclass(frozen=True)
class _Spec:
    """A frozen value record from the world (like the hardware's spec)."""

    width_cm: float = 15.0


_Spec.__module__ = "world.fake"


@dataclasses.dataclass(frozen=True)
class _Room:
    """A frozen world record that is not the hardware's (like the scenario: ground truth)."""

    walls: tuple = ((0, 0, 400, 0),)


_Room.__module__ = "world.fake"


def test_honesty_flags_a_world_object_other_than_the_own_hardware():
    hardware, other = _Live(), _Live()
    actor = SimpleNamespace(hw=hardware, spec=_Spec(), cache={"peer": [SimpleNamespace(h=other)]})
    got = inv.check_honesty({"hider/nav": actor}, {"hider/nav": (hardware, _Spec())})
    assert len(got) == 1 and got[0].name == "honesty"
    assert "world.fake._Live" in got[0].detail
    clean = SimpleNamespace(hw=hardware, spec=_Spec(), log=[1, 2])
    assert inv.check_honesty({"hider/nav": clean}, {"hider/nav": (hardware, _Spec())}) == []


def test_honesty_accepts_only_frozen_records_of_the_allowed_kinds():
    """A copy of the spec is a value the firmware was built with; the frozen room is not."""
    hardware = _Live()
    peeking = SimpleNamespace(hw=hardware, spec=_Spec(), room=_Room())
    got = inv.check_honesty({"hider/nav": peeking}, {"hider/nav": (hardware, _Spec())})
    assert [v.detail for v in got] == ["hider/nav._Room holds a world object world.fake._Room"]
    bare = SimpleNamespace(spec=_Spec())  # no spec allowed: even the spec is flagged
    assert inv.check_honesty({"server": bare}, {"server": None})[0].name == "honesty"


def test_module_honesty_holds_for_the_firmware_and_server_as_loaded():
    import actors.firmware  # noqa: F401, PLC0415 - make sure they are loaded
    import server  # noqa: F401, PLC0415
    assert inv.check_module_honesty() == []


# ---------------------------------------------------------------------------- probes

def _line(cmd, data, seq):
    frame = make_frame(cmd, data)
    return encode_frame(msgspec.structs.replace(frame, seq=seq))


def test_delivery_probe_keys_reliable_frames_and_ignores_resends_and_unreliable():
    clock = iter([1.0, 2.0, 3.0, 4.0])
    probe = inv.DeliveryProbe(lambda: next(clock))
    tap = probe.taps.setdefault("seeker", inv._RoleTap())
    nf = _line("not_found", Reason("nothing here"), 4)
    probe.note_sent(tap, nf[:10])            # split across writes
    probe.note_sent(tap, nf[10:] + _line("heartbeat", None, None) + b"garbage\n")
    probe.note_sent(tap, nf)                 # a resend: first sending time is kept
    assert list(tap.first_sent.values()) == [1.0]
    assert probe.pending(before=5.0) == 1 and probe.pending(before=0.5) == 0
    frame = msgspec.structs.replace(make_frame("not_found", Reason("nothing here")), seq=4)
    probe.note_delivered("seeker", frame)
    assert probe.pending(before=5.0) == 0
    assert inv.check_exactly_once(probe.sent_and_delivered(5.0)) == []
    probe.note_delivered("seeker", frame)
    assert [v.name for v in inv.check_exactly_once(probe.sent_and_delivered(5.0))] == [
        "no_loss.duplicate"]


def test_delivery_probe_assembles_the_map_as_it_left_the_rover():
    probe = inv.DeliveryProbe(lambda: 0.0)
    tap = probe.taps.setdefault("mapper", inv._RoleTap())
    cells = np.random.default_rng(1).choice(np.array([-1, 0, 100], dtype=np.int8), (40, 60))
    grid = GridMap(cells, 5.0, (-100.0, -50.0))
    frames = map_chunks(grid, 1)
    assert len(frames) > 1
    for k, f in enumerate(frames, start=10):
        probe.note_sent(tap, encode_frame(msgspec.structs.replace(f, seq=k)))
    assert inv.check_maps_equal(grid, probe.uploaded_map()) == []


def test_trace_counts_count_escalations_and_refused_faults():
    async def main():
        trace = Trace()
        counts = inv.TraceCounts(trace)
        trace.emit(EventKind.RESTART, "hider/motor")
        trace.emit(EventKind.ESCALATE, "hider")
        trace.emit(EventKind.FAULT, "hider/nose", detail="refused: no actor")
        counts.close()
        trace.emit(EventKind.RESTART, "hider/motor")  # after close: not counted
        return counts

    counts = trio.run(main, clock=virtual_clock())
    assert counts.counts == Counter({"restart": 1, "escalate": 1, "fault": 1})
    assert counts.escalations == ["hider at 0.0 s"]
    assert counts.refused_faults == ["hider/nose: refused: no actor"]


# ---------------------------------------------------------------------------- a real system

@pytest.mark.parametrize("mode", ["none", "single"])
def test_a_tapped_campaign_game_keeps_the_trace_hash_of_hideseek_run(mode):
    """The probes change nothing: run_game on the same scenario and seed gives the same hash."""
    config = CampaignConfig(3, mode=mode, rooms=("empty",), kinds=("actor:crash",),
                            window_s=(1.0, 4.0), mapping_budget_s=8.0)
    spec = plan_game(config, 0)
    seed_game_scheduler(spec.run_seed)
    report, checks = trio.run(lambda: play_checked(spec, drain_s=2.0), clock=virtual_clock())
    seed_game_scheduler(spec.run_seed)
    plain = trio.run(lambda: run_game(spec.scenario(), spec.run_seed,
                                      budget=Budget(mapping=8.0)), clock=virtual_clock())
    assert report.trace_hash == plain.trace_hash != ""
    assert report.outcome == "failed"  # 8 s is too short to map a room
    assert checks["violations"][0].startswith("liveness.ended: mapping did not finish")
    assert checks["faults_fired"] == (1 if mode == "single" else 0)
    if mode == "single":
        assert checks["events"].get("crash", 0) >= 1


def test_a_campaign_game_replays_in_process_and_reproduces_through_hideseek_run(capsys):
    """Determinism: the worker's replay and `hideseek run --campaign REF` give its trace hash."""
    from supervisors.harness.campaign import play_campaign_game  # noqa: PLC0415
    from tui.cli import main  # noqa: PLC0415

    ref = "4:2,rooms=empty,faults=actor:hang,window=1-3,budget=6"
    result = play_campaign_game(ref, determinism=True)
    assert result["faults_fired"] == 1
    assert result["replay_hash"] == result["trace_hash"] != ""
    assert not [v for v in result["violations"] if v.startswith("determinism")]
    command = result["reproduce"].split()
    assert command[:2] == ["hideseek", "run"]  # the failure list prints this command
    assert main([*command[1:], "--json"]) == 1  # 6 s cannot map a room
    assert json.loads(capsys.readouterr().out)["trace_hash"] == result["trace_hash"]
