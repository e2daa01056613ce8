"""``hideseek ports``: the serial ports of this machine, to give ``--rover ROLE=PORT``.

Listed with pyserial's ``serial.tools.list_ports`` (what ``python -m
serial.tools.list_ports -v`` shows): device, description, hardware id. A USB
serial adapter appears as ``/dev/ttyUSB0`` or ``/dev/ttyACM0`` on Linux,
``/dev/cu.usbserial-*`` on macOS, ``COM3`` on Windows. Pseudo-terminals
(``hideseek rover --link pty``) are not listed: that command prints its path.
"""

from __future__ import annotations

import argparse
import json


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true",
                        help="print one JSON list of {device, description, hwid}")


def run(args: argparse.Namespace) -> int:
    from serial.tools import list_ports

    ports = sorted(list_ports.comports(), key=lambda p: p.device)
    rows = [{"device": p.device, "description": p.description, "hwid": p.hwid} for p in ports]
    if args.json:
        print(json.dumps(rows))
        return 0
    if not rows:
        print("no serial ports found (a USB adapter shows as /dev/ttyUSB0, /dev/ttyACM0 or COMn)")
        return 0
    width = max(len(r["device"]) for r in rows)
    for r in rows:
        print(f"{r['device']:<{width}}  {r['description']}  [{r['hwid']}]")
    return 0
