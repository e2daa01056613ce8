"""``hideseek check-rover LINK``: check a rover's firmware against docs/protocol.md.

Plays the server's side over LINK (``tcp:HOST:PORT`` to a rover waiting with
``--link tcpin:...``, ``tcpin:HOST:PORT`` for a rover that connects,
``udpin:HOST:PORT`` for one that sends datagrams there (``--link udpout:``), ``serial:PORT,BAUD``)
and reports every rule as pass, fail or skip (`server.conformance`). Exit
status 0 when nothing failed, 1 when a rule failed, 2 for bad input (a bad
link string or option, an unreachable address or port: one line naming it).
"""

from __future__ import annotations

import argparse
import sys

from server.protocol import ROLES
from tui import args as args_


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("link", metavar="LINK",
                        help="tcp:HOST:PORT (connect to a rover listening with --link tcpin:), "
                             "tcpin:HOST:PORT (wait for a rover to connect), udpin:HOST:PORT "
                             "(receive its datagrams there) or serial:PORT[,BAUD]")
    parser.add_argument("--role", choices=ROLES,
                        help="the role the rover must say in hello (default: the one it says)")
    parser.add_argument("--json", action="store_true",
                        help="print the findings as one JSON object")
    parser.add_argument("--timeout", type=args_.positive_seconds, default=300.0, metavar="S",
                        help="the whole check at most, in the rover's seconds (default "
                             "%(default)g)")
    parser.add_argument("--speed", type=float, default=1.0, metavar="N",
                        help="the rover's clock rate (hideseek rover --speed N): every bound "
                             "is checked in its seconds (default 1, real time)")
    parser.add_argument("--slack", type=args_.positive_seconds, default=0.4, metavar="S",
                        help="added to every timing bound, in the rover's seconds: a "
                             "rover's tick, a loaded host (default %(default)g)")
    parser.add_argument("--transcript", metavar="FILE",
                        help="write every line of the check, both ways, to FILE")
    parser.add_argument("--map-seconds", type=args_.positive_seconds, default=4.0,
                        metavar="S", help="how long a mapper maps before stop (default "
                                          "%(default)g)")


def run(args: argparse.Namespace) -> int:
    from server.conformance import LinkUnreachable, Options, RoverLink, parse_rover_link

    try:
        spec = parse_rover_link(args.link)
        if not 0 < args.speed <= 1000:
            raise ValueError(f"--speed must be within 0..1000, got {args.speed:g}")
    except ValueError as exc:
        print(f"hideseek check-rover: {exc}", file=sys.stderr)
        return 2

    from actors import running, scaled_clock
    from server.conformance import as_json, as_table, check_rover, summary

    opts = Options(role=args.role, timeout_s=args.timeout, map_s=args.map_seconds,
                   slack_s=args.slack)
    clock = None if args.speed == 1.0 else scaled_clock(args.speed)
    try:
        findings, transcript = running.run(check_rover, RoverLink(spec), opts, clock=clock)
    except LinkUnreachable as exc:
        print(f"hideseek check-rover: {exc}", file=sys.stderr)
        return 2
    if args.transcript:
        try:
            with open(args.transcript, "w", encoding="utf-8") as out:
                out.writelines(seen.show(full=True) + "\n" for seen in transcript.lines)
        except OSError as exc:
            print(f"hideseek check-rover: cannot write {args.transcript}: {exc.strerror}",
                  file=sys.stderr)
    print(as_json(findings) if args.json else as_table(findings), flush=True)
    return 1 if summary(findings)["failed"] else 0
