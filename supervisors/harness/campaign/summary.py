"""The campaign's summary: outcomes, fault kinds, broken invariants, and whose each failure is.

Aggregation is separate from playing and cheap: results are keyed by
``index``, so the order in which games finish never matters.
"""

from __future__ import annotations

from collections import Counter
from typing import Any

from supervisors.harness.campaign.refs import CampaignConfig


def _failed(r: dict[str, Any]) -> bool:
    return r["outcome"] != "found" or bool(r["violations"])


def _cause(r: dict[str, Any]) -> str | None:
    """Whose failure a failed game is: ``faults``, ``game``, or None (not known).

    ``game`` when it fails without faults too (it had none, or its replay
    without them also failed or broke an invariant), ``faults`` when that
    replay found the hider with every invariant kept; None when no replay
    was played (``baseline=False``) or the game did not fail.
    """
    if not _failed(r):
        return None
    if not r["faults"]:
        return "game"
    if r.get("baseline") is None:
        return None
    return "faults" if r["baseline"] == "found" and not r.get("baseline_violations") else "game"


def _rooms(config: CampaignConfig) -> str | list[str]:
    """``generated`` (``generated:FAMILY`` for another family than the default), or the
    built-in rooms' names."""
    if not config.generated:
        return list(config.room_names())
    default = CampaignConfig(0).family
    return "generated" if config.family == default else f"generated:{config.family}"


def _passages(results: list[dict[str, Any]]) -> dict[str, Any]:
    """Trips through narrow passages (`world.passages`) over the games, per rover and in
    all; ``found_rate`` is the share of the games with an entry that found the hider."""
    per_role: dict[str, Counter] = {}
    entered = [r for r in results if any(t["entries"] for t in r.get("passages", {}).values())]
    for r in results:
        for role, trips in r.get("passages", {}).items():
            per_role.setdefault(role, Counter()).update(trips)
    total = sum(per_role.values(), Counter())
    return {"games_with_entries": len(entered),
            "found": sum(1 for r in entered if r["outcome"] == "found"),
            "found_rate": (sum(1 for r in entered if r["outcome"] == "found") / len(entered)
                           if entered else None),
            "entries": total["entries"], "through": total["through"], "back": total["back"],
            "inside_at_end": total["inside"],
            "by_rover": {role: {k: c[k] for k in ("entries", "through", "back", "inside")}
                         for role, c in sorted(per_role.items())}}


def summarize(config: CampaignConfig, results: list[dict[str, Any]], *,
              wall_s: float, workers: int) -> dict[str, Any]:
    """The campaign's JSON summary (what ``hideseek campaign --json`` prints).

    A game counts as a failure when the hider was not found or an invariant
    broke; per fault label, a fault is *injected* when its start came before
    the game ended, *recovered* when such a game did not fail. Each failure
    says whose it is (``cause``: ``faults``, ``game`` or None, see `_cause`),
    from the replay of the game without its faults.
    """
    results = sorted(results, key=lambda r: r["index"])
    outcomes = Counter(r["outcome"] for r in results)
    per_kind: dict[str, Counter] = {}
    for r in results:
        for f in r["faults"]:
            c = per_kind.setdefault(f["label"], Counter())
            if f["at_s"] > r["sim_s"] + 1e-9 and r["outcome"] != "failed":
                c["not_reached"] += 1  # the game was over before the fault's start
                continue
            c["injected"] += 1
            c["failed" if _failed(r) else "recovered"] += 1
    violated = Counter(v.split(":", 1)[0] for r in results for v in r["violations"])
    replayed = [r for r in results if r["replay_hash"] is not None]
    games = len(results)
    return {
        "campaign": {"seed": config.seed, "mode": config.mode, "kinds": list(config.kinds),
                     "rooms": _rooms(config),
                     "window_s": list(config.window_s), "swarm": config.swarm},
        "games": games,
        "found": outcomes.get("found", 0),
        "not_found": outcomes.get("not_found", 0),
        "failed": outcomes.get("failed", 0),
        "games_with_violations": sum(1 for r in results if r["violations"]),
        "success_rate": (sum(1 for r in results if not _failed(r)) / games) if games else 0.0,
        "found_rate": (outcomes.get("found", 0) / games) if games else 0.0,
        "found_by_wider_search": sum(1 for r in results
                                     if r["outcome"] == "found" and r.get("wider_search")),
        "found_after_second_hide": sum(1 for r in results if r["outcome"] == "found"
                                       and r.get("hide_attempts", 0) > 1),
        "passages": _passages(results),
        "fault_kinds": {k: {"injected": c["injected"], "recovered": c["recovered"],
                            "failed": c["failed"], "not_reached": c["not_reached"]}
                        for k, c in sorted(per_kind.items())},
        "violations": dict(sorted(violated.items())),
        "failures_also_without_faults": sum(1 for r in results if _cause(r) == "game"),
        "failures_by_cause": dict(sorted(Counter(_cause(r) or "unknown" for r in results
                                                 if _failed(r)).items())),
        "restarts": sum(r["restarts"] for r in results),
        "resent": sum(r["resent"] for r in results),
        "dropped": sum(r["dropped"] for r in results),
        "sim_s": round(sum(r["sim_s"] for r in results), 1),
        "determinism": {"replayed": len(replayed),
                        "mismatched": sum(1 for r in replayed
                                          if r["replay_hash"] != r["trace_hash"])},
        "workers": workers,
        "wall_s": round(wall_s, 2),
        "games_per_wall_minute": round(60.0 * games / wall_s, 2) if wall_s > 0 else None,
        "failures": [{"index": r["index"], "room": r["room"], "outcome": r["outcome"],
                      "reason": r["reason"], "violations": r["violations"],
                      "faults": [f"{f['target']} {f['kind']} at {f['at_s']:g} s for "
                                 f"{f['duration_s']:g} s" for f in r["faults"]],
                      "devices": r.get("devices") or {},
                      "without_faults": r.get("baseline"),
                      "without_faults_violations": r.get("baseline_violations", []),
                      "cause": _cause(r),
                      "passages": r.get("passages") or {},
                      "reproduce": r["reproduce"]}
                     for r in results if _failed(r)],
    }
