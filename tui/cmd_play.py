"""``hideseek play``: open the console on the simulated system (or the fake one with --fake).

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
                        help="attach a rover over a link, e.g. seeker=serial:/dev/pts/4 "
                             "(repeatable)")
    parser.add_argument("--fake", action="store_true",
                        help="run the built-in fake system (the console's demo and test double)")
    parser.add_argument("--speed", choices=list(SPEED_CHOICES), default="1",
                        help="initial speed of simulated time (default: %(default)s)")
    parser.add_argument("--export-dir", default=".", metavar="DIR",
                        help="where the export key saves maps (default: current directory)")


def run(args: argparse.Namespace) -> int:
    from tui.app import ConsoleApp

    if args.rover:
        print("hideseek play: --rover (real rovers in the console) is not available yet; "
              "use `hideseek serve --rover ID=LINK` for real rovers. Ignoring: "
              + ", ".join(f"{r}={ln}" for r, ln in args.rover), file=sys.stderr)
    if args.fake:
        from tui.fake import FakeSystem

        system = FakeSystem(seed=args.seed, scenario=args.scenario,
                            speed=SPEED_CHOICES[args.speed])
    else:
        from tui.live import LiveSystem
        from world.scenario import ScenarioError, load_scenario

        try:
            scenario = load_scenario(args.scenario)
        except (ScenarioError, OSError) as exc:
            print(f"hideseek play: {exc}", file=sys.stderr)
            return 2
        system = LiveSystem(scenario, seed=args.seed, speed=SPEED_CHOICES[args.speed],
                            db=args.db)
    app = ConsoleApp(system, export_dir=args.export_dir)
    app.run()
    if app.system_error is not None:
        print(f"hideseek play: the system stopped: {type(app.system_error).__name__}: "
              f"{app.system_error}", file=sys.stderr)
        return 1
    return 0
