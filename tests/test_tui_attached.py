"""The console treats an attached rover as a simulated one: queues, tree, faults.

``hideseek rover`` runs as its own process over TCP on loopback; the console
(`tui.live.LiveSystem` in `ConsoleApp`, driven headless) shows what its
telemetry says and sends it a fault from the fault dialog.
"""

from __future__ import annotations

import asyncio
import pathlib
import subprocess
import sys

from server.links import parse_link
from tests.raw_client import free_port
from tests.test_tui_app import inject_from_dialog, notes, press, tree_text, until
from tui.app import ConsoleApp
from tui.live import LiveSystem
from world.scenario import load_scenario

ROOT = pathlib.Path(__file__).resolve().parent.parent


def test_console_shows_an_attached_rovers_queues_tree_and_takes_its_faults() -> None:
    """An attached mapper's wifly, motor, lidar, map and nav mailboxes show on the Queues
    tab and its tree on the Tree tab, from telemetry; the fault dialog lists its faults
    and the link's, and lidar dead reaches it (its reply and its events come back)."""
    port = free_port()
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
            await inject_from_dialog(app, "mapper/lidar", "dead")
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
