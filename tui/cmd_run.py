"""``hideseek run``: one whole game, headless, in virtual time.

Exit status: 0 the hider was found, 1 it was not (or the game failed), 2 bad input,
3 a fork (``--replay FILE --fork-at T``) left its recording before T.

``--record FILE.mcap`` records the game (docs/recording.md); ``--replay FILE.mcap
--fork-at T`` plays a recorded game again to T, checking it, then on with the
changes given (``--fault``, ``--hide``, ``--seek``).
"""

from __future__ import annotations

import argparse
import json
import pathlib
import sys
import tempfile
import time
from typing import TYPE_CHECKING

from actors import JsonLinesRecorder, Trace, running, seed_trio_scheduler, virtual_clock
from supervisors.harness.headless import Budget, GameReport, run_game
from tui import args as args_
from world.scenario import (
    ROOM_FAMILIES,
    Scenario,
    ScenarioError,
    builtin_scenarios,
    generate_scenario,
    load_scenario,
    parse_generated,
)

if TYPE_CHECKING:
    from supervisors.recording import Recorder


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default="furniture", metavar="NAME|FILE",
                        help=f"built-in name ({', '.join(builtin_scenarios())}) or a .toml file "
                             "(default: furniture)")
    parser.add_argument("--generated", metavar="[FAMILY:]SEED:INDEX",
                        help="a procedurally generated room instead of --scenario (families: "
                             f"{', '.join(ROOM_FAMILIES)}; default {ROOM_FAMILIES[0]})")
    parser.add_argument("--seed", type=args_.seed, default=1, help="the run's seed (default 1)")
    parser.add_argument("--campaign", metavar="S:I[,...]",
                        help="game I of fault campaign S, as `hideseek campaign` printed it "
                             "(room, faults, seed and budget all come from it)")
    parser.add_argument("--json", action="store_true", help="print one JSON object on stdout")
    parser.add_argument("--db", type=args_.sqlite_file, default=":memory:",
                        help="SQLite file for the server's store")
    parser.add_argument("--trace", metavar="FILE", help="record the trace as JSON lines")
    parser.add_argument("--budget", type=args_.positive_seconds, default=1200.0,
                        help="simulated seconds allowed for mapping (default 1200)")
    parser.add_argument("--record", metavar="FILE.mcap",
                        help="record the game as MCAP (open it in Foxglove or with "
                             "`hideseek replay`)")
    parser.add_argument("--picture", metavar="FILE.png",
                        help="draw the game: the final map, each rover's true and believed "
                             "trajectory, the hide spot, the guesses and the fault onsets")
    fork = parser.add_argument_group("fork a recording")
    fork.add_argument("--replay", metavar="FILE.mcap",
                      help="the recorded game to play again (scenario, seed and budget "
                           "come from it)")
    fork.add_argument("--fork-at", type=float, metavar="T",
                      help="simulated time [s] where the game goes its own way")
    fork.add_argument("--fault", nargs="+", action="append", default=[],
                      metavar="TARGET KIND [DURATION]",
                      help="inject a fault at T (repeatable), e.g. --fault mapper/lidar dead 20")
    fork.add_argument("--hide", metavar="X,Y[,H]", help="another hide spot (room frame cm, deg)")
    fork.add_argument("--seek", metavar="X,Y", action="append",
                      help="a seek guess instead of the scenario's (room frame cm; repeatable)")


def _scenario(args: argparse.Namespace):
    if args.generated:
        return generate_scenario(*parse_generated(args.generated))
    return load_scenario(args.scenario)


def print_summary(r: GameReport) -> None:
    """The human-readable summary of a game (also `hideseek play --auto`'s)."""
    def pct(v: float | None) -> str:
        return "-" if v is None else f"{100 * v:.1f} %"

    def sec(v: float | None) -> str:
        return "-" if v is None else f"{v:.1f} s"

    print(f"\n{r.scenario} seed {r.seed}: {r.outcome.upper()}"
          + (f" ({r.reason})" if r.reason else ""))
    print(f"  simulated {r.sim_seconds:.1f} s in {r.wall_seconds:.1f} s wall "
          f"({r.real_time_factor:.0f}x real time)")
    print(f"  map: coverage {pct(r.coverage)}, accuracy {pct(r.accuracy)}, "
          f"T90 {sec(r.t90_s)}, T99 {sec(r.t99_s)}, mapper path {r.path_cm / 100:.1f} m")
    print("  phases: " + ", ".join(f"{k} {v:.1f} s" for k, v in r.phases.items()))
    print(f"  guesses {r.guesses}, restarts {r.restarts}, faults {r.faults}, "
          f"dropped {r.dropped}, resent {r.resent}, messages {r.messages}")
    print(f"  trace hash {r.trace_hash}")


def _numbers(text: str, name: str, counts: tuple[int, ...]) -> tuple[float, ...]:
    try:
        values = tuple(float(v) for v in text.split(","))
    except ValueError:
        values = ()
    if len(values) not in counts:
        form = "X,Y" if counts == (2,) else "X,Y[,H]"
        raise ValueError(f"--{name} must be {form} in cm, got {text!r}")
    return values


def _fork_faults(raw: list[list[str]]) -> list[tuple[str, str, float]]:
    out = []
    for items in raw:
        if len(items) not in (2, 3):
            raise ValueError(f"--fault takes TARGET KIND [DURATION], got {' '.join(items)!r}")
        try:
            duration = float(items[2]) if len(items) == 3 else 0.0
        except ValueError:
            raise ValueError(f"--fault duration must be seconds, got {items[2]!r}") from None
        out.append((items[0], items[1], duration))
    return out


def _fork(args: argparse.Namespace) -> int:
    """``--replay FILE --fork-at T``: play the recording again to T, then with the changes."""
    from supervisors.recording.fork import ForkDiverged, ForkError, fork_game  # noqa: PLC0415
    from supervisors.recording.reading import RecordingReadError  # noqa: PLC0415
    from supervisors.recording.recorder import RecordingError  # noqa: PLC0415

    try:
        if args.fork_at is None:
            raise ValueError("--replay needs --fork-at T (the simulated time to fork at)")
        faults = _fork_faults(args.fault)
        hide = None
        if args.hide:
            h = _numbers(args.hide, "hide", (2, 3))
            hide = (h[0], h[1], h[2] if len(h) == 3 else 0.0)
        seek = [_numbers(g, "seek", (2,)) for g in args.seek] if args.seek else None
        if not args.json:
            print(f"forking {args.replay} at {args.fork_at:g} s ...", flush=True)
        wall0 = time.perf_counter()
        report, checker = fork_game(args.replay, args.fork_at, faults=faults, hide=hide,
                                    seek=seek, record=args.record)
    except (ValueError, RecordingReadError, ForkError, RecordingError) as exc:
        print(f"hideseek run: {exc}", file=sys.stderr)
        return 2
    except ForkDiverged as exc:
        print(f"hideseek run: fork stopped: {exc}", file=sys.stderr)
        return 3
    report.wall_seconds = time.perf_counter() - wall0
    report.real_time_factor = report.sim_seconds / max(report.wall_seconds, 1e-9)
    if args.json:
        print(json.dumps({**report.to_json(), "fork_checkpoints": checker.compared}))
    else:
        print(f"  followed the recording to {args.fork_at:g} s "
              f"({checker.compared} checkpoints equal)")
        for line in report.events:
            print("  " + line)
        print_summary(report)
    return 0 if report.outcome == "found" else 1


def _recorder(args: argparse.Namespace, scenario: Scenario, path: str | None
              ) -> Recorder | None:
    """The observer recording to ``path``, or None (raises RecordingError when the file
    cannot be made)."""
    if not path:
        return None
    from supervisors.recording import Recorder  # noqa: PLC0415 - only when asked

    return Recorder.for_scenario(path, scenario, args.seed, budget_s=args.budget,
                                 campaign=args.campaign)


def _picture(recording: str, path: str) -> None:
    """Draw the recorded game into ``path`` (raises OSError when it cannot be written)."""
    from supervisors.recording.reading import read_recording  # noqa: PLC0415
    from tui.pictures.game_image import game_picture  # noqa: PLC0415 - Pillow when asked
    from tui.pictures.map_image import write_png  # noqa: PLC0415

    write_png(game_picture(read_recording(recording)), path)


def run(args: argparse.Namespace) -> int:
    if args.replay:
        return _fork(args)
    if args.fork_at is not None or args.fault or args.hide or args.seek:
        print("hideseek run: --fork-at, --fault, --hide and --seek fork a recording: "
              "give --replay FILE.mcap", file=sys.stderr)
        return 2
    try:
        if args.campaign:
            from supervisors.harness.campaign import (  # noqa: PLC0415 - only when asked
                game_from_ref,
                seed_game_scheduler,
            )
            scenario, args.seed, args.budget = game_from_ref(args.campaign)
            seed_game_scheduler(args.seed)  # the campaign's scheduling, so the same trace hash
        else:
            scenario = _scenario(args)
    except (ScenarioError, OSError) as exc:
        print(f"hideseek run: {exc}", file=sys.stderr)
        return 2
    trace = Trace()
    trace_file = None
    if args.trace:
        try:
            trace_file = open(args.trace, "w")  # noqa: SIM115 (closed below)
        except OSError as exc:
            print(f"hideseek run: cannot write trace: {exc}", file=sys.stderr)
            return 2
        trace.subscribe(JsonLinesRecorder(trace_file))
    budget = Budget(mapping=args.budget)
    scratch = None
    if args.picture and not args.record:  # the picture is drawn from a recording
        scratch = tempfile.TemporaryDirectory(prefix="hideseek-run-")
    recording = args.record or (scratch and str(pathlib.Path(scratch.name) / "game.mcap"))
    try:
        if args.picture and not pathlib.Path(args.picture).resolve().parent.is_dir():
            raise ValueError(f"--picture must be a file in an existing folder, "
                             f"got {args.picture!r}")
        recorder = _recorder(args, scenario, recording)
    except (RuntimeError, ValueError) as exc:  # RecordingError: the file cannot be made
        print(f"hideseek run: {exc}", file=sys.stderr)
        return 2
    if not args.json:
        print(f"running {scenario.name} (seed {args.seed}) in virtual time ...", flush=True)
    seed_trio_scheduler(args.seed)
    wall0 = time.perf_counter()  # wall time is measured for the report only
    try:
        report = running.run(lambda: run_game(scenario, args.seed, db=args.db, budget=budget,
                                              trace=trace,
                                              observers=[recorder] if recorder else []),
                             clock=virtual_clock())
    finally:  # also when a signal stops the game: the trace is kept to that point
        if trace_file is not None:
            trace_file.close()
    report.wall_seconds = time.perf_counter() - wall0
    report.real_time_factor = report.sim_seconds / max(report.wall_seconds, 1e-9)
    if args.picture:
        try:
            _picture(recording, args.picture)
        except OSError as exc:
            print(f"hideseek run: cannot write {args.picture}: {exc.strerror or exc}",
                  file=sys.stderr)
            return 2
        finally:
            if scratch is not None:
                scratch.cleanup()
    return print_report(report, as_json=args.json)


def print_report(report: GameReport, *, as_json: bool) -> int:
    """Print a finished game as ``hideseek run`` does (one JSON object, or its events and
    a summary); returns the exit status: 0 the hider was found, else 1."""
    if as_json:
        print(json.dumps(report.to_json()))
    else:
        for line in report.events:
            print("  " + line)
        print_summary(report)
    return 0 if report.outcome == "found" else 1
