"""The console treats an attached rover as a simulated one: queues, tree, faults.

``hideseek rover`` runs as its own process over TCP on loopback; the console
(`tui.live.LiveSystem` in `ConsoleApp`, driven headless) shows what its
telemetry says and sends it a fault from the fault dialog.
"""

from __future__ import annotations

import asyncio
import pathlib
import socket
import subprocess
import sys

from textual.widgets import Button, Select

from server.links import parse_link
from tests.test_tui_app import notes, press, tree_text, until
from tui.app import ConsoleApp
from tui.live import LiveSystem
from tui.widgets import FaultDialog
from world.scenario import load_scenario

ROOT = pathlib.Path(__file__).resolve().parent.parent


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def test_console_shows_an_attached_rovers_queues_tree_and_takes_its_faults() -> None:
    """An attached mapper's wifly, motor, lidar, map and nav mailboxes show on the Queues
    tab and its tree on the Tree tab, from telemetry; the fault dialog lists its faults
    and the link's, and lidar dead reaches it (its reply and its events come back)."""
    port = _free_port()
    live = LiveSystem(load_scenario("empty"), remote={"mapper": parse_link("tcp")},
                      listen=[parse_link(f"tcp:127.0.0.1:{port}")])
    app = ConsoleApp(live)
    proc = subprocess.Popen(
        [sys.executable, "-m", "tui.cli", "rover", "--role", "mapper", "--scenario", "empty",
         "--link", f"tcp:127.0.0.1:{port}", "--accept-faults"],
        cwd=ROOT, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)

    async def main() -> None:
        async with app.run_test(size=(120, 40), notifications=True):
            await until(lambda: app.snapshot is not None, "the first snapshot")
            await until(lambda: {q.name for q in app.snapshot.queues} >= {
                "mapper/wifly", "mapper/motor", "mapper/lidar", "mapper/map", "mapper/nav"},
                "the mapper's mailboxes", timeout=60)
            wifly = next(q for q in app.snapshot.queues if q.name == "mapper/wifly")
            assert wifly.rover == "mapper" and wifly.capacity > 0
            press(app, "3")
            await until(lambda: "mapper/nav" in tree_text(app) or "nav" in tree_text(app),
                        "the mapper's tree")
            targets = {t.target: t.kinds for t in app.snapshot.catalogue}
            assert "dead" in targets["mapper/lidar"] and "loss" in targets["mapper/link"]
            press(app, "f")
            await until(lambda: isinstance(app.screen, FaultDialog)
                        and app.screen.query(Select)
                        and all(w.is_mounted for w in app.screen.query(Select)), "fault dialog")
            dialog = app.screen
            dialog.query_one("#target", Select).value = "mapper/lidar"
            await until(lambda: len(dialog.query_one("#kind", Select)._options) > 1, "kinds")
            dialog.query_one("#kind", Select).value = "dead"
            dialog.query_one("#inject", Button).press()
            await until(lambda: any("fault reply" in e.text and "accepted" in e.text
                                    for e in app.snapshot.timeline), "the rover's reply",
                        timeout=20)
            await until(lambda: any("fault_injected mapper/lidar" in e.text
                                    for e in app.snapshot.timeline), "its injected event",
                        timeout=20)
            assert not [n for n in notes(app) if "rror" in n]

    try:
        asyncio.run(main())
    finally:
        proc.terminate()
        out, _ = proc.communicate(timeout=20)
    assert "fault_injected mapper/lidar dead" in out
