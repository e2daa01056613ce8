"""The pure game state machine: legal and illegal commands per phase, frames sent."""

from __future__ import annotations

import numpy as np
import pytest

from server.game import Game, Phase
from server.protocol import GridMap, Pose

MAP = GridMap(np.zeros((20, 20), dtype=np.int8), 10.0, (-100.0, -100.0))


def _ready(**poses) -> Game:
    g = Game(start_poses=poses or {"mapper": Pose(0, 0, 0), "hider": Pose(10, 0, 0),
                                   "seeker": Pose(0, 10, 0)})
    assert g.command("start_mapping").ok
    assert g.on_map(MAP).ok
    return g


def test_happy_path_sends_the_right_frames() -> None:
    """Each transition sends exactly the frames the protocol describes, to the right role."""
    g = Game(start_poses={"hider": Pose(10, 0, 0), "seeker": Pose(0, 10, 0)})
    r = g.command("start_mapping")
    assert [(s.role, s.frame.cmd) for s in r.sends] == [("mapper", "origin"), ("mapper", "start")]
    r = g.command("stop_mapping")
    assert [(s.role, s.frame.cmd) for s in r.sends] == [("mapper", "stop")]
    assert g.phase is Phase.MAPPING and g.on_map(MAP).ok and g.phase is Phase.MAP_READY
    r = g.command("hide", x=20, y=30, heading=90)
    assert [(s.role, s.frame.cmd) for s in r.sends] == [
        ("hider", "origin"), ("hider", "start"), ("hider", "destination")]
    assert r.sends[2].frame.data == {"x": 20.0, "y": 30.0, "heading": 90.0}
    assert g.on_rover("hider", "arrived", Pose(20, 30, 90)).ok and g.phase is Phase.HIDDEN
    r = g.command("seek", x=0, y=0)
    assert [s.frame.cmd for s in r.sends] == ["origin", "start", "destination"]
    assert r.sends[2].frame.data["heading"] is None
    assert g.on_rover("seeker", "not_found", reason="nothing").ok
    r = g.command("seek", x=20, y=30)
    assert [s.frame.cmd for s in r.sends] == ["destination"]  # seeker already started
    assert g.on_rover("seeker", "found", Pose(20, 25)).ok and g.finished


def test_a_wider_search_says_how_far_round_the_guess_and_is_bounded() -> None:
    """``seek ... within=W`` puts W in the seeker's destination (a plain guess's frame has
    no such field); a radius out of (0, 500] cm or on another command is refused with a
    reason and changes nothing."""
    g = Game(start_poses={"hider": Pose(10, 0, 0), "seeker": Pose(0, 10, 0)})
    g.command("start_mapping")
    g.on_map(MAP)
    g.command("hide", x=20, y=30)
    g.on_rover("hider", "arrived", Pose(20, 30, 0))
    r = g.command("seek", x=0, y=0)
    assert "within" not in r.sends[-1].frame.data
    g.on_rover("seeker", "not_found", reason="nothing")
    for within, reason in ((0, "within must be in (0, 500] cm, got 0"),
                           (501, "within must be in (0, 500] cm, got 501"),
                           ("far", "within must be a number of cm, got 'far'")):
        r = g.command("seek", x=0, y=0, within=within)
        assert (r.ok, r.reason, g.phase) == (False, reason, Phase.NOT_FOUND)
    assert g.command("hide", x=0, y=0, within=50).reason == "within applies to seek only, not hide"
    r = g.command("seek", x=0, y=0, within=120)
    assert r.ok and g.phase is Phase.SEEKING
    assert r.sends[-1].frame.data == {"x": 0.0, "y": 0.0, "heading": None, "within": 120.0}


@pytest.mark.parametrize(
    ("setup", "command", "kwargs", "reason"),
    [
        ("idle", "stop_mapping", {}, "stop_mapping needs phase mapping, the game is idle"),
        ("idle", "seek", {"x": 0, "y": 0},
         "seek needs phase hidden or not_found, the game is idle"),
        ("ready", "start_mapping", {}, "start_mapping needs phase idle, the game is map_ready"),
        ("ready", "hide", {"x": 0}, "hide needs x and y [cm]"),
        ("ready", "hide", {"x": 500, "y": 0},
         "hide spot (500, 0) cm (map frame) is outside the map [-100..100] x [-100..100]"),
        ("ready", "hide", {"x": 0, "y": 0, "frame": "world"}, "frame must be 'map' or 'room', "
                                                             "got 'world'"),
        ("nohider", "hide", {"x": 0, "y": 0},
         "start pose of the hider is not configured (--origin ID=X,Y,HEADING)"),
    ],
)
def test_illegal_commands_are_refused_with_reason(setup, command, kwargs, reason) -> None:
    """A command outside its phase or with bad arguments is refused and changes nothing."""
    g = Game() if setup == "idle" else (_ready(mapper=Pose(0, 0, 0)) if setup == "nohider"
                                        else _ready())
    before = g.phase
    r = g.command(command, **kwargs)
    assert (r.ok, r.reason) == (False, reason)
    assert g.phase is before


def test_invalid_spot_returns_to_map_ready_with_reason() -> None:
    """An invalid spot sends the game back to map_ready and keeps the reason."""
    g = _ready()
    g.command("hide", x=0, y=0)
    assert g.on_rover("hider", "invalid_spot", reason="too tight").ok
    assert (g.phase, g.last_reason) == (Phase.MAP_READY, "too tight")


def test_a_reason_belongs_to_the_phase_it_caused() -> None:
    """A not_found's reason is shown while not_found, and gone once seeking goes on and finds."""
    g = _ready()
    assert g.command("hide", x=20, y=30).ok and g.on_rover("hider", "arrived", Pose(20, 30, 0)).ok
    assert g.command("seek", x=0, y=0).ok
    assert g.on_rover("seeker", "not_found", reason="the IR sensor saw nothing").ok
    assert (g.phase, g.last_reason) == (Phase.NOT_FOUND, "the IR sensor saw nothing")
    assert g.command("seek", x=20, y=30).ok
    assert (g.phase, g.last_reason) == (Phase.SEEKING, "")
    assert g.on_rover("seeker", "found", Pose(20, 30, 0)).ok
    assert (g.phase, g.last_reason) == (Phase.FOUND, "")


def test_reports_from_wrong_role_or_phase_are_refused() -> None:
    """found from the hider, or arrived while mapping, are ignored with a reason."""
    g = _ready()
    assert g.on_rover("hider", "found").reason == "found comes from the seeker, not the hider"
    assert g.on_rover("hider", "arrived").reason == "arrived ignored in phase map_ready"


def test_room_frame_spots_are_converted_to_map_frame() -> None:
    """With the mapper at (100, 0) facing +y, room (100, 50) is map (50, 0)."""
    g = _ready(mapper=Pose(100, 0, 90), hider=Pose(100, 0, 90))
    r = g.command("hide", x=100, y=50, heading=90, frame="room")
    d = r.sends[2].frame.data
    assert (round(d["x"], 6), round(d["y"], 6), d["heading"]) == (50.0, 0.0, 0.0)
    assert g.origin_of("hider") == Pose(0.0, 0.0, 0.0)


def test_new_game_stops_the_busy_rover_and_resets() -> None:
    """new_game while hiding stops the hider and returns to idle, keeping start poses."""
    g = _ready()
    g.command("hide", x=0, y=0)
    r = g.command("new_game")
    assert [(s.role, s.frame.cmd) for s in r.sends] == [("hider", "stop")]
    assert g.phase is Phase.IDLE and g.map is None and "hider" in g.start_poses
