"""``hideseek rover``: one simulated rover as its own process, over TCP, UDP or serial.

The rover's WiFly bytes go over ``--link`` instead of the in-memory link, so
the path a real rover takes (a WiFly module connecting over TCP, or a serial
cable) is exercised end to end. It runs in real time (``--speed`` scales the
clock; the server must then run at the same speed, or links time out).
Ctrl-C stops it with status 0.
"""

from __future__ import annotations

import argparse
import sys

from server.links.spec import ROVER_LINK
from server.protocol import ROLES
from tui import args as args_
from tui.stopping import is_interrupt, leaves


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--role", required=True, choices=ROLES, help="which rover this is")
    parser.add_argument("--link", required=True, metavar="LINK",
                        help=f"{ROVER_LINK.forms}; as in MAVProxy")
    parser.add_argument("--scenario", default="furniture", metavar="NAME|FILE",
                        help="built-in scenario name or TOML file (default: %(default)s)")
    parser.add_argument("--seed", type=args_.seed, default=1,
                        help="seed of the rover's world (default 1)")
    parser.add_argument("--id", dest="rover_id", metavar="ID",
                        help="the id said in hello (default: the role)")
    parser.add_argument("--token", help="the hello token, when the server asks for one")
    parser.add_argument("--accept-faults", action="store_true",
                        help="take faults over the link (the server's fault command): "
                             "without it every fault is refused, so a rover is never broken "
                             "by accident")
    parser.add_argument("--no-telemetry", action="store_true",
                        help="offer no telemetry (mailboxes, tree, map, pose, events)")
    parser.add_argument("--speed", type=float, default=1.0, metavar="N",
                        help="clock rate: 1 is real time (default); the server must match it")


def run(args: argparse.Namespace) -> int:
    from server.links.spec import parse_link_for
    from world.scenario import ScenarioError, load_scenario

    try:
        link = parse_link_for(args.link, ROVER_LINK)
        if not args.speed > 0 or args.speed > 1000:
            raise ValueError(f"--speed must be within 0..1000, got {args.speed:g}")
        scenario = load_scenario(args.scenario)
    except (ValueError, ScenarioError, OSError) as exc:
        print(f"hideseek rover: {exc}", file=sys.stderr)
        return 2

    from actors import running, scaled_clock, seed_trio_scheduler
    from supervisors.remote import run_remote_rover

    def report(text: str) -> None:
        print(f"{args.role}: {text}", flush=True)

    seed_trio_scheduler(args.seed)
    clock = None if args.speed == 1.0 else scaled_clock(args.speed)
    print(f"{args.role}: {scenario.name} (seed {args.seed}), link {args.link}, "
          f"speed x{args.speed:g}, faults over the link "
          f"{'accepted' if args.accept_faults else 'refused'}; Ctrl-C stops", flush=True)
    try:
        running.run(lambda: run_remote_rover(scenario, args.role, link, seed=args.seed,
                                             rover_id=args.rover_id, token=args.token,
                                             report=report, accept_faults=args.accept_faults,
                                             telemetry=not args.no_telemetry), clock=clock)
    except BaseException as exc:  # noqa: BLE001 - sorted out below: never a traceback
        bad = [e for e in leaves(exc) if isinstance(e, OSError | ValueError)]
        if not bad or is_interrupt(exc):
            raise  # a stop by signal: tui.cli prints its one line
        print(f"hideseek rover: {getattr(bad[0], 'strerror', None) or bad[0]}", file=sys.stderr)
        return 1
    return 0

