"""``hideseek play``: open the console on the simulated system (or the fake one with --fake).

With ``--rover ROLE=LINK`` that rover is not simulated here but attached over a
serial port, TCP or UDP (a real rover, or ``hideseek rover`` in another process);
simulated time then runs at real time only.

Textual is imported only when the command runs, so ``hideseek --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys
import time

from server.links.spec import LISTEN, PLAY_ROVER
from tui import args as args_
from tui import stopping

SPEED_CHOICES = {"1": 1.0, "4": 4.0, "16": 16.0, "max": None}


def rover_link(text: str) -> tuple[str, str]:
    """Parse ``ID=LINK`` (``seeker=serial:/dev/pts/4``).

    Raises:
        argparse.ArgumentTypeError: when the text is not ID=LINK with both parts.
    """
    rover, sep, link = text.partition("=")
    if not sep or not rover.strip() or not link.strip():
        raise argparse.ArgumentTypeError(f"--rover must be ID=LINK, got {text!r}")
    return rover.strip(), link.strip()


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--scenario", default="furniture", metavar="NAME|FILE",
                        help="built-in scenario name or TOML file (default: %(default)s)")
    parser.add_argument("--seed", type=args_.seed, default=1, help="seed of the run (default: 1)")
    parser.add_argument("--db", type=args_.sqlite_file, default=":memory:", metavar="FILE",
                        help="SQLite file for the server's games and maps (default: in memory)")
    parser.add_argument("--rover", type=rover_link, action="append", default=[],
                        metavar="ID=LINK",
                        help=f"attach a rover over a link instead of simulating it here, "
                             f"LINK one of: {PLAY_ROVER.forms}; then time runs at x1 only "
                             f"(repeatable)")
    parser.add_argument("--listen", action="append", metavar="tcpin:HOST:PORT|udpin:HOST:PORT",
                        help=f"where rovers on tcp connect and rovers on udp send: "
                             f"{LISTEN.forms} (repeatable; loopback only; default "
                             f"tcp:127.0.0.1:7878 and udp:127.0.0.1:7878, each where a rover "
                             f"uses it)")
    parser.add_argument("--fake", action="store_true",
                        help="run the built-in fake system (the console's demo and test double)")
    parser.add_argument("--speed", choices=list(SPEED_CHOICES), default="1",
                        help="initial speed of simulated time (default: %(default)s)")
    parser.add_argument("--record", metavar="FILE.mcap",
                        help="record the game from the start (R in the console starts and "
                             "stops recording)")
    parser.add_argument("--export-dir", default=".", metavar="DIR",
                        help="where the export key saves maps, the screenshot key SVGs and "
                             "the record key recordings (default: current directory)")
    parser.add_argument("--auto", action="store_true",
                        help="play the headless operator's game by itself (start mapping, the "
                             "scenario's hide spot and guesses), then leave the console and "
                             "print what `hideseek run` prints")
    parser.add_argument("--json", action="store_true",
                        help="with --auto: print one JSON object, as `hideseek run --json`")
    parser.add_argument("--budget", type=args_.positive_seconds, default=1200.0, metavar="S",
                        help="with --auto: simulated seconds allowed for mapping (default 1200)")


def _links(args: argparse.Namespace):
    """``--rover`` and ``--listen`` -> (role -> LinkSpec, listen LinkSpecs).

    A rover on ``tcp`` or ``udp`` needs a listening address of that kind: the
    one given with ``--listen``, else ``127.0.0.1:7878`` when none is given.

    Raises:
        ValueError: a bad link string, a rover given twice, a missing or
            non-loopback listen.
    """
    from server.links import is_loopback, parse_link
    from server.links.spec import parse_link_for
    from tui.cmd_serve import parse_listens

    remote = {}
    for role, text in args.rover:
        if role in remote:
            raise ValueError(f"--rover {role} given twice")
        remote[role] = parse_link_for(text, PLAY_ROVER)
    given = parse_listens(args.listen or [])
    listen = []
    for kind in ("tcp", "udp"):
        if not any(spec.kind == kind for spec in remote.values()):
            continue
        where = next((spec for proto, spec in given if proto == kind), None)
        if where is None:
            if args.listen:
                raise ValueError(f"a rover on {kind} needs --listen {kind}:HOST:PORT")
            where = parse_link(f"{kind}:127.0.0.1:7878")
        if not is_loopback(where.host):
            raise ValueError(f"refusing to listen on {where.host}: the console has no rover "
                             "tokens; use a loopback address or hideseek serve --token")
        listen.append(where)
    return remote, listen


def run(args: argparse.Namespace) -> int:
    from tui.app import ConsoleApp

    if args.record and args.fake:
        print("hideseek play: --record needs the real system, not --fake", file=sys.stderr)
        return 2
    if args.rover and args.fake:
        print("hideseek play: --rover needs the real system, not --fake", file=sys.stderr)
        return 2
    if (args.json or args.auto) and args.fake:
        print("hideseek play: --auto plays the simulated game, not --fake", file=sys.stderr)
        return 2
    if args.json and not args.auto:
        print("hideseek play: --json goes with --auto (the report of the auto game)",
              file=sys.stderr)
        return 2
    if not args.budget > 0:
        print(f"hideseek play: --budget must be > 0 s, got {args.budget:g}", file=sys.stderr)
        return 2
    if args.fake:
        from tui.fake import FakeSystem

        system = FakeSystem(seed=args.seed, scenario=args.scenario,
                            speed=SPEED_CHOICES[args.speed])
    else:
        from supervisors.harness.headless import Budget
        from tui.live import LiveSystem
        from world.scenario import ScenarioError, load_scenario

        try:
            remote, listen = _links(args)
            scenario = load_scenario(args.scenario)
            system = LiveSystem(scenario, seed=args.seed, speed=SPEED_CHOICES[args.speed],
                                db=args.db, remote=remote, listen=listen, record=args.record,
                                auto=args.auto,
                                budget=Budget(mapping=args.budget))
        except (ScenarioError, OSError, ValueError) as exc:
            print(f"hideseek play: {exc}", file=sys.stderr)
            return 2
    app = ConsoleApp(system, export_dir=args.export_dir)
    wall0 = time.perf_counter()  # wall time for the auto game's report only
    app.run()
    if app.stopped_by_signal:
        print(stopping.stopped_line("play"), file=sys.stderr)
        return 0
    if app.system_error is not None:
        from tui.live import ListenError

        busy = [e for e in stopping.leaves(app.system_error) if isinstance(e, ListenError)]
        if busy:
            print(f"hideseek play: {busy[0]}", file=sys.stderr)
            return 2
        print(f"hideseek play: the system stopped: {type(app.system_error).__name__}: "
              f"{app.system_error}", file=sys.stderr)
        return 1
    if args.auto:
        return _auto_report(system, time.perf_counter() - wall0, as_json=args.json)
    return 0


def _auto_report(system, wall_s: float, *, as_json: bool) -> int:
    """Print the auto game's report as ``hideseek run`` does (nothing if it was quit early)."""
    from tui.cmd_run import print_report

    report = system.report
    if report is None:
        print("hideseek play: quit before the game ended: no report", file=sys.stderr)
        return 0
    report.wall_seconds = wall_s
    report.real_time_factor = report.sim_seconds / max(wall_s, 1e-9)
    return print_report(report, as_json=as_json)
