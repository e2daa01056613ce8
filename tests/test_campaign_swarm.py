"""Swarm mode: each game its own fault kinds and device parameters, drawn from its seed."""

from __future__ import annotations

import json

from supervisors.harness.campaign import FAULT_LABELS, CampaignConfig, parse_game_ref, plan_game
from supervisors.harness.campaign.plan import SWARM_DEVICES
from tui import cli

_SWARM = CampaignConfig(2, mode="overlapping", swarm=True)


def test_a_swarm_game_reference_says_so_and_reads_back():
    ref = _SWARM.game_ref(7)
    assert ref.endswith(",swarm=on")
    assert parse_game_ref(ref) == (_SWARM, 7)
    assert "swarm" not in CampaignConfig(2).game_ref(7)


def test_swarm_games_draw_different_kind_subsets_and_faults_only_from_them():
    subsets = set()
    for i in range(40):
        spec = plan_game(_SWARM, i)
        assert spec == plan_game(_SWARM, i)  # a pure function of (seed, index)
        assert spec.kinds and set(spec.kinds) <= set(FAULT_LABELS)
        assert set(spec.labels) <= set(spec.kinds)
        subsets.add(spec.kinds)
    assert len(subsets) >= 35  # 2**18 subsets: nearly every game its own
    sizes = [len(plan_game(_SWARM, i).kinds) for i in range(40)]
    assert 4 <= sum(sizes) / len(sizes) <= 14  # about half the kinds each
    assert plan_game(CampaignConfig(2), 3).kinds == FAULT_LABELS


def test_swarm_device_parameters_lie_in_their_ranges_and_make_a_valid_room():
    for i in range(10):
        spec = plan_game(_SWARM, i)
        devices = dict(spec.devices)
        assert set(devices) == set(SWARM_DEVICES)
        assert all(SWARM_DEVICES[k][0] <= v <= SWARM_DEVICES[k][1] for k, v in devices.items())
        params = spec.scenario().params()  # validated by DeviceParams
        assert params.wifly_bytes_s == devices["wifly_bytes_s"]
    assert len({plan_game(_SWARM, i).devices for i in range(10)}) == 10


def test_campaigns_without_swarm_draw_no_device_parameters():
    assert all(plan_game(CampaignConfig(2, mode="overlapping"), i).devices == ()
               for i in range(10))


def test_a_swarm_game_plays_alone_from_its_reference(capsys):
    ref = CampaignConfig(2, rooms=("empty",), mapping_budget_s=20.0, swarm=True).game_ref(1)
    assert cli.main(["run", "--campaign", ref, "--json"]) in (0, 1)
    report = json.loads(capsys.readouterr().out.splitlines()[-1])
    assert report["scenario"] == "empty" and report["trace_hash"]
