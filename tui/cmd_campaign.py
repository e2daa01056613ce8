"""``hideseek campaign``: many seeded games under random faults, invariants checked.

Game i of campaign S is fully determined by (S, i) and the options; every
failure is printed with the command that plays it again alone
(``hideseek run --campaign S:i[,...]``), with the same trace hash.

``--max-wall MINUTES`` stops starting games once that much wall time has
passed (checked as each game finishes; games still in flight are abandoned)
and summarises the games done: "as many games as fit in N minutes", for CI
and for a shared machine. Ctrl-C does the same at once.

Exit status: 0 every game found the hider with every invariant kept, 1 some
game failed, 2 bad input, 130 stopped early (interrupted or out of wall time).
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import time
from pathlib import Path
from typing import Any, TextIO

from supervisors.harness.campaign import (
    MAX_GAMES,
    MODES,
    CampaignConfig,
    CampaignError,
    CampaignStore,
    default_workers,
    play_campaign_game,
    run_campaign,
    select_kinds,
    summarize,
)
from supervisors.harness.campaign.engines import ENGINES, open_engine
from supervisors.harness.shrink import DEFAULT_MAX_RUNS, shrink_failures, shrinkable
from tui import args as args_
from tui.progress import progress_bar
from world.scenario import ROOM_FAMILIES, builtin_scenarios

_CAUSES = {"faults": "the faults (found, every invariant kept, without them)",
           "game": "the game itself (fails without faults too)"}


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("-n", "--games", type=int, default=None, metavar="N",
                        help="games to play (default 200, or 6 with --quick)")
    parser.add_argument("--seed", type=int, default=1,  # checked by the campaign's config
                        help="the campaign's seed S (default 1)")
    parser.add_argument("--workers", type=int, default=None, metavar="W",
                        help=f"worker processes (default one per core: {default_workers()}; "
                             "0 plays in this process)")
    rooms = parser.add_mutually_exclusive_group()
    rooms.add_argument("--scenarios", metavar="NAMES",
                       help=f"built-in rooms, comma separated, round-robin (default all: "
                            f"{', '.join(builtin_scenarios())})")
    rooms.add_argument("--generated", action="store_true",
                       help="procedurally generated rooms (room i of seed S)")
    parser.add_argument("--family", choices=ROOM_FAMILIES, default=ROOM_FAMILIES[0],
                        help="the generated rooms' family: obstacles (boxes and round "
                             "obstacles, default) or passages (parts joined by 25-45 cm gaps); "
                             "another than the default implies --generated")
    parser.add_argument("--faults", metavar="KINDS", default=None,
                        help="fault kinds to draw from, comma separated: a label such as "
                             "wifly:loss, a device (lidar, wifly, motor ...), 'actor', or a "
                             "kind (crash, stuck ...); default all")
    parser.add_argument("--mode", choices=MODES, default="single",
                        help="faults per game: single (exactly one, default), overlapping "
                             "(0 to 3), none")
    parser.add_argument("--window", default=None, metavar="A-B",
                        help="simulated seconds in which faults start (default 5-240)")
    parser.add_argument("--budget", type=args_.positive_seconds, default=1200.0,
                        help="simulated seconds allowed for mapping (default 1200)")
    parser.add_argument("--replay-every", type=int, default=10, metavar="K",
                        help="replay every K-th game to check determinism (0: never; default 10)")
    parser.add_argument("--timeout", type=float, default=600.0,
                        help="guard per game [s]: stopped after this much CPU time, or "
                             "10x this much wall time (default 600)")
    parser.add_argument("--max-wall", type=float, default=None, metavar="MINUTES",
                        help="stop after this much wall time and summarise the games done")
    parser.add_argument("--quick", action="store_true",
                        help="a handful of games (6) with no replays beyond the first")
    parser.add_argument("--json", action="store_true",
                        help="print one JSON summary on stdout (progress stays on stderr)")
    parser.add_argument("--out", type=args_.sqlite_file, default="hideseek-campaign.sqlite",
                        metavar="FILE",
                        help="SQLite file for the results (default hideseek-campaign.sqlite; "
                             "':memory:' to keep none)")
    parser.add_argument("--no-progress", action="store_true", help="no progress bar on stderr")
    parser.add_argument("--record-failures", metavar="DIR",
                        help="after the campaign, play each failed game again recorded as "
                             "DIR/game-I.mcap (open with hideseek replay)")
    parser.add_argument("--engine", choices=ENGINES, default="local",
                        help="where games run: local (a process pool, default) or ray (a Ray "
                             "cluster with --address, else a local Ray instance of --workers "
                             "CPUs; needs pip install 'hideseek[cluster]')")
    parser.add_argument("--address", default=None, metavar="ADDR",
                        help="the Ray cluster to join: HOST:PORT, ray://HOST:PORT or auto")
    parser.add_argument("--swarm", action="store_true",
                        help="swarm testing: each game draws its own subset of the fault kinds "
                             "and its own device parameters (link speed, sensor noise)")
    parser.add_argument("--shrink", action="store_true",
                        help="shrink each failure's faults to what it needs, in parallel on "
                             "the same engine, and write each as a scenario file")
    parser.add_argument("--shrink-dir", default="hideseek-shrunk", metavar="DIR",
                        help="folder for the shrunk scenario files (default hideseek-shrunk)")
    parser.add_argument("--shrink-runs", type=int, default=DEFAULT_MAX_RUNS, metavar="N",
                        help=f"games each shrink may play (default {DEFAULT_MAX_RUNS})")


def code_version() -> str | None:
    """The project's git version (``git describe --always --dirty``), None where unknown.

    A game reproduces (same trace hash) only with the code it was played
    with; the summary records the version at the start and at the end, so
    a campaign whose working tree changed meanwhile says so.
    """
    root = Path(__file__).resolve().parents[1]
    try:
        done = subprocess.run(["git", "-C", str(root), "describe", "--always", "--dirty",
                               "--abbrev=12"], capture_output=True, text=True, timeout=10,
                              check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    if done.returncode != 0:
        return None
    return done.stdout.strip() or None


def config_from_args(args: argparse.Namespace) -> CampaignConfig:
    """The campaign configuration the options describe.

    Raises:
        CampaignError: an option is wrong; the message says which.
    """
    kw: dict[str, Any] = {"seed": args.seed, "mode": args.mode,
                          "kinds": select_kinds(args.faults),
                          "mapping_budget_s": args.budget, "generated": args.generated,
                          "family": args.family}
    kw["swarm"] = args.swarm
    if args.scenarios:
        kw["rooms"] = tuple(s.strip() for s in args.scenarios.split(",") if s.strip())
    if args.window:
        try:
            lo, hi = (float(v) for v in args.window.split("-"))
        except ValueError:
            raise CampaignError(f"--window must be A-B in seconds, got {args.window!r}") from None
        kw["window_s"] = (lo, hi)
    return CampaignConfig(**kw)


def _print_table(s: dict[str, Any]) -> None:
    print(f"\ncampaign seed {s['campaign']['seed']} ({s['campaign']['mode']} faults): "
          f"{s['games']} games in {s['wall_s']:.1f} s wall with {s['workers']} workers "
          f"({s['games_per_wall_minute']} games/min)")
    code = s.get("code") or {}
    if code.get("at_start") != code.get("at_end"):
        print(f"  WARNING: the code changed during the campaign ({code.get('at_start')} -> "
              f"{code.get('at_end')}): games may not replay with the same trace hash")
    elif "dirty" in (code.get("at_start") or ""):
        print(f"  code {code['at_start']}: uncommitted changes; a replay needs the same files")
    if s.get("stopped_early"):
        print(f"  stopped early ({s['stopped_early']}): {s['games']} of "
              f"{s['games_requested']} games played")
    print(f"  found {s['found']} ({s.get('found_by_wider_search', 0)} by the wider search "
          f"after every guess failed, {s.get('found_after_second_hide', 0)} after a second "
          f"hide), not found {s['not_found']}, failed {s['failed']}; "
          f"games with broken invariants {s['games_with_violations']}; "
          f"success rate {100 * s['success_rate']:.1f} %; failures that fail without "
          f"their faults too {s['failures_also_without_faults']}")
    if s.get("failures_by_cause"):
        print("  failures by cause: " + ", ".join(f"{k} {v}" for k, v
                                                  in s["failures_by_cause"].items()))
    _print_passages(s.get("passages") or {})
    print(f"  restarts {s['restarts']}, resent {s['resent']}, dropped {s['dropped']}; "
          f"determinism: {s['determinism']['replayed']} replayed, "
          f"{s['determinism']['mismatched']} mismatched")
    if s["fault_kinds"]:
        print(f"\n  {'fault kind':<18}{'injected':>9}{'recovered':>10}{'failed':>8}"
              f"{'not reached':>13}")
        for kind, c in s["fault_kinds"].items():
            print(f"  {kind:<18}{c['injected']:>9}{c['recovered']:>10}{c['failed']:>8}"
                  f"{c['not_reached']:>13}")
    if s["violations"]:
        print("\n  broken invariants: " + ", ".join(f"{k} x{v}"
                                                  for k, v in s["violations"].items()))
    for f in s["failures"]:
        print(f"\n  FAILED game {f['index']} ({f['room']}): {f['outcome']}"
              + (f" ({f['reason']})" if f["reason"] else ""))
        for fault in f["faults"]:
            print(f"    fault: {fault}")
        for v in f["violations"]:
            print(f"    broken: {v}")
        trips = [f"{role} {t['entries']} ({t['through']} through, {t['back']} back"
                 + (", inside at the end)" if t["inside"] else ")")
                 for role, t in (f.get("passages") or {}).items() if t["entries"]]
        if trips:
            print("    narrow passages entered: " + ", ".join(trips))
        if f.get("without_faults"):
            broken = f.get("without_faults_violations") or []
            print(f"    without its faults: {f['without_faults']}"
                  + (f", broken: {'; '.join(broken)}" if broken else ""))
        if f.get("cause"):
            print(f"    cause: {_CAUSES[f['cause']]}")
        print(f"    reproduce: {f['reproduce']}")


def _print_passages(p: dict[str, Any]) -> None:
    """The narrow-passage line of the table (nothing when no rover entered one)."""
    if not p.get("entries"):
        return
    print(f"  narrow passages: {p['entries']} entries in {p['games_with_entries']} games "
          f"({p['through']} through, {p['back']} back, {p['inside_at_end']} inside at the "
          f"end); found in {p['found']} of those games ({100 * p['found_rate']:.1f} %)")
    print("    by rover: " + ", ".join(f"{role} {c['entries']} ({c['through']} through)"
                                     for role, c in p["by_rover"].items()))


def _record_dir(path: str) -> Path:
    """The ``--record-failures`` folder, made if missing.

    Raises:
        CampaignError: it cannot be made (a file of that name, no permission).
    """
    folder = Path(path)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise CampaignError(f"--record-failures {path!r}: {exc.strerror or exc}") from None
    return folder


def _record_failures(folder: str, failures: list[dict[str, Any]], results: list[dict[str, Any]],
                     *, out: TextIO, show: bool = True) -> None:
    """Play each failed game again by its campaign reference, recorded (the path of
    ``hideseek run --campaign REF --record FILE``); say whether it is the same game."""
    from supervisors.harness.campaign import game_from_ref  # noqa: PLC0415
    from supervisors.recording.play import record_game  # noqa: PLC0415
    from supervisors.recording.recorder import RecordingError  # noqa: PLC0415

    by_index = {r["index"]: r for r in results}
    print(f"\nrecording {len(failures)} failed game(s) into {folder} ...", file=out, flush=True)
    with progress_bar("recording", len(failures), enabled=show) as bar:
        for f in failures:
            r = by_index[f["index"]]
            path = Path(folder) / f"game-{f['index']}.mcap"
            bar.note(f"game {f['index']}")
            try:
                scenario, seed, budget = game_from_ref(r["ref"])
                report = record_game(scenario, seed, path, budget_s=budget, campaign=r["ref"])
            except (CampaignError, RecordingError) as exc:
                print(f"  game {f['index']}: not recorded: {exc}", file=out)
                continue
            finally:
                bar.advance()
            same = "the campaign's game" if report.trace_hash == r.get("trace_hash") else (
                f"NOT the campaign's game (trace hash {report.trace_hash}, campaign "
                f"{r.get('trace_hash')})")
            print(f"  game {f['index']}: {path} ({report.outcome}; {same})", file=out)


def run(args: argparse.Namespace, *, worker=play_campaign_game) -> int:
    """Run the campaign the options describe; ``worker`` is for tests."""
    try:
        config = config_from_args(args)
        games, workers = _sizes(args)
        engine = _open_engine(args, workers)
        store = CampaignStore(args.out)
    except CampaignError as exc:
        print(f"hideseek campaign: {exc}", file=sys.stderr)
        return 2
    replay_every = games if args.quick else args.replay_every
    show = not args.no_progress
    if not args.json:
        print(f"campaign seed {config.seed}: {games} games, {config.mode} faults, "
              f"{engine.workers if engine else workers} workers ...", flush=True)
    results = []
    stopped = None
    code_at_start = code_version()
    wall0 = time.perf_counter()  # wall time is measured for the report and --max-wall only
    with store:
        cid = store.new_campaign(config, time.time())
        playing = run_campaign(config, games, workers=workers, worker=worker,
                               determinism_every=replay_every, wall_timeout_s=args.timeout,
                               engine=engine)
        try:
            with progress_bar("games", games, enabled=show) as bar:
                failed = 0
                for r in playing:
                    results.append(r)
                    store.add_game(cid, r)
                    failed += r["outcome"] != "found" or bool(r["violations"])
                    rate = 60.0 * len(results) / max(time.perf_counter() - wall0, 1e-9)
                    bar.advance(note=f"{failed} failed, {rate:.1f} games/min")
                    if (args.max_wall is not None and len(results) < games
                            and time.perf_counter() - wall0 >= 60.0 * args.max_wall):
                        stopped = f"out of wall time ({args.max_wall:g} min)"
                        break
        except KeyboardInterrupt:
            stopped = "interrupted"
        finally:
            playing.close()  # stops the worker pool: games in flight are abandoned
        if stopped:
            print(f"\nhideseek campaign: {stopped} after {len(results)} of {games} games",
                  file=sys.stderr)
        summary = summarize(config, results, wall_s=time.perf_counter() - wall0,
                            workers=engine.workers if engine else workers)
        summary["games_requested"] = games
        summary["stopped_early"] = stopped
        summary["code"] = {"at_start": code_at_start, "at_end": code_version()}
        summary["engine"] = args.engine
        if args.shrink and not stopped:
            summary["shrunk"] = _shrink(args, results, engine)
        summary["out"] = args.out
        store.finish(cid, summary)
    if engine is not None:
        engine.close()
    if args.json:
        print(json.dumps(summary))
    else:
        _print_table(summary)
        _print_shrunk(summary.get("shrunk"))
        if args.out != ":memory:":
            print(f"  results stored in {args.out} (campaign {cid}; --out FILE to choose)")
    if args.record_failures and summary["failures"]:
        _record_failures(args.record_failures, summary["failures"], results,
                         out=sys.stderr if args.json else sys.stdout, show=show)
    if stopped == "interrupted":
        return 0  # Ctrl-C or SIGTERM: a clean stop, the games played so far are stored
    if len(results) < games:
        return 130
    return 1 if summary["failures"] else 0


def _sizes(args: argparse.Namespace) -> tuple[int, int]:
    """The games to play and the workers to play them, after checking every bound.

    Raises:
        CampaignError: a count, timeout or wall-time limit out of its bounds, or a
            ``--record-failures`` folder that cannot be made.
    """
    games = args.games if args.games is not None else (6 if args.quick else 200)
    if not 1 <= games <= MAX_GAMES:
        raise CampaignError(f"-n must be within 1..{MAX_GAMES}, got {games}")
    workers = default_workers() if args.workers is None else args.workers
    if not 0 <= workers <= 256:
        raise CampaignError(f"--workers must be within 0..256, got {workers}")
    if args.replay_every < 0:
        raise CampaignError(f"--replay-every must be >= 0, got {args.replay_every}")
    if not args.timeout > 0:
        raise CampaignError(f"--timeout must be > 0, got {args.timeout}")
    if args.max_wall is not None and not 0 < args.max_wall <= 1e6:
        raise CampaignError(f"--max-wall must be within (0, 1e6] minutes, "
                            f"got {args.max_wall}")
    if args.record_failures:
        _record_dir(args.record_failures)
    return games, workers


def _open_engine(args: argparse.Namespace, workers: int) -> Any:
    """The engine ``--engine`` names (None: the local pool ``run_campaign`` starts itself).

    Raises:
        CampaignError: Ray missing or unreachable, an address without ``--engine ray``,
            a bad ``--shrink-runs``.
    """
    if not 1 <= args.shrink_runs <= 10_000:
        raise CampaignError(f"--shrink-runs must be within 1..10000, got {args.shrink_runs}")
    if args.engine == "local" and not args.address:
        return None
    return open_engine(args.engine, workers=workers or None, address=args.address)


def _shrink(args: argparse.Namespace, results: list[dict[str, Any]], engine: Any
            ) -> list[dict[str, Any]]:
    """Shrink the failures on the campaign's engine; write each file; the reports, by index."""
    workers = engine.workers if engine else args.workers
    local = None if engine or workers == 0 else open_engine(
        "local", workers=min(workers or default_workers(), max(len(results), 1)))
    folder = Path(args.shrink_dir)
    out = []
    todo = len(shrinkable(results))
    if todo and not args.json:
        print(f"\nshrinking {todo} failed game(s), at most {args.shrink_runs} runs each ...",
              flush=True)
    with progress_bar("shrinking", todo, enabled=not args.no_progress) as bar:
        for r in shrink_failures(results, engine=engine or local, max_runs=args.shrink_runs,
                                 wall_timeout_s=args.timeout):
            if "toml" in r:
                path = folder / f"campaign-{args.seed}-{r['index']}.toml"
                try:
                    folder.mkdir(parents=True, exist_ok=True)
                    path.write_text(r.pop("toml"), encoding="utf-8")
                    r["file"] = str(path)
                except OSError as exc:
                    r["error"] = f"cannot write {path}: {exc}"
            out.append(r)
            bar.advance(note=f"game {r.get('index')}")
    return sorted(out, key=lambda r: r.get("index") or 0)


def _print_shrunk(shrunk: list[dict[str, Any]] | None) -> None:
    """Each shrunk failure: its schedule before and after, and the file that reproduces it."""
    for r in shrunk or []:
        what = r.get("error") or (
            f"{len(r['original'])} faults -> {len(r['shrunk'])} in {r['runs']} runs"
            + (" (ran out of runs)" if r["exhausted"] else ""))
        print(f"\n  SHRUNK {r['ref']}: {what}")
        if "error" in r:
            continue
        for line in r["shrunk"] or ["(no fault: it fails without them)"]:
            print(f"    needs: {line}")
        verdict = "fails the same way" if r["reproduces"] else "DOES NOT fail the same way"
        print(f"    {verdict}: {r['reproduce'].replace('FILE', r.get('file', 'FILE'))}")
