"""``hideseek play``: open the console on the simulated system (or the fake one with --fake).

With ``--rover ROLE=LINK`` that rover is not simulated here but attached over a
serial port or TCP (a real rover, or ``hideseek rover`` in another process);
simulated time then runs at real time only.

Textual is imported only when the command runs, so ``hideseek --help`` stays fast.
"""

from __future__ import annotations

import argparse
import sys

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
    parser.add_argument("--seed", type=int, default=1, help="seed of the run (default: 1)")
    parser.add_argument("--db", default=":memory:", metavar="FILE",
                        help="SQLite file for the server's games and maps (default: in memory)")
    parser.add_argument("--rover", type=rover_link, action="append", default=[],
                        metavar="ID=LINK",
                        help="attach a rover over a link instead of simulating it here: "
                             "ROLE=serial:PORT,BAUD or ROLE=tcp (it connects to --listen); "
                             "then time runs at x1 only (repeatable)")
    parser.add_argument("--listen", default="tcp:127.0.0.1:7878", metavar="tcp:HOST:PORT",
                        help="where rovers on tcp connect (default %(default)s; loopback only)")
    parser.add_argument("--fake", action="store_true",
                        help="run the built-in fake system (the console's demo and test double)")
    parser.add_argument("--speed", choices=list(SPEED_CHOICES), default="1",
                        help="initial speed of simulated time (default: %(default)s)")
    parser.add_argument("--record", metavar="FILE.mcap",
                        help="record the game from the start (R in the console starts and "
                             "stops recording)")
    parser.add_argument("--export-dir", default=".", metavar="DIR",
                        help="where the export key saves maps (default: current directory)")


def _links(args: argparse.Namespace):
    """``--rover`` and ``--listen`` -> (role -> LinkSpec, listen LinkSpec or None).

    Raises:
        ValueError: a bad link string, a rover given twice, or a non-loopback listen.
    """
    from server.links import is_loopback, parse_link

    remote = {}
    for role, text in args.rover:
        if role in remote:
            raise ValueError(f"--rover {role} given twice")
        remote[role] = parse_link(text)
    listen = None
    if any(spec.kind == "tcp" for spec in remote.values()):
        listen = parse_link(args.listen)
        if listen.kind != "tcp_listen":
            raise ValueError(f"--listen must be tcp:HOST:PORT, got {args.listen!r}")
        if not is_loopback(listen.host):
            raise ValueError(f"refusing to listen on {listen.host}: the console has no rover "
                             "tokens; use a loopback address or hideseek serve --token")
    return remote, listen


def run(args: argparse.Namespace) -> int:
    from tui.app import ConsoleApp

    if args.record and args.fake:
        print("hideseek play: --record needs the real system, not --fake", file=sys.stderr)
        return 2
    if args.rover and args.fake:
        print("hideseek play: --rover needs the real system, not --fake", file=sys.stderr)
        return 2
    if args.fake:
        from tui.fake import FakeSystem

        system = FakeSystem(seed=args.seed, scenario=args.scenario,
                            speed=SPEED_CHOICES[args.speed])
    else:
        from tui.live import LiveSystem
        from world.scenario import ScenarioError, load_scenario

        try:
            remote, listen = _links(args)
            scenario = load_scenario(args.scenario)
            system = LiveSystem(scenario, seed=args.seed, speed=SPEED_CHOICES[args.speed],
                                db=args.db, remote=remote, listen=listen,
                                record=args.record)
        except (ScenarioError, OSError, ValueError) as exc:
            print(f"hideseek play: {exc}", file=sys.stderr)
            return 2
    app = ConsoleApp(system, export_dir=args.export_dir)
    app.run()
    if app.system_error is not None:
        print(f"hideseek play: the system stopped: {type(app.system_error).__name__}: "
              f"{app.system_error}", file=sys.stderr)
        return 1
    return 0
