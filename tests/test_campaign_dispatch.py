"""Campaign dispatch order (longest expected game first) and whose failure a failure is."""

from __future__ import annotations

import heapq

import pytest

from supervisors.harness.campaign import (
    ORDER_BLOCK,
    ROOM_CPU_S,
    CampaignConfig,
    dispatch_order,
    expected_cpu_s,
    plan_game,
    run_campaign,
    summarize,
)
from tests.test_campaign import fake_worker
from world.scenario import builtin_scenarios


def _makespan(costs: list[float], workers: int) -> float:
    """When the last of ``workers`` greedy workers ends, handed ``costs`` in this order."""
    ends = [0.0] * workers
    for c in costs:
        heapq.heapreplace(ends, ends[0] + c)
    return max(ends)


# ---------------------------------------------------------------------------- order

@pytest.mark.parametrize("start, games", [(0, 1), (0, 8), (3, 64), (0, 65), (10, 200)])
def test_dispatch_order_hands_out_every_game_once(start, games):
    order = list(dispatch_order(CampaignConfig(1), start, games))
    assert sorted(order) == list(range(start, start + games))


def test_every_built_in_room_has_a_measured_cost():
    assert set(ROOM_CPU_S) == set(builtin_scenarios())


def test_longest_expected_game_goes_first_within_a_block():
    config = CampaignConfig(1)
    order = list(dispatch_order(config, 0, 16))
    costs = [expected_cpu_s(plan_game(config, i)) for i in order]
    assert costs == sorted(costs, reverse=True)
    assert plan_game(config, order[-1]).room == "empty"


def test_blocks_follow_index_order_and_the_last_block_is_full():
    """A campaign stopped early has played about a prefix; the end is balanced over a full block."""
    games = 2 * ORDER_BLOCK + 5
    order = list(dispatch_order(CampaignConfig(1), 0, games))
    first, rest = order[:5], order[5:]
    assert sorted(first) == list(range(5))
    assert sorted(rest[:ORDER_BLOCK]) == list(range(5, 5 + ORDER_BLOCK))
    assert sorted(rest[ORDER_BLOCK:]) == list(range(5 + ORDER_BLOCK, games))


def test_a_replayed_game_counts_twice():
    """Of equal rooms, the games replayed for determinism go first (they play twice)."""
    config = CampaignConfig(1, rooms=("empty",))
    assert list(dispatch_order(config, 0, 5, determinism_every=2)) == [0, 2, 4, 1, 3]
    assert list(dispatch_order(config, 0, 5)) == [0, 1, 2, 3, 4]


def test_generated_rooms_cost_more_the_more_floor_they_have():
    config = CampaignConfig(1, generated=True)
    specs = [plan_game(config, i) for i in range(6)]
    free = []
    for spec in specs:
        room = spec.scenario()
        free.append(room.room_size[0] * room.room_size[1] - sum(o.area for o in room.obstacles))
    costs = [expected_cpu_s(s) for s in specs]
    assert all(c > 0 for c in costs)
    assert sorted(range(6), key=free.__getitem__) == sorted(range(6), key=costs.__getitem__)
    assert expected_cpu_s(specs[0], replayed=True) == pytest.approx(2 * costs[0])


@pytest.mark.parametrize("rooms, games", [((), 8), ((), 16), ((), 24),
                                          (("empty",) * 5 + ("hall",), 12)])
def test_two_workers_finish_together_in_dispatch_order(rooms, games):
    """With the expected costs, longest-first ends within 5 % of the best possible end.

    The last case is one that index order gets wrong: the long game comes
    last and one worker plays it alone.
    """
    config = CampaignConfig(1, rooms=rooms)
    cost = {i: expected_cpu_s(plan_game(config, i)) for i in range(games)}
    lpt = _makespan([cost[i] for i in dispatch_order(config, 0, games)], 2)
    by_index = _makespan([cost[i] for i in range(games)], 2)
    best = max(sum(cost.values()) / 2, *cost.values())  # no schedule ends earlier
    assert lpt <= by_index
    assert lpt <= 1.05 * best
    if rooms:
        assert by_index > 1.2 * best


class _RecordingPool:
    """Stands in for a process pool: plays the jobs here, in the order handed over."""

    def __init__(self) -> None:
        self.refs: list[str] = []

    def imap_unordered(self, func, jobs, chunksize=1):
        for job in jobs:
            self.refs.append(job[1][0])  # job: (entry point, (ref,), options)
            yield func(job)


def test_a_pool_gets_the_games_in_dispatch_order_and_the_results_match():
    config = CampaignConfig(4)
    pool = _RecordingPool()
    pooled = list(run_campaign(config, 10, worker=fake_worker, pool=pool, determinism_every=3))
    assert pool.refs == [config.game_ref(i) for i in dispatch_order(config, 0, 10, 3)]
    local = list(run_campaign(config, 10, workers=0, worker=fake_worker, determinism_every=3))
    assert [r["index"] for r in local] == list(range(10))  # in this process: index order
    assert sorted(pooled, key=lambda r: r["index"]) == local


# ---------------------------------------------------------------------------- cause

def _result(index: int, *, outcome: str = "found", faults: bool = True,
            baseline: str | None = None, baseline_violations: tuple[str, ...] = (),
            violations: tuple[str, ...] = ()) -> dict:
    r = fake_worker(CampaignConfig(1, kinds=("wifly:loss",)).game_ref(index))
    r.update(outcome=outcome, violations=list(violations), baseline=baseline,
             baseline_violations=list(baseline_violations))
    if not faults:
        r["faults"] = []
    return r


def test_each_failure_says_whether_the_faults_or_the_game_caused_it():
    results = [
        _result(0),                                                # found: no failure
        _result(1, outcome="not_found", baseline="found"),         # the faults
        _result(2, outcome="not_found", baseline="not_found"),     # the game
        _result(3, violations=("noloss.exactly_once: x",), baseline="found",
                baseline_violations=("noloss.exactly_once: x",)),  # the game: repeats calm
        _result(4, outcome="failed", faults=False),                # the game: had no faults
        _result(5, outcome="failed"),                              # not replayed: unknown
    ]
    s = summarize(CampaignConfig(1), results, wall_s=1.0, workers=1)
    causes = {f["index"]: f["cause"] for f in s["failures"]}
    assert causes == {1: "faults", 2: "game", 3: "game", 4: "game", 5: None}
    assert s["failures_by_cause"] == {"faults": 1, "game": 3, "unknown": 1}
    assert s["failures_also_without_faults"] == 3
    by_index = {f["index"]: f for f in s["failures"]}
    assert by_index[3]["without_faults_violations"] == ["noloss.exactly_once: x"]


def test_the_table_prints_each_failures_cause_and_what_broke_without_faults(capsys):
    from tui import cmd_campaign  # noqa: PLC0415

    results = [_result(1, outcome="not_found", baseline="found"),
               _result(3, violations=("no_loss.lost: x",), baseline="found",
                       baseline_violations=("no_loss.lost: x",))]
    cmd_campaign._print_table(summarize(CampaignConfig(1), results, wall_s=1.0, workers=1))
    out = capsys.readouterr().out
    assert "failures by cause: faults 1, game 1" in out
    blocks = out.split("FAILED game ")[1:]
    assert "cause: the faults" in blocks[0] and "without its faults: found\n" in blocks[0]
    assert "cause: the game itself" in blocks[1]
    assert "without its faults: found, broken: no_loss.lost: x" in blocks[1]


# ---------------------------------------------------------------------------- guard

def _guarded(body, cpu_s: float, factor: float) -> str:
    """Run ``body`` in Trio under a `_Guard`; return what stopped it ("" if nothing)."""
    import trio  # noqa: PLC0415

    from supervisors.harness.campaign.play import _Guard  # noqa: PLC0415

    fired = []

    async def main():
        with trio.CancelScope() as scope:
            guard = _Guard(cpu_s, trio.lowlevel.current_trio_token(), scope.cancel, factor)
            try:
                await body()
            finally:
                guard.stop()
                fired.append(guard.fired)

    trio.run(main)
    return fired[0]


def test_the_guard_stops_a_game_that_keeps_computing_by_its_cpu_time():
    import time  # noqa: PLC0415

    import trio  # noqa: PLC0415

    async def spin():
        while True:
            t = time.perf_counter()
            while time.perf_counter() - t < 0.01:
                pass
            await trio.lowlevel.checkpoint()

    assert "CPU s of 0.2" in _guarded(spin, 0.2, 50.0)


def test_the_guard_stops_a_game_blocked_without_computing_by_wall_time():
    import time  # noqa: PLC0415

    import trio  # noqa: PLC0415

    async def blocked():
        await trio.to_thread.run_sync(time.sleep, 3.0, abandon_on_cancel=True)

    assert "wall s of 0.2" in _guarded(blocked, 0.05, 4.0)


def test_the_guard_leaves_a_short_game_alone():
    import trio  # noqa: PLC0415

    async def short():
        await trio.sleep(0.01)

    assert _guarded(short, 5.0, 10.0) == ""


def test_a_game_stopped_by_its_guard_is_a_harness_failure_not_a_crash():
    from supervisors.harness.campaign import play_campaign_game  # noqa: PLC0415

    r = play_campaign_game(CampaignConfig(1, rooms=("empty",)).game_ref(0),
                           wall_timeout_s=0.05, baseline=False)
    assert r["outcome"] == "failed"
    assert r["violations"][0].startswith("harness.exception: TimeoutError: game stopped by the "
                                         "guard after")
