"""``hideseek play``: open the console on a system (for now the fake one).

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
    parser.add_argument("--scenario", default="fake-room", metavar="NAME|FILE",
                        help="scenario name or TOML file (default: %(default)s)")
    parser.add_argument("--seed", type=int, default=0, help="seed of the run (default: 0)")
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
    from tui.fake import FakeSystem

    if args.rover:
        print("hideseek play: --rover needs the real system; the fake system has only "
              "simulated rovers, ignoring: " + ", ".join(f"{r}={ln}" for r, ln in args.rover),
              file=sys.stderr)
    system = FakeSystem(seed=args.seed, scenario=args.scenario,
                        speed=SPEED_CHOICES[args.speed])
    app = ConsoleApp(system, export_dir=args.export_dir)
    app.run()
    if app.system_error is not None:
        print(f"hideseek play: the system stopped: {type(app.system_error).__name__}: "
              f"{app.system_error}", file=sys.stderr)
        return 1
    return 0
