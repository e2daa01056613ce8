"""Trips through narrow passages (world/passages.py) and how campaigns count them."""

from __future__ import annotations

import pytest

from supervisors.harness.campaign import (
    CampaignConfig,
    CampaignError,
    parse_game_ref,
    plan_game,
    summarize,
)
from supervisors.harness.campaign.play import play_campaign_game
from supervisors.recording.runinfo import RunInfo
from tui import cmd_campaign
from world.passages import PassageCounter, narrow_passages
from world.scenario import generate_scenario, load_scenario


def _drive(counter: PassageCounter, role: str, points: list[tuple[float, float]],
           step: float = 2.0) -> None:
    """Feed the counter the straight legs between ``points``, ``step`` cm apart."""
    for (x0, y0), (x1, y1) in zip(points, points[1:], strict=False):
        n = max(1, int(max(abs(x1 - x0), abs(y1 - y0)) / step))
        for k in range(n + 1):
            counter.update(role, x0 + (x1 - x0) * k / n, y0 + (y1 - y0) * k / n)


def test_the_corridor_is_one_passage_of_its_width() -> None:
    (p,) = narrow_passages(load_scenario("corridor"))
    assert p.width_cm == pytest.approx(30.0)
    assert p.contains(*p.centre) and p.contains(300, 140) and p.contains(450, 158)
    assert not p.contains(200, 150) and not p.contains(300, 100)
    assert abs(p.axis[0]) == pytest.approx(1.0)  # the corridor runs along x


def test_an_open_room_has_no_passage() -> None:
    assert narrow_passages(load_scenario("empty")) == []


def test_a_drive_through_the_corridor_is_one_entry_through() -> None:
    counter = PassageCounter(narrow_passages(load_scenario("corridor")))
    _drive(counter, "hider", [(100, 150), (600, 150)])
    assert counter.summary() == {"hider": {"entries": 1, "through": 1, "back": 0,
                                           "inside": 0}}


def test_a_drive_near_one_side_of_a_gap_is_an_entry_through() -> None:
    """Off the centre line (a rover 15 cm wide in a gap up to 45 cm has room to be)."""
    for i in range(6):
        s = generate_scenario(5, i, "passages")
        for p in narrow_passages(s):
            counter = PassageCounter([p])
            y = p.centre[1] + 0.4 * p.width_cm * (1 if i % 2 else -1)
            x0, _, x1, _ = p.bounds
            _drive(counter, "hider", [(x0 - 40, y), (x1 + 40, y)])
            assert counter.summary()["hider"] == {"entries": 1, "through": 1, "back": 0,
                                                  "inside": 0}


def test_a_rover_that_backs_out_came_back_and_one_left_inside_is_counted_inside() -> None:
    counter = PassageCounter(narrow_passages(load_scenario("corridor")))
    _drive(counter, "seeker", [(100, 150), (350, 150), (100, 150), (600, 150), (350, 150)])
    assert counter.summary() == {"seeker": {"entries": 3, "through": 1, "back": 1,
                                            "inside": 1}}


def test_a_rover_that_stays_clear_of_passages_enters_none() -> None:
    counter = PassageCounter(narrow_passages(load_scenario("corridor")))
    _drive(counter, "mapper", [(50, 50), (200, 250), (50, 250)])
    assert counter.summary() == {"mapper": {"entries": 0, "through": 0, "back": 0,
                                            "inside": 0}}


def test_each_wall_of_a_passage_room_is_one_passage_of_25_to_45_cm() -> None:
    for i in range(20):
        s = generate_scenario(5, i, "passages")
        walls = {g.bounds[0] for g in s.obstacles if g.bounds[1] == 0
                 and g.bounds[3] < s.room_size[1]}
        widths = [p.width_cm for p in narrow_passages(s)]
        assert len(widths) == len(walls)
        assert all(25.0 - 1e-9 <= w <= 45.0 + 1e-9 for w in widths)


# ---------------------------------------------------------------------------- campaigns

def test_the_family_names_generated_rooms_and_its_reference_round_trips() -> None:
    config = CampaignConfig(9, family="passages")
    assert config.generated
    assert config.game_ref(4) == "9:4,rooms=generated,family=passages"
    assert parse_game_ref(config.game_ref(4)) == (config, 4)
    spec = plan_game(config, 4)
    assert spec.room == "generated"
    assert spec.scenario().source == "generated:passages:9/4"
    assert CampaignConfig(9, generated=True).game_ref(4) == "9:4,rooms=generated"


@pytest.mark.parametrize(("kw", "message"), [
    ({"family": "mazes"}, "room family must be one of obstacles, passages, got 'mazes'"),
    ({"family": "passages", "rooms": ("gap",)}, "a room family is for generated rooms"),
])
def test_a_bad_family_is_refused_clearly(kw: dict, message: str) -> None:
    with pytest.raises(CampaignError, match=message):
        CampaignConfig(1, **kw)
    with pytest.raises(CampaignError, match="room family must be one of"):
        parse_game_ref("1:0,family=mazes")


def test_the_cli_family_option_makes_the_rooms_passage_rooms() -> None:
    parser = cmd_campaign.argparse.ArgumentParser()
    cmd_campaign.add_arguments(parser)
    config = cmd_campaign.config_from_args(parser.parse_args(["--family", "passages"]))
    assert config.generated and config.family == "passages"
    default = cmd_campaign.config_from_args(parser.parse_args(["--generated"]))
    assert default.family == "obstacles"


def _result(index: int, outcome: str, passages: dict) -> dict:
    return {"index": index, "outcome": outcome, "violations": [], "faults": [],
            "sim_s": 100.0, "restarts": 0, "resent": 0, "dropped": 0, "replay_hash": None,
            "room": "generated", "reason": "", "reproduce": "", "baseline": None,
            "passages": passages}


def test_the_summary_counts_passage_entries_and_the_games_with_one_that_found() -> None:
    trips = {"hider": {"entries": 3, "through": 1, "back": 1, "inside": 1},
             "seeker": {"entries": 1, "through": 1, "back": 0, "inside": 0}}
    results = [_result(0, "found", trips), _result(1, "failed", trips),
               _result(2, "found", {"hider": {"entries": 0, "through": 0, "back": 0,
                                              "inside": 0}}),
               _result(3, "found", {})]
    p = summarize(CampaignConfig(1, family="passages"), results, wall_s=1.0,
                  workers=1)["passages"]
    assert (p["games_with_entries"], p["found"], p["found_rate"]) == (2, 1, 0.5)
    assert (p["entries"], p["through"], p["back"], p["inside_at_end"]) == (8, 4, 2, 2)
    assert p["by_rover"]["hider"] == {"entries": 6, "through": 2, "back": 2, "inside": 2}


def test_a_campaign_game_in_a_passage_room_counts_every_rovers_trips() -> None:
    """A real game (about 10 CPU s): the hide spot lies beyond every wall's passage and
    the decoy before them, so a game that found the hider has the hider and the seeker
    through each at least once; every entry ended or is still inside."""
    out = play_campaign_game("901:0,mode=none,rooms=generated,family=passages",
                             baseline=False)
    assert out["violations"] == []
    trips = out["passages"]
    assert out["outcome"] == "found"
    walls = len(narrow_passages(plan_game(*parse_game_ref(out["ref"])).scenario()))
    assert trips["hider"]["through"] >= walls and trips["seeker"]["through"] >= walls
    for t in trips.values():
        assert t["entries"] == t["through"] + t["back"] + t["inside"]


def test_a_recordings_reference_rebuilds_the_room_of_either_family() -> None:
    for family, ref in (("obstacles", "generated:3:2"), ("passages", "generated:passages:3:2")):
        room = generate_scenario(3, 2, family)
        info = RunInfo.for_scenario(room, 5)
        assert info.scenario_ref == ref
        assert info.scenario() == room


def test_the_table_prints_the_passage_line_and_each_failures_trips(capsys) -> None:
    stuck = {"hider": {"entries": 11, "through": 0, "back": 10, "inside": 1},
             "mapper": {"entries": 0, "through": 0, "back": 0, "inside": 0}}
    fine = {"hider": {"entries": 1, "through": 1, "back": 0, "inside": 0}}
    results = [_result(0, "failed", stuck), _result(1, "found", fine)]
    s = summarize(CampaignConfig(1, family="passages"), results, wall_s=1.0, workers=1)
    cmd_campaign._print_table(s)
    out = capsys.readouterr().out
    assert ("narrow passages: 12 entries in 2 games (1 through, 10 back, 1 inside at the "
            "end); found in 1 of those games (50.0 %)") in out
    assert "    narrow passages entered: hider 11 (0 through, 10 back, inside at the end)\n" in out
