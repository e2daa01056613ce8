"""Game frames' round trip at 57600 baud with an attached rover's telemetry on and off.

The real server serves a serial port; the mapper (`supervisors.remote`, its
own world and firmware, exploring an empty room after ``start``) is on a
second pty; a relay joins the two and paces each direction at the line rate
(57600 baud, 8N1: 5760 bytes/s; a pty has no baud rate of its own), as a UART
does: bytes queue behind the ones on the wire. Every 0.25 s the server sends
a reliable ``fault`` frame (a ``clear`` with nothing to clear: harmless) and
times it until the rover's reliable ``fault_reply`` arrives: a game exchange
through the whole firmware path. Run once with telemetry off, once on (the
server's default intervals, 25 % share), on Trio's virtual clock that only
jumps when nothing can run and no byte is on its way, so the machine's load
does not enter the figures.

Reports per run: round trips p50/p95 [ms], the p95 ratio on/off (target 1.2
at most), telemetry's bytes and share of the line's capacity in the rover's
direction, and all bytes the rover sent.

Run: ``python -m benchmarks.telemetry [--seconds 60] [--json]``.
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tty

import trio
import trio.testing

from server.links import parse_link
from server.server import ServerConfig, open_server
from server.store import Store
from supervisors.remote import open_remote_rover
from world.scenario import load_scenario

BAUD = 57600
LINE_RATE = BAUD / 10  # 8N1 [bytes/s]
EXCHANGE_S = 0.25      # one timed exchange per this [s]
CLOCK_THRESHOLD_S = 0.0005  # real time with nothing to do before the virtual clock jumps [s]


def _pty_pair() -> tuple[trio.lowlevel.FdStream, str, int]:
    master, slave = os.openpty()
    tty.setraw(slave)
    return trio.lowlevel.FdStream(master), os.ttyname(slave), slave


async def _paced_relay(a, b, rate: float) -> None:
    """Bytes from ``a`` to ``b`` at ``rate`` [bytes/s], in order (a UART's wire)."""
    while data := await a.receive_some(256):
        await trio.sleep(len(data) / rate)
        await b.send_all(data)


def _pct(values: list[float], q: float) -> float:
    values = sorted(values)
    return values[min(len(values) - 1, int(q * len(values)))]


async def _run(seconds: float, telemetry: bool) -> dict:
    scenario = load_scenario("empty")
    server_end, server_path, s1 = _pty_pair()
    rover_end, rover_path, s2 = _pty_pair()
    sent: dict[int, float] = {}
    rtts: list[float] = []
    out: dict = {}
    try:
        async with trio.open_nursery() as cable:
            cable.start_soon(_paced_relay, server_end, rover_end, LINE_RATE)
            cable.start_soon(_paced_relay, rover_end, server_end, LINE_RATE)
            with Store(":memory:") as store:
                async with open_server(store, ServerConfig(rovers=frozenset({"mapper"}))) \
                        as server, open_remote_rover(
                            scenario, "mapper", parse_link(f"serial:{rover_path},{BAUD}"),
                            accept_faults=True, telemetry=telemetry) as rover:
                    events = server.subscribe()
                    server.start_serial(server_path, BAUD)
                    with trio.fail_after(60):
                        async for e in events:
                            if e.kind == "hello":
                                break
                    await server.command("start_mapping")

                    async def replies() -> None:
                        async for e in events:
                            if e.kind == "fault_reply" and e.data["fault_id"] in sent:
                                rtts.append(trio.current_time() - sent.pop(e.data["fault_id"]))

                    async with trio.open_nursery() as inner:
                        inner.start_soon(replies)
                        t0 = trio.current_time()
                        fid = 0
                        while trio.current_time() - t0 < seconds:
                            server.rover_fault("mapper", "clear", "lidar", "*")
                            fid += 1
                            sent[fid] = trio.current_time()
                            await trio.sleep(EXCHANGE_S)
                        await trio.sleep(5)  # the last replies
                        elapsed = trio.current_time() - t0
                        inner.cancel_scope.cancel()
                    lane = rover.telemetry.stats() if rover.telemetry else None
                    out = {"telemetry": telemetry, "exchanges": fid, "answered": len(rtts),
                           "rtt_p50_ms": 1000 * statistics.median(rtts),
                           "rtt_p95_ms": 1000 * _pct(rtts, 0.95),
                           "telemetry_bytes": lane.bytes if lane else 0,
                           "telemetry_frames": lane.frames if lane else 0,
                           "telemetry_share": (lane.bytes if lane else 0) / (LINE_RATE * elapsed),
                           "rover_bytes_out": rover.bytes_out,
                           "line_use": rover.bytes_out / (LINE_RATE * elapsed)}
            cable.cancel_scope.cancel()
    finally:
        os.close(s1)
        os.close(s2)
    return out


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0,
                        help="timed exchanges for this long per run [virtual s] (default 60)")
    parser.add_argument("--json", action="store_true")
    args = parser.parse_args()
    clock = trio.testing.MockClock(autojump_threshold=CLOCK_THRESHOLD_S)
    off = trio.run(_run, args.seconds, False, clock=clock)
    clock = trio.testing.MockClock(autojump_threshold=CLOCK_THRESHOLD_S)
    on = trio.run(_run, args.seconds, True, clock=clock)
    ratio = on["rtt_p95_ms"] / off["rtt_p95_ms"]
    if args.json:
        print(json.dumps({"off": off, "on": on, "p95_ratio": ratio}))
        return
    for run in (off, on):
        print(f"telemetry {'on ' if run['telemetry'] else 'off'}: {run['answered']}/"
              f"{run['exchanges']} exchanges, round trip p50 {run['rtt_p50_ms']:.0f} ms, "
              f"p95 {run['rtt_p95_ms']:.0f} ms; telemetry {run['telemetry_bytes']} B in "
              f"{run['telemetry_frames']} frames = {100 * run['telemetry_share']:.1f} % of the "
              f"line; rover sent {run['rover_bytes_out']} B = {100 * run['line_use']:.1f} %")
    print(f"p95 on/off: {ratio:.2f}x (target <= 1.2x)")


if __name__ == "__main__":
    main()
