"""Mailbox and supervisor speed against raw Trio, measured in one run.

Run as ``python -m benchmarks.mailbox [--quick]``. Figures (best of a few
repeats, real clock, one process):

* cast throughput: one actor casting N messages to another, against a naive
  awaited trio memory channel moving N messages between two tasks (ratio,
  target >= 3);
* cast CPU: the CPU time of the same casts against a batched trio channel whose
  producer uses ``send_nowait`` (awaiting only when full) and whose consumer
  drains with ``receive_nowait`` and awaits one handler per message (ratio,
  target <= 1.5);
* call round trip: ``system.call`` to an echo actor, against a raw trio
  ping-pong over two memory channels (ratio, target <= 1.2);
* fan-in: 10 sender tasks casting to one actor [messages/s];
* restart latency: median time from a crash to the restarted actor handling
  its next message (target <= 150 us), and the same for a minimal hand-written
  Trio supervisor (a task that restarts a channel-reading worker task in a
  nursery when it raises), as a ratio.

Ratios compare figures of this one run: on a shared machine only they are
stable, not the absolute figures.

The last line printed is one JSON object with every figure.
"""

from __future__ import annotations

import argparse
import json
import statistics
import time

import trio
import trio.testing

from actors import Actor, open_actor_system
from supervisors import ChildSpec, SupervisorSpec

DEPTH = 1024  # mailbox / channel depth used for both sides of the comparison


class Sink(Actor):
    """Counts messages; sets an event at the expected count."""

    def __init__(self, expected: int, done: trio.Event) -> None:
        self.expected = expected
        self.done = done
        self.count = 0

    async def handle(self, message: object) -> None:
        self.count += 1
        if self.count == self.expected:
            self.done.set()


class Echo(Actor):
    async def handle(self, message: object) -> object:
        return message


class Caster(Actor):
    """Casts ``n`` messages to ``target`` when it gets ``go``."""

    def __init__(self, target: str, n: int) -> None:
        self.target, self.n = target, n

    async def handle(self, message: object) -> None:
        cast = self.ctx.system.cast
        for i in range(self.n):
            await cast(self.target, i)


class Crashy(Actor):
    """Crashes on "crash"; records when it handles "probe"."""

    def __init__(self, seen: list[float]) -> None:
        self.seen = seen

    async def handle(self, message: object) -> None:
        if message == "crash":
            raise RuntimeError("benchmark crash")
        self.seen.append(time.perf_counter())


def best(fn, repeats: int) -> float:
    return min(trio.run(fn) for _ in range(repeats))




# ---------------------------------------------------------------------- baselines
async def naive_channel(n: int) -> float:
    send, receive = trio.open_memory_channel(DEPTH)

    async def producer() -> None:
        for i in range(n):
            await send.send(i)

    async def consumer() -> None:
        for _ in range(n):
            await receive.receive()

    t0 = time.perf_counter()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(producer)
        nursery.start_soon(consumer)
    return time.perf_counter() - t0


async def batched_channel(n: int, clock=time.perf_counter) -> float:
    """Producer ``send_nowait`` (awaits only when full); consumer drains what is waiting
    and awaits a handler per message: what an actor's mailbox does, by hand."""
    send, receive = trio.open_memory_channel(DEPTH)
    done = trio.Event()
    count = 0

    async def handler(message: object) -> None:
        nonlocal count
        count += 1
        if count == n:
            done.set()

    async def producer() -> None:
        for i in range(n):
            try:
                send.send_nowait(i)
            except trio.WouldBlock:
                await send.send(i)

    async def consumer() -> None:
        while count < n:
            await handler(await receive.receive())
            while True:
                try:
                    message = receive.receive_nowait()
                except trio.WouldBlock:
                    break
                await handler(message)

    t0 = clock()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(producer)
        nursery.start_soon(consumer)
        await done.wait()
    return clock() - t0


async def raw_ping_pong(n: int) -> float:
    s1, r1 = trio.open_memory_channel(0)
    s2, r2 = trio.open_memory_channel(0)

    async def server() -> None:
        async for m in r1:
            await s2.send(m)

    async with trio.open_nursery() as nursery:
        nursery.start_soon(server)
        t0 = time.perf_counter()
        for i in range(n):
            await s1.send(i)
            await r2.receive()
        elapsed = time.perf_counter() - t0
        nursery.cancel_scope.cancel()
    return elapsed


async def hand_restart_latency(rounds: int) -> list[float]:
    """A minimal hand-written supervisor: restart a worker task whenever it raises."""
    send, receive = trio.open_memory_channel(DEPTH)
    seen: list[float] = []
    latencies = []

    async def worker() -> None:
        async for message in receive:
            if message == "crash":
                raise RuntimeError("benchmark crash")
            seen.append(time.perf_counter())

    async def supervisor() -> None:
        while True:
            try:
                async with trio.open_nursery() as nursery:
                    nursery.start_soon(worker)
            except* RuntimeError:
                pass  # crashed: start it again

    async with trio.open_nursery() as nursery:
        nursery.start_soon(supervisor)
        await trio.testing.wait_all_tasks_blocked()
        for _ in range(rounds):
            before = len(seen)
            t0 = time.perf_counter()
            send.send_nowait("crash")
            send.send_nowait("probe")
            while len(seen) == before:
                await trio.sleep(0)
            latencies.append(seen[-1] - t0)
        nursery.cancel_scope.cancel()
    return latencies


# ---------------------------------------------------------------------- the runtime
async def actor_cast(n: int, clock=time.perf_counter) -> float:
    done = trio.Event()
    spec = SupervisorSpec([
        ChildSpec("sink", lambda: Sink(n, done), mailbox=DEPTH),
        ChildSpec("caster", lambda: Caster("sink", n)),
    ])
    async with open_actor_system(seed=0) as system:
        await system.start_supervisor(spec)
        t0 = clock()
        system.send_nowait("caster", "go")
        await done.wait()
        return clock() - t0


async def actor_call(n: int) -> float:
    async with open_actor_system(seed=0) as system:
        await system.start_supervisor(SupervisorSpec([ChildSpec("echo", Echo)]))
        call = system.call
        t0 = time.perf_counter()
        for i in range(n):
            await call("echo", i, timeout=10.0)
        return time.perf_counter() - t0


async def fan_in(n: int, senders: int = 10) -> float:
    done = trio.Event()
    async with open_actor_system(seed=0) as system:
        await system.start_supervisor(
            SupervisorSpec([ChildSpec("sink", lambda: Sink(n * senders, done), mailbox=DEPTH)]))

        async def sender() -> None:
            for i in range(n):
                await system.send("sink", i)

        t0 = time.perf_counter()
        async with trio.open_nursery() as nursery:
            for _ in range(senders):
                nursery.start_soon(sender)
        await done.wait()
        return time.perf_counter() - t0


async def restart_latency(rounds: int) -> list[float]:
    seen: list[float] = []
    latencies = []
    async with open_actor_system(seed=0) as system:
        await system.start_supervisor(SupervisorSpec(
            [ChildSpec("crashy", lambda: Crashy(seen))], intensity=rounds + 10, period=1.0))
        for _ in range(rounds):
            before = len(seen)
            t0 = time.perf_counter()
            system.send_nowait("crashy", "crash")
            system.send_nowait("crashy", "probe")
            while len(seen) == before:
                await trio.sleep(0)
            latencies.append(seen[-1] - t0)
    return latencies


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.mailbox", description=__doc__)
    parser.add_argument("--quick", action="store_true", help="fewer messages and repeats")
    args = parser.parse_args(argv)
    n = 20_000 if args.quick else 200_000
    calls = 5_000 if args.quick else 50_000
    repeats = 2 if args.quick else 3

    naive = best(lambda: naive_channel(n), repeats)
    cast = best(lambda: actor_cast(n), repeats)
    batched_cpu = best(lambda: batched_channel(n, time.process_time), repeats)
    cast_cpu = best(lambda: actor_cast(n, time.process_time), repeats)
    ping = best(lambda: raw_ping_pong(calls), repeats)
    rtt = best(lambda: actor_call(calls), repeats)
    fan = best(lambda: fan_in(n // 10), repeats)
    rounds = 200 if args.quick else 1000
    lat = trio.run(restart_latency, rounds)
    hand = trio.run(hand_restart_latency, rounds)
    restart_ms = statistics.median(lat) * 1e3
    hand_ms = statistics.median(hand) * 1e3

    figures = {
        "messages": n,
        "naive_channel_msgs_per_s": round(n / naive),
        "cast_msgs_per_s": round(n / cast),
        "cast_vs_naive": round(naive / cast, 2),
        "batched_channel_cpu_us_per_msg": round(batched_cpu / n * 1e6, 3),
        "cast_cpu_us_per_msg": round(cast_cpu / n * 1e6, 3),
        "cast_cpu_vs_batched": round(cast_cpu / batched_cpu, 2),
        "raw_ping_pong_us": round(ping / calls * 1e6, 2),
        "call_round_trip_us": round(rtt / calls * 1e6, 2),
        "call_vs_ping_pong": round(rtt / ping, 2),
        "fan_in_10_msgs_per_s": round(n / fan),
        "restart_median_ms": round(restart_ms, 4),
        "restart_p90_ms": round(sorted(lat)[int(len(lat) * 0.9)] * 1e3, 4),
        "hand_restart_median_ms": round(hand_ms, 4),
        "restart_vs_hand": round(restart_ms / hand_ms, 2),
    }
    rows = [
        ("naive awaited channel", f"{figures['naive_channel_msgs_per_s']:,} msg/s", "baseline"),
        ("actor cast", f"{figures['cast_msgs_per_s']:,} msg/s",
         f"{figures['cast_vs_naive']}x naive (target >= 3)"),
        ("batched channel CPU", f"{figures['batched_channel_cpu_us_per_msg']} us/msg",
         "baseline"),
        ("actor cast CPU", f"{figures['cast_cpu_us_per_msg']} us/msg",
         f"{figures['cast_cpu_vs_batched']}x batched (target <= 1.5)"),
        ("raw trio ping-pong", f"{figures['raw_ping_pong_us']} us", "baseline"),
        ("actor call round trip", f"{figures['call_round_trip_us']} us",
         f"{figures['call_vs_ping_pong']}x ping-pong (target <= 1.2)"),
        ("fan-in, 10 senders", f"{figures['fan_in_10_msgs_per_s']:,} msg/s", ""),
        ("hand supervisor restart", f"{figures['hand_restart_median_ms']} ms", "baseline"),
        ("restart latency median", f"{figures['restart_median_ms']} ms",
         f"{figures['restart_vs_hand']}x hand (target <= 0.15 ms)"),
        ("restart latency p90", f"{figures['restart_p90_ms']} ms", ""),
    ]
    print(f"{'measure':<26}{'figure':>20}  note")
    for name, fig, note in rows:
        print(f"{name:<26}{fig:>20}  {note}")
    print(json.dumps(figures))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
