"""Dispatch order: which game an engine should start first (longest expected first).

Only the order in which games start changes; what each game does never
does (docs/scaling.md, "Dispatch order").
"""

from __future__ import annotations

from collections.abc import Iterator

from supervisors.harness.campaign.plan import GameSpec, plan_game
from supervisors.harness.campaign.refs import CampaignConfig

#: a game's expected CPU time per built-in room [s] (whole campaign game, one core; games of
#: measured on whole campaigns, rounded: docs/scaling.md "Dispatch order"); only the
#: dispatch order reads it, so a stale figure costs the pool some balance at the end, never
#: a different result
ROOM_CPU_S: dict[str, float] = {
    "empty": 4.0, "corridor": 8.0, "round": 12.0, "gap": 12.0, "l_shaped": 12.0,
    "cluttered": 16.0, "furniture": 25.0, "hall": 30.0,
}
#: generated rooms (and rooms missing above): expected CPU time per m² of free floor [s]
#: (the built-in rooms' median; a generated campaign has only generated rooms, so only the
#: proportion to floor area matters)
_CPU_S_PER_FREE_M2 = 0.5
#: games ordered together; the blocks follow index order, so a campaign stopped early
#: (``--max-wall``) has played about a prefix of its games and planning stays bounded
ORDER_BLOCK = 64


def expected_cpu_s(spec: GameSpec, *, replayed: bool = False) -> float:
    """The game's expected CPU time [s], from what is known before it starts.

    The room decides most of it (a 4 x 3 m empty room maps in a minute of
    simulated time, a furnished one in up to ten), so built-in rooms use the
    measured `ROOM_CPU_S` and generated rooms their free floor area. A
    determinism replay plays the game twice. The figure only orders the
    dispatch: it never changes what a game does.
    """
    if spec.room in ROOM_CPU_S:
        cost = ROOM_CPU_S[spec.room]
    else:
        room = spec.scenario()
        width, height = room.room_size
        free_cm2 = width * height - sum(o.area for o in room.obstacles)
        cost = _CPU_S_PER_FREE_M2 * max(free_cm2, 0.0) / 1e4
    return 2.0 * cost if replayed else cost


def dispatch_order(config: CampaignConfig, start: int, games: int,
                   determinism_every: int = 0) -> Iterator[int]:
    """Game indices in the order a pool should start them: longest expected first.

    Games of one campaign differ tenfold in length, and a pool that starts
    them in index order can end with one worker playing a long game while
    the others idle. Longest-first (LPT) scheduling within blocks of
    `ORDER_BLOCK` games ends with the short ones, so the workers finish
    together. The first block takes the remainder, so the last block (whose
    end is the campaign's end) is always a full one. Results are keyed by
    index, so the order changes when a game finishes, never what it does.

    Yields:
        Each index of ``start .. start+games-1`` exactly once.
    """
    end = start + games
    first = start + (games % ORDER_BLOCK or ORDER_BLOCK)
    edges = [start, *range(first, end, ORDER_BLOCK), end]
    for lo, hi in zip(edges, edges[1:], strict=False):
        costs = {i: expected_cpu_s(plan_game(config, i),
                                   replayed=is_replayed(i, determinism_every))
                 for i in range(lo, hi)}
        yield from sorted(costs, key=lambda i: (-costs[i], i))


def is_replayed(index: int, determinism_every: int) -> bool:
    """Whether game ``index`` is played twice to compare trace hashes (every n-th game)."""
    return bool(determinism_every) and index % determinism_every == 0
