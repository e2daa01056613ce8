"""Hostile load on ``hideseek serve`` over TCP loopback while legitimate rovers talk.

The server runs as its own process, configured as deployed (``--rover ID=tcp``
with per-rover tokens, default limits: 64 connections, 16 without hello per
address, 64 waiting beyond those caps, 5 s hello timeout, a bad-frame budget per
link). For ``--seconds``, this process attacks it:

* **holders** try to keep ``--connections`` idle TCP connections open (a
  connection the server closes is opened again), from 127.0.0.1 or spread over
  ``--sources`` loopback addresses (which defeats the per-address limit, so
  the connection cap and the waiting room carry the load);
* **slowloris**: 50 connections send one byte of a hello per second;
* **fuzzer** (its own process, from 127.0.0.3): one connection (reopened
  when the server closes it) sends mutated frames as fast as it can.

Meanwhile two legit rovers run in a process of their own (so the attackers'
load does not delay them there), from 127.0.0.2, another loopback address,
timed alone for 5 s first, then under the attack:

* the **rover** ``h1`` stays
  connected, heartbeats, and sends a frame with ``seq`` every 0.2 s, timing
  each ack (``link_closed_by_server``: the server closed its link);
* the **reconnecting rover** ``s1`` connects, says hello and
  times hello -> welcome, once a second.

It reports the legit rovers' latencies (median, 95th percentile, worst), how
many hellos went unanswered, the server's RSS before and after [MB], the
database's growth, the fuzzer's frames/s, the holders' connection counts and
the CPU each side used (share of one core).
Loopback only; bounded in connections and time.

Run: ``python -m benchmarks.hostile [--connections 2000] [--seconds 30]
[--sources N] [--max-connections N]``.
"""

from __future__ import annotations

import argparse
import json
import os
import pathlib
import re
import socket
import statistics
import subprocess
import sys
import tempfile
import time

import numpy as np
import trio

from server.protocol import Frame, decode_line, encode_frame, make_frame

TOKENS = {"h1": "hider-secret", "s1": "seeker-secret"}
LEGIT_SOURCE = "127.0.0.2"
FUZZ_SOURCE = "127.0.0.3"


def _rss_mb(pid: int) -> float:
    for line in pathlib.Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def _cpu_s(pid: int) -> float:
    """User + system CPU time of a process [s]."""
    fields = pathlib.Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _db_use(db: str) -> tuple[int, int]:
    """(bytes in use, event rows) of the server's database, read-only."""
    from server.store import Store

    with Store(db, readonly=True) as store:
        rows = store._db.execute("SELECT count(*) FROM events").fetchone()[0]
        return store.size_bytes(), rows


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def _connect(port: int, source: str | None = None) -> trio.SocketStream:
    sock = trio.socket.socket()
    try:
        if source:
            await sock.bind((source, 0))
        await sock.connect(("127.0.0.1", port))
    except OSError:
        sock.close()
        raise
    return trio.SocketStream(sock)


def _hello(rid: str, role: str, token: str | None) -> bytes:
    return encode_frame(make_frame("hello", {"id": rid, "role": role, "token": token}))


class Counters:
    def __init__(self) -> None:
        self.opened = 0
        self.open_now = 0
        self.open_max = 0
        self.connect_failed = 0
        self.fuzz_frames = 0
        self.fuzz_bytes = 0
        self.fuzz_closed = 0
        self.slow_closed = 0
        self.ack_ms: list[float] = []
        self.unacked = 0
        self.rover_closed = False
        self.welcome_ms: list[float] = []
        self.no_welcome = 0


async def _holder(port: int, c: Counters, stop: trio.Event, source: str | None) -> None:
    """Hold one idle connection, reopening it whenever the server closes it."""
    while not stop.is_set():
        try:
            stream = await _connect(port, source)
        except OSError:
            c.connect_failed += 1
            await trio.sleep(0.5)
            continue
        c.opened += 1
        c.open_now += 1
        c.open_max = max(c.open_max, c.open_now)
        try:
            with trio.move_on_after(60):
                while not stop.is_set():
                    if not await stream.receive_some(4096):
                        break
        except (trio.BrokenResourceError, OSError):
            pass
        finally:
            c.open_now -= 1
            await stream.aclose()
        await trio.sleep(0.05)


async def _slowloris(port: int, c: Counters, stop: trio.Event) -> None:
    line = _hello("h1", "hider", "x" * 20)
    while not stop.is_set():
        try:
            stream = await _connect(port)
        except OSError:
            await trio.sleep(0.5)
            continue
        try:
            for b in line:
                await stream.send_all(bytes([b]))
                await trio.sleep(1.0)
                if stop.is_set():
                    break
        except (trio.BrokenResourceError, OSError):
            c.slow_closed += 1
        await stream.aclose()


async def _fuzzer(port: int, c: Counters, stop: trio.Event, seed: int,
                  source: str | None = None) -> None:
    rng = np.random.default_rng(seed)
    good = [encode_frame(make_frame("pose", {"x": 1.5, "y": 2, "heading": 3})),
            encode_frame(make_frame("hello", {"id": "h1", "role": "hider", "token": "no"})),
            encode_frame(Frame("map_request", "none", None, seq=4))]
    while not stop.is_set():
        try:
            stream = await _connect(port, source)
        except OSError:
            await trio.sleep(0.2)
            continue

        async def drain(stream=stream) -> None:
            try:
                while await stream.receive_some(65536):
                    pass
            except (trio.BrokenResourceError, OSError):
                pass

        try:
            async with trio.open_nursery() as n:
                n.start_soon(drain)
                while not stop.is_set():
                    batch = []
                    for _ in range(64):
                        b = bytearray(good[int(rng.integers(0, len(good)))])
                        for _ in range(int(rng.integers(1, 4))):
                            b[int(rng.integers(0, len(b) - 1))] = int(rng.integers(0, 256))
                        batch.append(bytes(b))
                    data = b"".join(batch)
                    await stream.send_all(data)
                    c.fuzz_frames += len(batch)
                    c.fuzz_bytes += len(data)
                n.cancel_scope.cancel()
        except* (trio.BrokenResourceError, OSError, trio.ClosedResourceError):
            c.fuzz_closed += 1
        await stream.aclose()


async def _rover(port: int, c: Counters, stop: trio.Event) -> None:
    """h1: stays connected, a frame with seq every 0.2 s, each ack timed."""
    stream = await _connect(port, LEGIT_SOURCE)
    await stream.send_all(_hello("h1", "hider", TOKENS["h1"]))
    sent: dict[int, float] = {}
    buf = b""

    async def reader() -> None:
        nonlocal buf
        while True:
            data = await stream.receive_some(65536)
            if not data:
                return
            buf += data
            *lines, buf = buf.split(b"\n")
            for ln in lines:
                f = decode_line(ln)
                if f.ack is not None:
                    for s in [s for s in sent if s <= f.ack]:
                        c.ack_ms.append((time.perf_counter() - sent.pop(s)) * 1000)

    try:
        async with trio.open_nursery() as n:
            n.start_soon(reader)
            await trio.sleep(0.5)
            seq = 0
            while not stop.is_set():
                seq += 1
                sent[seq] = time.perf_counter()
                await stream.send_all(encode_frame(Frame("status", "status",
                                                         {"state": "bench"}, seq=seq)))
                await trio.sleep(0.2)
            await trio.sleep(1.0)
            n.cancel_scope.cancel()
    except* (trio.BrokenResourceError, OSError):
        c.rover_closed = True  # the server closed the attached rover's link
    c.unacked = len(sent)
    await stream.aclose()


async def _reconnecting_rover(port: int, c: Counters, stop: trio.Event) -> None:
    """s1: connect, hello, time the welcome; once a second."""
    while not stop.is_set():
        t0 = time.perf_counter()
        try:
            stream = await _connect(port, LEGIT_SOURCE)
            await stream.send_all(_hello("s1", "seeker", TOKENS["s1"]))
            got = b""
            with trio.move_on_after(5) as timer:
                while b'"welcome"' not in got:
                    data = await stream.receive_some(65536)
                    if not data:
                        break
                    got += data
            if b'"welcome"' in got and not timer.cancelled_caught:
                c.welcome_ms.append((time.perf_counter() - t0) * 1000)
            else:
                c.no_welcome += 1
            await stream.aclose()
        except (OSError, trio.BrokenResourceError):
            c.no_welcome += 1
        await trio.sleep(max(0.0, 1.0 - (time.perf_counter() - t0)))


def _stats(ms: list[float]) -> dict:
    if not ms:
        return {"n": 0}
    q = sorted(ms)
    return {"n": len(q), "median_ms": round(statistics.median(q), 2),
            "p95_ms": round(q[int(0.95 * (len(q) - 1))], 2), "max_ms": round(q[-1], 2)}


QUIET_S = 5.0
"""Seconds the legit rovers are timed alone before the attack starts."""


async def _legit(port: int, seconds: float) -> dict:
    """The legit rovers, in their own process: alone for `QUIET_S`, then under attack."""
    quiet, c = Counters(), Counters()
    q_stop, stop = trio.Event(), trio.Event()
    async with trio.open_nursery() as n:
        n.start_soon(_reconnecting_rover, port, quiet, q_stop)
        await trio.sleep(QUIET_S)
        q_stop.set()
    async with trio.open_nursery() as n:
        n.start_soon(_rover, port, c, stop)
        n.start_soon(_reconnecting_rover, port, c, stop)
        await trio.sleep(seconds)
        stop.set()
    return {"quiet_hello_to_welcome": _stats(quiet.welcome_ms),
            "hello_to_welcome": {**_stats(c.welcome_ms), "unanswered": c.no_welcome},
            "ack_latency": {**_stats(c.ack_ms), "unacked_at_end": c.unacked,
                            "link_closed_by_server": c.rover_closed}}


async def _fuzz(port: int, seconds: float) -> dict:
    """The fuzzer, in its own process, from 127.0.0.3."""
    c, stop = Counters(), trio.Event()
    t0 = time.perf_counter()
    async with trio.open_nursery() as n:
        n.start_soon(_fuzzer, port, c, stop, 1, FUZZ_SOURCE)
        await trio.sleep(seconds)
        stop.set()
        n.cancel_scope.cancel()
    wall = time.perf_counter() - t0
    return {"fuzzer": {"frames_per_s": round(c.fuzz_frames / wall), "frames": c.fuzz_frames,
                       "connections_closed_by_server": c.fuzz_closed}}


async def _attack(port: int, pid: int, args: argparse.Namespace) -> dict:
    c = Counters()
    stop = trio.Event()
    rss_before = _rss_mb(pid)
    cpu0, own0 = _cpu_s(pid), time.process_time()
    t0 = time.perf_counter()
    async with trio.open_nursery() as n:
        for k in range(args.connections):
            source = f"127.1.{k % args.sources // 256}.{k % args.sources % 256 + 1}" \
                if args.sources > 1 else None
            n.start_soon(_holder, port, c, stop, source)
            if k % 100 == 99:
                await trio.sleep(0.05)
        for _ in range(50):
            n.start_soon(_slowloris, port, c, stop)
        await trio.sleep(args.seconds - (time.perf_counter() - t0))
        held = c.open_now
        stop.set()
        with trio.move_on_after(5):
            while c.open_now:
                await trio.sleep(0.1)
        n.cancel_scope.cancel()
    wall = time.perf_counter() - t0
    cpu = {"server": round((_cpu_s(pid) - cpu0) / wall, 2),
           "attackers": round((time.process_time() - own0) / wall, 2)}
    await trio.sleep(2)
    return {"server_rss_mb": {"before": round(rss_before, 1), "after": round(_rss_mb(pid), 1)},
            "holders": {"tried": args.connections, "sources": args.sources,
                        "server_max_connections": args.max_connections,
                        "connections_opened": c.opened, "open_at_end": held,
                        "open_max_client_side": c.open_max,
                        "connect_failed": c.connect_failed},
            "slowloris_closed": c.slow_closed, "attack_s": round(wall, 1),
            "cpu_share_of_one_core": cpu}


def _counted(lines: list[str]) -> dict[str, int]:
    """What the server's log says it refused: first events plus summaries, by kind."""
    out: dict[str, int] = {}
    for kind in ("bad_frame", "auth_failed", "conn_closed"):
        first = sum(1 for ln in lines if re.search(rf"\s{kind}\s", ln))
        summed = sum(int(m.group(1)) for ln in lines
                     if (m := re.search(rf"\s{kind}_summary\s.*\bcount=(\d+)", ln)))
        out[kind] = first + summed
    return out


def _part(part: str, port: int, seconds: float) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "benchmarks.hostile", "--part", part,
                             "--port", str(port), "--seconds", str(seconds)],
                            stdout=subprocess.PIPE, text=True,
                            cwd=pathlib.Path(__file__).resolve().parent.parent)


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.hostile")
    parser.add_argument("--connections", type=int, default=2000)
    parser.add_argument("--seconds", type=float, default=30.0)
    parser.add_argument("--sources", type=int, default=1,
                        help="loopback addresses the holders come from (127.1.x.y); 1: all "
                             "from 127.0.0.1 (default %(default)s)")
    parser.add_argument("--max-connections", type=int, default=64,
                        help="the server's --max-connections (default %(default)s)")
    parser.add_argument("--part", choices=("legit", "fuzz"), help=argparse.SUPPRESS)
    parser.add_argument("--port", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    if args.part:  # the legit rovers' or the fuzzer's own process
        part = _legit if args.part == "legit" else _fuzz
        print(json.dumps(trio.run(part, args.port, args.seconds)))
        return 0
    if not 1 <= args.connections <= 5000 or not 5 <= args.seconds <= 300 \
            or not 1 <= args.sources <= 4096:
        parser.error("--connections must be 1..5000, --seconds 5..300, --sources 1..4096")
    port = _free_port()
    with tempfile.TemporaryDirectory() as tmp:
        db = os.path.join(tmp, "hostile.db")
        cmd = [sys.executable, "-m", "tui.cli", "serve", "--db", db, "--listen",
               f"tcp:127.0.0.1:{port}", "--rover", "h1=tcp", "--rover", "s1=tcp",
               "--no-console", "--max-connections", str(args.max_connections)] + [
                   f"--token={k}={v}" for k, v in TOKENS.items()]
        log = open(os.path.join(tmp, "serve.log"), "w")
        server = subprocess.Popen(cmd, stdout=log, stderr=subprocess.STDOUT,
                                  cwd=pathlib.Path(__file__).resolve().parent.parent)
        try:
            deadline = time.time() + 30
            while time.time() < deadline:
                with socket.socket() as s:
                    if s.connect_ex(("127.0.0.1", port)) == 0:
                        break
                time.sleep(0.2)
            db_before, rows_before = _db_use(db)
            parts = [_part("legit", port, args.seconds)]
            time.sleep(QUIET_S + 0.5)
            parts.append(_part("fuzz", port, args.seconds))
            result = trio.run(_attack, port, server.pid, args)
            for proc in parts:
                out, _ = proc.communicate(timeout=60)
                result.update(json.loads(out.strip().splitlines()[-1]))
            db_after, rows_after = _db_use(db)
            result["db"] = {"bytes_before": db_before, "bytes_after": db_after,
                            "event_rows_added": rows_after - rows_before}
            result["server_alive"] = server.poll() is None
        finally:
            server.terminate()
            server.wait(10)
            log.close()
        lines = pathlib.Path(tmp, "serve.log").read_text().splitlines()
        result["server_log_lines"] = len(lines)
        result["server_tracebacks"] = sum("Traceback" in ln for ln in lines)
        result["server_counted"] = _counted(lines)
    print(json.dumps(result, indent=2))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
