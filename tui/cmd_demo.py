"""``hideseek demo``: a small supervised actor tree under injected faults, printed as it recovers.

The tree (names as registered)::

    demo                      one_for_one, MaxR 10 in 5 s
    ├── sensor                worker: a timer posts a reading every 0.1 s to filter
    └── pipeline              supervisor, rest_for_one, restart backoff 0.05..0.4 s
        ├── pipeline/filter   worker, watchdog 0.5 s: smooths readings, forwards to sink
        └── pipeline/sink     worker, mailbox 16: slow consumer (10 ms per message)

Fault schedule (simulated seconds): crash the filter at 1 s, hang it for 2 s at
2 s (its watchdog restarts it as ``hung``), flood the sink with 100 messages at
3 s (most are dropped: its mailbox holds 16), crash the sensor at 4 s.
"""

from __future__ import annotations

import argparse
import sys
from typing import Any

import trio

from actors import (
    Actor,
    EventKind,
    JsonLinesRecorder,
    TraceEvent,
    open_actor_system,
    running,
    scaled_clock,
    seed_trio_scheduler,
    virtual_clock,
)
from supervisors import Backoff, ChildSpec, ChildType, Strategy, SupervisorSpec, TreeNode
from tui import args as args_

#: events printed as they happen (per-message events are not subscribed)
SHOWN = {EventKind.CRASH, EventKind.POISON, EventKind.HUNG, EventKind.KILLED, EventKind.RESTART,
         EventKind.ESCALATE, EventKind.FAULT, EventKind.STOP}


class Sensor(Actor):
    """Posts a noisy reading to the filter every 0.1 s."""

    async def on_start(self) -> None:
        self.ctx.start_timer(0.1, "tick", interval=0.1)

    async def handle(self, message: Any) -> None:
        self.ctx.send_nowait("pipeline/filter", float(20.0 + self.ctx.rng.normal(0.0, 0.5)))


class Filter(Actor):
    """Exponential smoothing of readings; forwards the smoothed value to the sink."""

    async def on_start(self) -> None:
        self.level: float | None = None

    async def handle(self, message: Any) -> None:
        x = float(message)
        self.level = x if self.level is None else 0.8 * self.level + 0.2 * x
        self.ctx.send_nowait("pipeline/sink", round(self.level, 3))


class Sink(Actor):
    """A slow consumer: 10 ms per message."""

    async def on_start(self) -> None:
        self.count = 0

    async def handle(self, message: Any) -> None:
        await trio.sleep(0.01)
        self.count += 1


def tree_spec() -> SupervisorSpec:
    pipeline = SupervisorSpec(
        [ChildSpec("filter", Filter, watchdog=0.5), ChildSpec("sink", Sink, mailbox=16)],
        strategy=Strategy.REST_FOR_ONE, intensity=5, period=5.0,
        backoff=Backoff(min=0.05, max=0.4, jitter=0.2, reset_after=2.0))
    return SupervisorSpec(
        [ChildSpec("sensor", Sensor),
         ChildSpec("pipeline", lambda: pipeline, type=ChildType.SUPERVISOR)],
        strategy=Strategy.ONE_FOR_ONE, intensity=10, period=5.0)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--seed", type=args_.seed, default=1, help="run seed (default 1)")
    parser.add_argument("--clock", choices=("virtual", "scaled"), default="scaled",
                        help="virtual: as fast as possible; scaled: --rate x real time")
    parser.add_argument("--rate", type=float, default=4.0,
                        help="speed factor of the scaled clock (default 4)")
    parser.add_argument("--duration", type=float, default=6.0,
                        help="simulated seconds to run (default 6, at least 5)")
    parser.add_argument("--trace-out", metavar="FILE",
                        help="also record every lifecycle event as JSON lines")


def _line(event: TraceEvent) -> str:
    what = event.detail
    if event.kind == EventKind.POISON:
        what = f"dropped {event.message} ({event.detail})"
    return f"[{event.time:7.3f} s] {event.kind.value:<9} {event.actor or '-':<17} {what}"


def _tree_lines(node: TreeNode, indent: str = "") -> list[str]:
    lines = []
    for child in node.children:
        box = child.mailbox
        mb = (f"mailbox {box.depth}/{box.capacity} sent {box.sent} dropped {box.dropped}"
              if box else "")
        last = str(child.last_exit) if child.last_exit else "-"
        lines.append(f"  {indent}{child.name:<{22 - len(indent)}} {child.state.value:<9} "
                     f"restarts {child.restarts:<3} last exit {last:<38} {mb}")
        lines += _tree_lines(child, indent + "  ")
    return lines


async def _demo(args: argparse.Namespace, out: Any, recorder_stream: Any) -> int:
    async with open_actor_system(seed=args.seed) as system:
        system.trace.subscribe(lambda e: print(_line(e), file=out) if e.kind in SHOWN else None)
        if recorder_stream is not None:
            system.trace.subscribe(JsonLinesRecorder(recorder_stream))
        root = await system.start_supervisor(tree_spec(), "")
        schedule = [
            (1.0, "crash pipeline/filter", lambda: system.inject_crash("pipeline/filter")),
            (2.0, "hang pipeline/filter for 2 s", lambda: system.inject_hang("pipeline/filter", 2)),
            (3.0, "flood pipeline/sink with 100",
             lambda: f"accepted {system.flood('pipeline/sink', 100, 0.0)}, the rest dropped"),
            (4.0, "crash sensor", lambda: system.inject_crash("sensor")),
        ]
        start = trio.current_time()
        for at, what, fault in schedule:
            await trio.sleep_until(start + at)
            print(f"--- fault: {what}", file=out)
            note = fault()
            if note:
                print(f"    {note}", file=out)
        await trio.sleep_until(start + args.duration)
        print("--- tree at the end:", file=out)
        for line in _tree_lines(root.snapshot()):
            print(line, file=out)
        sink = system.whereis("pipeline/sink").actor
        print(f"--- sink (this incarnation) handled {sink.count if sink else '?'} messages; "
              f"{system.trace.count} lifecycle events", file=out)
        digest = system.trace.hexdigest()
    note = ("virtual clock: same seed, same hash" if args.clock == "virtual"
            else "scaled clock: real-time jitter changes it; use --clock virtual to compare")
    print(f"--- trace hash {digest} ({note})", file=out)
    return 0


def run(args: argparse.Namespace, out: Any = None) -> int:
    """Run the demo; returns the exit status (0 on success, 2 on bad arguments)."""
    out = out or sys.stdout
    if args.duration < 5.0 or args.duration > 600:
        print(f"hideseek demo: --duration must be in 5..600 s, got {args.duration}",
              file=sys.stderr)
        return 2
    if args.clock == "scaled" and not 0 < args.rate <= 1e6:
        print(f"hideseek demo: --rate must be in (0, 1e6], got {args.rate}", file=sys.stderr)
        return 2
    clock = virtual_clock() if args.clock == "virtual" else scaled_clock(args.rate)
    print(f"hideseek demo: seed {args.seed}, {args.clock} clock"
          + (f" x{args.rate:g}" if args.clock == "scaled" else ""), file=out)
    seed_trio_scheduler(args.seed)
    stream = None
    try:
        if args.trace_out:
            stream = open(args.trace_out, "w", encoding="utf-8")  # noqa: SIM115
        return running.run(_demo, args, out, stream, clock=clock)
    except OSError as exc:
        print(f"hideseek demo: cannot write trace: {exc}", file=sys.stderr)
        return 1
    finally:
        if stream is not None:
            stream.close()
