"""The ``hideseek`` command line: one entry point, one module per subcommand.

Each subcommand lives in its own module under ``tui/`` exposing
``add_arguments(parser)`` and ``run(args) -> int`` (the exit status). Only the
module of the subcommand being run is imported (its options are added to its
parser alone; ``hideseek --help`` lists every subcommand from `COMMANDS`), and
the installed version is looked up only for ``--version``: a game's process
start pays for nothing but its own command (``importlib.metadata`` alone costs
about 20 ms, the campaign and shrink modules as much again).
"""

from __future__ import annotations

import argparse
import gc
import importlib
import sys
from collections.abc import Sequence
from typing import Any

from tui import stopping

#: subcommand -> (module, one-line help)
COMMANDS: dict[str, tuple[str, str]] = {
    "run": ("tui.cmd_run", "one whole game, headless, in virtual time (--json for figures)"),
    "demo": ("tui.cmd_demo", "a small supervised actor tree under fault, printed as it recovers"),
    "serve": ("tui.cmd_serve", "run the game server for real rovers (TCP, serial), log events"),
    "maps": ("tui.cmd_maps", "list stored games and maps"),
    "export-map": ("tui.cmd_maps", "export a game's map as PGM + map_server YAML, or PNG"),
    "rover": ("tui.cmd_rover", "one simulated rover as its own process, over TCP or serial"),
    "play": ("tui.cmd_play", "the terminal console: watch, steer and break a game"),
    "campaign": ("tui.cmd_campaign", "many seeded games under random faults, invariants checked"),
    "replay": ("tui.cmd_replay", "open a recording (.mcap) in the console: pause, step, seek"),
    "shrink": ("tui.cmd_shrink", "a failing game's faults shrunk to what the failure needs"),
    "report": ("tui.cmd_report", "a campaign's results as one HTML page with charts"),
    "ports": ("tui.cmd_ports", "list the serial ports a rover may be attached to"),
    "check-rover": ("tui.cmd_check_rover", "check a rover's firmware against the protocol, "
                    "rule by rule"),
}


class _Parser(argparse.ArgumentParser):
    """Bad options are one line naming the option and the rule, and exit status 2 (no
    usage block: ``-h`` shows it)."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: {message}\n")


def version() -> str:
    """The installed distribution's version (``unknown`` when run from a bare checkout)."""
    from importlib import metadata  # noqa: PLC0415 - only ``--version`` pays for it

    try:
        return metadata.version("hideseek")
    except metadata.PackageNotFoundError:
        return "unknown"


class _VersionAction(argparse.Action):
    """``--version``: prints the version, looked up only when asked for."""

    def __init__(self, option_strings: Sequence[str], dest: str = argparse.SUPPRESS,
                 default: Any = argparse.SUPPRESS, help: str | None = None) -> None:  # noqa: A002
        super().__init__(option_strings=option_strings, dest=dest, default=default, nargs=0,
                         help=help or "show program's version number and exit")

    def __call__(self, parser: argparse.ArgumentParser, namespace: argparse.Namespace,
                 values: Any, option_string: str | None = None) -> None:
        parser._print_message(f"hideseek {version()}\n", sys.stdout)  # as argparse's own
        parser.exit()


def _command_in(argv: Sequence[str]) -> str | None:
    """The subcommand ``argv`` names: its first word that is not an option (the top-level
    options take no value), or None."""
    for word in argv:
        if word == "--":
            return None
        if not word.startswith("-"):
            return word
    return None


def build_parser(command: str | None = None, *, every: bool = True) -> argparse.ArgumentParser:
    """The parser: every subcommand's options (``every``), or only ``command``'s (the
    others are listed, with their help line, but their modules are not imported)."""
    parser = _Parser(
        prog="hideseek",
        description="Three-rover hide-and-seek on a supervised actor system.",
    )
    parser.add_argument("--version", action=_VersionAction)
    sub = parser.add_subparsers(dest="command", metavar="COMMAND")
    for name, (module_name, help_text) in COMMANDS.items():
        p = sub.add_parser(name, help=help_text, description=help_text)
        p.set_defaults(_module=module_name)
        if not every and name != command:
            continue
        try:
            importlib.import_module(module_name).add_arguments(p)
        except ImportError as exc:  # one broken command must not take the others down
            p.set_defaults(_module=None, _broken=f"{name}: not available ({exc})")
    return parser


def main(argv: list[str] | None = None) -> int:
    words = sys.argv[1:] if argv is None else argv
    # Importing a command makes some hundred thousand objects that live as long as the
    # process; the cyclic collector would walk them again and again while they are made,
    # and in every full collection after, and could free none. It pauses while the parser
    # and its command's module are made, and when this is the process's own command line
    # (no ``argv`` given) they are then frozen: out of every later collection (a game's
    # start and its collections cost about 30 ms less).
    gc.disable()
    try:
        parser = build_parser(_command_in(words), every=False)
        args = parser.parse_args(words)
    finally:
        if argv is None:
            gc.freeze()
        gc.enable()
    if getattr(args, "_broken", None):
        print(f"hideseek {args._broken}", file=sys.stderr)
        return 2
    if not getattr(args, "_module", None):
        parser.print_help()
        return 2
    module = importlib.import_module(args._module)
    stopping.install()
    try:
        return int(module.run(args) or 0)
    except BaseException as exc:  # noqa: BLE001 - a stop by signal is sorted out here, once
        if not stopping.is_interrupt(exc):
            raise
        print(stopping.stopped_line(args.command), file=sys.stderr)
        return 0


if __name__ == "__main__":
    sys.exit(main())
