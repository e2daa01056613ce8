"""Frames per second parsed and answered by the server: in process, TCP loopback, pty.

A client sends reliable ``status`` frames (each one is parsed, checked against
the catalogue, delivered and acknowledged by the server) through its own
`ReliableSession` with a window of 32, and counts until every one is acked.

* baseline: two sessions in one process, no I/O (the codec's own ceiling);
* tcp: the real `Server` on TCP loopback;
* pty: the real `Server` on a pty serial link at 115200 baud; the client
  paces its bytes at the line rate (a pty itself has no baud rate), so the
  share of line rate achieved is the figure of merit.

CPU is process CPU time / wall time over the run (both server and client
run in this process). Run: ``python -m benchmarks.protocol [--quick]``.
"""

from __future__ import annotations

import argparse
import json
import os
import time
import tty

import trio

from server.protocol import Frame, ReliableSession, encode_frame, make_frame
from server.server import open_server
from server.store import Store

BAUD = 115200
LINE_RATE = BAUD / 10  # 8N1: 10 bits per byte [bytes/s]


def _status(i: int) -> Frame:
    return Frame("status", "status", {"state": "bench", "detail": f"frame {i}"})


def _client() -> ReliableSession:
    return ReliableSession(window=32, outbox_limit=100000, rto_initial_s=2.0, rto_min_s=1.0)


def bench_baseline(n: int) -> dict:
    """Two sessions in one process: send, parse, deliver, ack."""
    a, b = _client(), ReliableSession(window=32)
    b.feed(a.transmit(0.0), 0.0)
    a.feed(b.transmit(0.0), 0.0)
    for i in range(n):
        a.send(_status(i), reliable=True)
    t0, c0 = time.perf_counter(), time.process_time()
    delivered, t = 0, 0.0
    while a.stats(t).unacked or a.stats(t).queued:
        t += 1e-4
        delivered += len(b.feed(a.transmit(t), t))
        a.feed(b.transmit(t), t)
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    assert delivered == n
    return {"frames": n, "wall_s": wall, "fps": n / wall, "cpu": cpu / wall,
            "bytes_per_frame": len(encode_frame(Frame("status", "status", _status(0).data,
                                                      seq=1000, ack=10)))}


async def _drive(receive, send, n: int, pace_bytes_s: float | None) -> dict:
    client = _client()
    client.send(make_frame("hello", {"id": "bench", "role": "mapper"}))
    for i in range(n):
        client.send(_status(i), reliable=True)
    done = trio.Event()
    sent_bytes = 0

    async def reader() -> None:
        while True:
            data = await receive()
            if not data:
                return
            client.feed(data, trio.current_time())
            s = client.stats(trio.current_time())
            if s.unacked == 0 and s.queued == 0:
                done.set()

    t0, c0 = time.perf_counter(), time.process_time()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(reader)
        budget_t = trio.current_time()
        while not done.is_set():
            now = trio.current_time()
            data = client.transmit(now)
            if data:
                if pace_bytes_s:
                    for k in range(0, len(data), 64):  # write at the line rate
                        piece = data[k:k + 64]
                        budget_t = max(budget_t, trio.current_time()) + len(piece) / pace_bytes_s
                        await send(piece)
                        await trio.sleep_until(budget_t)
                else:
                    await send(data)
                sent_bytes += len(data)
            with trio.move_on_at(min(client.next_deadline(now), now + 0.002)):
                await done.wait()
        nursery.cancel_scope.cancel()
    wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    s = client.stats(trio.current_time())
    return {"frames": n, "wall_s": wall, "fps": n / wall, "cpu": cpu / wall,
            "bytes_out": sent_bytes, "resent": s.resent, "rtt_ms": (s.rtt_s or 0) * 1e3}


def bench_tcp(n: int) -> dict:
    async def main() -> dict:
        async with open_server(Store(":memory:")) as server:
            port = await server.listen_tcp("127.0.0.1", 0)
            stream = await trio.open_tcp_stream("127.0.0.1", port)
            r = await _drive(lambda: stream.receive_some(65536), stream.send_all, n, None)
            await stream.aclose()
            return r
    return trio.run(main)


def bench_pty(n: int) -> dict:
    master, slave = os.openpty()
    tty.setraw(slave)
    path = os.ttyname(slave)

    async def main() -> dict:
        async with open_server(Store(":memory:")) as server:
            server.start_serial(path, BAUD)
            pty = trio.lowlevel.FdStream(os.dup(master))
            r = await _drive(lambda: pty.receive_some(65536), pty.send_all, n, LINE_RATE)
            await pty.aclose()
            return r
    try:
        r = trio.run(main)
    finally:
        os.close(master)
        os.close(slave)
    r["line_share"] = r["bytes_out"] / r["wall_s"] / LINE_RATE
    return r


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer frames (a few seconds)")
    args = parser.parse_args()
    n_fast, n_pty = (2000, 150) if args.quick else (20000, 1000)
    base = bench_baseline(n_fast)
    tcp = bench_tcp(n_fast)
    pty = bench_pty(n_pty)
    print(f"{'link':<22}{'frames':>8}{'frames/s':>11}{'vs base':>9}{'CPU':>7}  notes")
    print(f"{'in process (baseline)':<22}{base['frames']:>8}{base['fps']:>11.0f}{1:>9.2f}"
          f"{base['cpu']:>7.0%}  {base['bytes_per_frame']} bytes/frame")
    print(f"{'TCP loopback':<22}{tcp['frames']:>8}{tcp['fps']:>11.0f}"
          f"{tcp['fps'] / base['fps']:>9.2f}{tcp['cpu']:>7.0%}  rtt {tcp['rtt_ms']:.2f} ms, "
          f"resent {tcp['resent']}")
    print(f"{'pty at 115200 baud':<22}{pty['frames']:>8}{pty['fps']:>11.0f}"
          f"{pty['fps'] / base['fps']:>9.4f}{pty['cpu']:>7.0%}  {pty['line_share']:.0%} of line "
          f"rate ({LINE_RATE:.0f} B/s), resent {pty['resent']}")
    print(json.dumps({
        "baseline_fps": round(base["fps"]), "tcp_fps": round(tcp["fps"]),
        "tcp_vs_baseline": round(tcp["fps"] / base["fps"], 3), "tcp_cpu": round(tcp["cpu"], 2),
        "pty_fps": round(pty["fps"], 1), "pty_line_share": round(pty["line_share"], 3),
        "pty_cpu": round(pty["cpu"], 3), "bytes_per_frame": base["bytes_per_frame"],
    }))


if __name__ == "__main__":
    main()
