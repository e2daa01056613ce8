"""Each campaign invariant can fail: real short games where it is broken on purpose.

The pure checks are tested in test_campaign_invariants.py; here a whole
system runs (virtual time, a few simulated seconds) with a stand-in
navigation or a tampered probe record, and the game's checks must name the
broken invariant. Each test also has its control: the same game untampered
keeps that invariant.
"""

from __future__ import annotations

import os

import numpy as np
import pytest
import trio

from actors import Actor, Message, virtual_clock
from actors.firmware.commands import Cmd
from actors.firmware.nav.factory import make_nav
from server.protocol import GridMap
from supervisors.harness import campaign
from supervisors.harness import invariants as inv
from supervisors.harness.campaign import CampaignConfig, plan_game, play_campaign_game, play_checked
from supervisors.harness.campaign import play as campaign_play
from world.scenario import load_scenario

_CONFIG = CampaignConfig(3, mode="none", rooms=("empty",), mapping_budget_s=8.0)


def _play(nav_factory=None) -> tuple[object, list[str]]:
    """Play the short game 3:0 (empty room, no faults) with its checks; (report, violations)."""
    spec = plan_game(_CONFIG, 0)
    campaign.seed_game_scheduler(spec.run_seed)
    report, checks = trio.run(lambda: play_checked(spec, drain_s=2.0, nav_factory=nav_factory),
                              clock=virtual_clock())
    return report, checks["violations"]


def _names(violations: list[str]) -> set[str]:
    return {v.split(":", 1)[0] for v in violations}


# ---------------------------------------------------------------------------- stand-in navs

class CrashingNav(Actor):
    """Crashes 50 ms after every start: its rover's supervisor must give up."""

    async def on_start(self) -> None:
        self.ctx.start_timer(0.05, "boom")

    async def handle(self, message: object) -> None:
        if message == "boom":
            raise RuntimeError("stand-in navigation crashes after every start")


def _map_cells(rows: int, cols: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).choice(np.array([-1, 0, 100], dtype=np.int8),
                                              (rows, cols))


class UploadingNav(Actor):
    """Mapper stand-in: uploads a small map (several reliable chunks) when the game starts."""

    def __init__(self, pool, cells: np.ndarray) -> None:
        self.pool, self.cells = pool, cells

    async def handle(self, message: object) -> None:
        if not (isinstance(message, Message) and message.type == 4):
            return
        payload = self.pool.take(int(message.value))
        if message.command == Cmd.NAV_NET and getattr(payload, "cmd", "") == "start":
            handle = self.pool.put(GridMap(self.cells, 5.0, (-50.0, -50.0)))
            await self.ctx.cast("mapper/wifly", Message.handle(Cmd.WIFLY_SEND_MAP, handle))


def uploading(role, *, pool, **kw):
    """The real navigation, except a mapper that uploads a fixed map at once."""
    if role == "mapper":
        return UploadingNav(pool, _map_cells(60, 80, 5))
    return make_nav(role, pool=pool, **kw)


def unseeded(role, *, pool, **kw):
    """A nondeterministic mapper: its map's size comes from the OS, not the run's seed."""
    if role == "mapper":
        noise = int.from_bytes(os.urandom(8), "little")
        rows, cols = 20 + noise % 80, 20 + (noise >> 8) % 80
        return UploadingNav(pool, _map_cells(rows, cols, noise >> 16))
    return make_nav(role, pool=pool, **kw)


class PeekingNav(Actor):
    """A cheating hider: it holds the scenario, i.e. the room's ground truth."""

    def __init__(self, pool, spec) -> None:
        self.pool, self.spec = pool, spec
        self.room = load_scenario("empty")

    async def handle(self, message: object) -> None:
        if isinstance(message, Message) and message.type == 4:
            self.pool.take(int(message.value))


# ---------------------------------------------------------------------------- liveness

def test_liveness_names_a_supervisor_that_gave_up_and_the_actors_it_left_dead():
    """A navigation that crashes after every start exhausts the hider's restart intensity."""
    def factory(role, *, pool, **kw):
        return CrashingNav() if role == "hider" else make_nav(role, pool=pool, **kw)

    _, violations = _play(factory)
    assert "liveness.ended" in _names(violations)
    dead = next(v for v in violations if v.startswith("liveness.actor_dead"))
    assert "hider/nav stopped" in dead and "hider/wifly stopped" in dead
    assert "mapper/" not in dead
    gave_up = next(v for v in violations if v.startswith("liveness.gave_up"))
    assert gave_up.startswith("liveness.gave_up: hider at ")


def test_liveness_control_the_real_navigation_leaves_every_actor_running():
    _, violations = _play()
    assert _names(violations) == {"liveness.ended"}  # 8 s cannot map a room; nothing else


# ---------------------------------------------------------------------------- no loss

def test_no_loss_control_every_chunk_delivered_once_and_the_map_stored():
    report, violations = _play(uploading)
    assert any("map=1 nx=80 ny=60" in line for line in report.events)  # the server got it
    assert not [v for v in violations if v.startswith("no_loss")]


def test_no_loss_names_a_frame_the_server_never_delivered(monkeypatch):
    """A probe record with the first map chunk missing reads as a lost frame."""
    original = inv.DeliveryProbe.note_delivered
    skipped: list[int] = []

    def forgetful(self, role, frame):
        if frame.cmd == "map" and not skipped:
            skipped.append(frame.seq)
            return
        original(self, role, frame)

    monkeypatch.setattr(inv.DeliveryProbe, "note_delivered", forgetful)
    _, violations = _play(uploading)
    lost = [v for v in violations if v.startswith("no_loss.lost")]
    assert skipped and len(lost) == 1
    assert lost[0].startswith("no_loss.lost: mapper: 1 of ")
    assert f"e.g. {skipped[0]}|map|" in lost[0]


def test_no_loss_names_a_frame_delivered_twice(monkeypatch):
    original = inv.DeliveryProbe.note_delivered

    def stuttering(self, role, frame):
        original(self, role, frame)
        if frame.cmd == "map":
            original(self, role, frame)

    monkeypatch.setattr(inv.DeliveryProbe, "note_delivered", stuttering)
    _, violations = _play(uploading)
    assert [v.split(":", 2)[:2] for v in violations if v.startswith("no_loss")] == [
        ["no_loss.duplicate", " mapper"]]


def test_no_loss_names_a_stored_map_that_differs_from_the_uploaded_one(monkeypatch):
    """A store that changed one cell of the mapper's map breaks no-loss."""
    real = campaign_play._stored_map

    def tampered(system, store):
        grid = real(system, store)
        cells = np.array(grid.cells)
        cells[0, 0] = 100 if cells[0, 0] != 100 else 0
        return GridMap(cells, grid.resolution_cm, grid.origin_cm)

    monkeypatch.setattr(campaign_play, "_stored_map", tampered)
    _, violations = _play(uploading)
    assert "no_loss.map: stored map differs from the uploaded one: 1 cells" in violations


# ---------------------------------------------------------------------------- honesty

def test_honesty_names_firmware_that_holds_the_rooms_ground_truth():
    def factory(role, *, pool, **kw):
        return PeekingNav(pool, kw["spec"]) if role == "hider" else make_nav(role, pool=pool,
                                                                              **kw)

    _, violations = _play(factory)
    honesty = [v for v in violations if v.startswith("honesty")]
    assert honesty == [
        "honesty: hider/nav.Scenario holds a world object world.scenario.Scenario"]


def test_honesty_control_firmware_may_keep_its_own_hardware_spec():
    """The hider stand-in without the scenario (it still keeps its spec) is honest."""
    class Honest(PeekingNav):
        def __init__(self, pool, spec) -> None:
            self.pool, self.spec = pool, spec

    def factory(role, *, pool, **kw):
        return Honest(pool, kw["spec"]) if role == "hider" else make_nav(role, pool=pool, **kw)

    _, violations = _play(factory)
    assert not [v for v in violations if v.startswith("honesty")]


# ---------------------------------------------------------------------------- determinism

@pytest.mark.parametrize("factory, broken", [(uploading, False), (unseeded, True)],
                         ids=["seeded", "unseeded"])
def test_determinism_catches_a_game_that_plays_differently_twice(factory, broken):
    """The worker's replay names a navigation that draws from the OS instead of the seed."""
    ref = _CONFIG.game_ref(0)
    result = play_campaign_game(ref, determinism=True, nav_factory=factory)
    mismatch = [v for v in result["violations"] if v.startswith("determinism")]
    assert result["replay_hash"] and result["trace_hash"]
    assert (result["replay_hash"] != result["trace_hash"]) is broken
    assert bool(mismatch) is broken


# ---------------------------------------------------------------------------- truth

def test_truth_accepts_a_found_on_a_hider_in_view_and_names_one_out_of_view():
    assert inv.check_found_is_true("found", [True]) == []
    assert inv.check_found_is_true("not_found", []) == []
    assert inv.check_found_is_true("found", [False, True]) == []  # the last report ends it
    (v,) = inv.check_found_is_true("found", [True, False])
    assert v.name == "truth.false_found" and "out of its IR sensor's view" in v.detail
    (v,) = inv.check_found_is_true("found", [])
    assert v.name == "truth.false_found"


def _play_whole_empty_game() -> tuple[object, list[str]]:
    from supervisors.harness.headless import Budget  # noqa: PLC0415

    campaign.seed_game_scheduler(1)
    report, checks = trio.run(lambda: campaign_play.play_checked_scenario(
        load_scenario("empty"), 1, Budget(), drain_s=2.0), clock=virtual_clock())
    return report, checks["violations"]


def test_truth_control_a_real_found_keeps_the_invariant():
    report, violations = _play_whole_empty_game()
    assert report.outcome == "found" and not [v for v in violations if v.startswith("truth")]


def test_truth_names_a_found_the_world_says_was_out_of_view(monkeypatch):
    """The same game, with the world's ground truth saying the hider was out of view at the
    found report: the campaign names it a false found."""
    from world.world import World  # noqa: PLC0415

    monkeypatch.setattr(World, "hider_in_ir_view", lambda self: False)
    report, violations = _play_whole_empty_game()
    assert report.outcome == "found"
    assert "truth.false_found" in _names(violations)
