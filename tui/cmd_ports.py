"""``hideseek ports``: the serial ports of this machine, to give ``--rover ROLE=PORT``.

Listed with pyserial's ``serial.tools.list_ports`` (what ``python -m
serial.tools.list_ports -v`` shows): device, description, hardware id. A USB
serial adapter appears as ``/dev/ttyUSB0`` or ``/dev/ttyACM0`` on Linux,
``/dev/cu.usbserial-*`` on macOS, ``COM3`` on Windows. Beside each kernel name
go its stable names, udev's symlinks in ``/dev/serial/by-id`` (named for the
adapter's vendor, model and serial number): the kernel renumbers an adapter
that is replugged (``ttyUSB0`` coming back as ``ttyUSB1``), its by-id name
stays, so ``--rover mapper=serial:/dev/serial/by-id/...`` finds it again.
Pseudo-terminals (``hideseek rover --link pty``) are not listed: that command
prints its path.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib

__all__ = ["add_arguments", "run", "stable_names", "BY_ID"]

BY_ID = "/dev/serial/by-id"
"""Where udev keeps the stable names of serial adapters (Linux)."""


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--json", action="store_true",
                        help="print one JSON list of {device, by_id, description, hwid}")


def stable_names(folder: str = BY_ID) -> dict[str, list[str]]:
    """Kernel device path -> the stable names (symlinks in ``folder``) that lead to it,
    sorted; empty where the folder does not exist (no adapter plugged, not Linux)."""
    names: dict[str, list[str]] = {}
    try:
        entries = sorted(pathlib.Path(folder).iterdir())
    except OSError:
        return names
    for link in entries:
        if link.is_symlink():
            names.setdefault(os.path.realpath(link), []).append(str(link))
    return names


def run(args: argparse.Namespace) -> int:
    from serial.tools import list_ports

    ports = sorted(list_ports.comports(), key=lambda p: p.device)
    stable = stable_names(BY_ID)
    rows = [{"device": p.device, "by_id": stable.get(os.path.realpath(p.device), []),
             "description": p.description, "hwid": p.hwid} for p in ports]
    if args.json:
        print(json.dumps(rows))
        return 0
    if not rows:
        print("no serial ports found (a USB adapter shows as /dev/ttyUSB0, /dev/ttyACM0 or COMn)")
        return 0
    width = max(len(r["device"]) for r in rows)
    for r in rows:
        print(f"{r['device']:<{width}}  {r['description']}  [{r['hwid']}]")
        for name in r["by_id"]:
            print(f"{'':<{width}}  stable name: {name}")
    if any(r["by_id"] for r in rows):
        print("a stable name stays when a replugged adapter gets another kernel name: "
              "give it as --rover ID=serial:NAME")
    return 0
