"""One simulated rover as its own process, speaking to a server over TCP or serial.

This is wiring (DESIGN.md section 1): it builds a `World` for the scenario's
room, starts ONE rover's supervision tree (`supervisors.rover.rover_tree`)
on that world's hardware, and carries the bytes of the rover's WiFly link
over a real byte stream instead of the in-memory link:

* ``tcp:HOST:PORT``: connect as a TCP client, as a WiFly module does;
* ``tcpin:HOST:PORT``: listen there; the server connects out to the rover;
* ``udpout:HOST:PORT``: send datagrams there from a connected UDP socket
  (`server.links.udp`: one frame per datagram);
* ``serial:PORT,BAUD``: any pyserial port or URL (a pty stands in for a cable); an
  unplugged port is awaited back for `SERIAL_WAIT_S` and reopened;
* ``pty``: make a pseudo-terminal pair, hold one end, report the other's path
  for the server (``hideseek serve --rover ID=serial:PATH,115200``).

Bytes flow: firmware -> WiFly link model of the world (UART speed, latency,
faults) -> `Uplink` (bounded) -> stream -> server; and back from the stream
into the link model's server side. An unreachable server or a missing port is
reported through ``report`` and retried with doubling backoff; a dropped
connection likewise. The firmware notices the silence by itself (heartbeats)
and says hello again, so a reconnect resumes the rover's reliable session.

What it is not: the rover's world is its own. The other two rovers stand at
their start poses in it and do not move, and this rover's body does not move
in the server's world. The mapper is faithful this way (the others do not
move while it maps); a remote hider is invisible to a seeker simulated
elsewhere, so its seeker reports not found. Scheduled actor faults of the
scenario are not injected here (device faults are, by the world).
"""

from __future__ import annotations

import contextlib
import functools
import random
from collections.abc import AsyncIterator, Callable
from dataclasses import dataclass
from typing import Any

import numpy as np
import trio

from actors import ActorSystem, Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.hardware import ROLES
from actors.firmware.telemetry import STREAMS_OF_ROLE, TelemetrySource
from server.links import LinkSpec, open_pty_cable, open_serial_stream_within, open_udp_stream
from server.links.spec import ROVER_LINK
from server.protocol import DEFAULT_LINK_BYTES_S, TelemetryLane
from supervisors.rover import rover_tree
from supervisors.rover_fault_port import RoverFaultPort
from world.scenario import Scenario
from world.wifly import WiflyLink
from world.world import World, run_world

__all__ = ["UPLINK_BYTES", "RETRY_S", "SERIAL_WAIT_S", "Uplink", "RemoteRover",
           "open_remote_rover", "run_remote_rover"]

UPLINK_BYTES = 16384
"""Bytes from the rover waiting for the stream at most [bytes] (beyond: dropped, counted)."""
RETRY_S = (0.5, 4.0)
"""Backoff between connection attempts: first, most [s]. It starts again from the first
after the server answered, and each wait is jittered (3/4 to all of the step, from the
rover's seeded generator), so rovers cut off together do not come back in step; the cap
keeps a restarted server waiting for an attached rover at most that long."""
_JITTER = 0.25  # share of a backoff step taken off at random
SERIAL_WAIT_S = 10.0
"""A serial port whose path is missing (unplugged) is tried this long before one
failed attempt is reported [s]."""
_READ_SIZE = 4096  # [bytes]

Report = Callable[[str], None]


class Uplink:
    """Bytes from the rover's link model waiting for the stream: bounded, never blocks.

    `put` is called by the world's tick (synchronously); overflow is dropped
    and counted, like a WiFly module's full buffer.
    """

    def __init__(self, capacity: int = UPLINK_BYTES) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1 byte, got {capacity!r}")
        self.capacity = capacity
        self.dropped = 0
        """Bytes dropped (buffer full, or no connection) so far."""
        self.connected = False
        """False drops every byte put (no server to send to)."""
        self._buf = bytearray()
        self._ready = trio.Event()

    def put(self, data: bytes) -> None:
        """Queue bytes for the server; drops what does not fit."""
        if not self.connected:
            self.dropped += len(data)
            return
        room = self.capacity - len(self._buf)
        if len(data) > room:
            self.dropped += len(data) - room
            data = data[:room]
        if data:
            self._buf += data
            self._ready.set()

    async def get(self) -> bytes:
        """Wait for bytes and take them all."""
        while not self._buf:
            await self._ready.wait()
            self._ready = trio.Event()
        data = bytes(self._buf)
        self._buf.clear()
        return data

    def clear(self) -> None:
        """Drop what is waiting (the connection went away)."""
        self.dropped += len(self._buf)
        self._buf.clear()


@dataclass
class RemoteRover:
    """A running remote rover (made by `open_remote_rover`)."""

    role: str
    link: LinkSpec
    world: World
    actors: ActorSystem
    tree: Any
    """The rover's root supervisor."""
    uplink: Uplink
    connects: int = 0
    """Connections made so far."""
    failures: int = 0
    """Failed connection attempts so far."""
    bytes_in: int = 0
    bytes_out: int = 0
    last_error: str = ""
    pty_path: str = ""
    """With ``--link pty``: the path the server must open."""
    telemetry: TelemetryLane | None = None
    """The WiFly's telemetry lane (what the server asked for, what was sent)."""
    faults: RoverFaultPort | None = None
    """Faults over the link: refused unless the rover was opened with ``accept_faults``."""

    @property
    def connected(self) -> bool:
        return self.uplink.connected


async def _open_stream(spec: LinkSpec) -> Any:
    """The byte stream of one connection attempt.

    Raises:
        OSError: the server is unreachable or the port is missing.
    """
    if spec.kind == "tcp_out":
        return await trio.open_tcp_stream(spec.host, spec.port)
    if spec.kind == "serial":  # an unplugged port is awaited back a while (a replug)
        return await open_serial_stream_within(spec.url, spec.baud, SERIAL_WAIT_S)
    if spec.kind == "udp_out":  # datagrams to the server; "connected" once it answers
        return await open_udp_stream(spec.host, spec.port)
    if spec.kind == "tcp_in":  # the rover listens; the server connects out to it
        listeners = await trio.open_tcp_listeners(spec.port, host=spec.host or None)
        try:
            return await listeners[0].accept()
        finally:
            for listener in listeners:
                await listener.aclose()
    raise OSError(f"{ROVER_LINK.option} must be {ROVER_LINK.forms}, got {spec.text!r}")


async def _pump(stream: Any, link: WiflyLink, rover: RemoteRover, on_answer: Any) -> str:
    """Move bytes both ways until the stream ends; returns why it ended. ``on_answer()`` is
    called once, when the first bytes from the server arrive (a peer is there)."""
    why = "closed by the other end"
    answered = False

    async def writer() -> None:
        while True:
            data = await rover.uplink.get()
            await stream.send_all(data)
            rover.bytes_out += len(data)

    async with trio.open_nursery() as nursery:
        nursery.start_soon(writer)
        try:
            while True:
                data = await stream.receive_some(_READ_SIZE)
                if not data:
                    break
                rover.bytes_in += len(data)
                if not answered:
                    answered = True
                    on_answer()
                link.server_write(data)
        finally:
            nursery.cancel_scope.cancel()
    return why


def _reason(exc: BaseException) -> str:
    leaf = exc
    while isinstance(leaf, BaseExceptionGroup):
        leaf = leaf.exceptions[0]
    text = getattr(leaf, "strerror", None) or str(leaf) or type(leaf).__name__
    return text.splitlines()[0]


def _answered(answered: list[bool], report: Report, text: str) -> None:
    answered.append(True)
    report(text)


async def _keep_connected(rover: RemoteRover, link: WiflyLink, report: Report,
                          retry_s: tuple[float, float], stream: Any = None,
                          rng: random.Random | None = None) -> None:
    """Connect, pump, and on any failure report and retry with doubling backoff
    (from the first step again once the server has answered; jittered by ``rng``)."""
    first, most = retry_s
    delay = first
    spec = rover.link
    rng = rng or random.Random(0)

    async def wait(step: float) -> None:
        await trio.sleep(step * (1.0 - _JITTER * rng.random()))

    wifly = f"{rover.role}/wifly"
    while True:
        if stream is None:
            try:
                stream = await _open_stream(spec)
            except (OSError, trio.BrokenResourceError) as exc:
                rover.failures += 1
                rover.last_error = _reason(exc)
                report(f"cannot connect over {spec.text}: {rover.last_error}; "
                       f"retrying in {delay:g} s")
                await wait(delay)
                delay = min(delay * 2, most)
                continue
        rover.connects += 1
        rover.uplink.connected = True
        # a new connection knows no hello yet: the WiFly says it at once, not at the end
        # of its hello backoff (the server closes a link without hello after 5 s)
        rover.actors.send_nowait(wifly, Message.uint(Cmd.WIFLY_LINK_OPEN, 0))
        where = rover.pty_path or spec.text
        answered: list[bool] = []
        try:  # "connected" once the server answers: an open port or socket is no server yet
            why = await _pump(stream, link, rover, functools.partial(
                _answered, answered, report, f"connected to {where}"))
        except (OSError, trio.BrokenResourceError, trio.ClosedResourceError,
                BaseExceptionGroup) as exc:
            if isinstance(exc, BaseExceptionGroup) and not exc.subgroup(
                    (OSError, trio.BrokenResourceError, trio.ClosedResourceError)):
                raise
            why = _reason(exc)
        finally:
            rover.uplink.connected = False
            rover.uplink.clear()
            if not rover.pty_path:
                with trio.CancelScope(shield=True), contextlib.suppress(Exception), \
                        trio.move_on_after(1):
                    await stream.aclose()
        rover.last_error = why
        if answered:
            delay = first  # the server was there: come back at once when it is again
        if rover.pty_path:
            report(f"pty {rover.pty_path}: {why}; waiting for the server")
            await wait(delay)
            continue  # the cable stays: same stream, wait for the other end again
        stream = None
        lost = "lost the server at" if answered else "no answer from"
        report(f"{lost} {spec.text}: {why}; reconnecting in {delay:g} s")
        await wait(delay)
        delay = min(delay * 2, most)


def _check_remote(role: str, link: LinkSpec, retry_s: tuple[float, float]) -> None:
    """Check `open_remote_rover`'s arguments.

    Raises:
        ValueError: an unknown role, a link kind a rover cannot use, or a backoff that is
            not ``0 < first <= most``.
    """
    if role not in ROLES:
        raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
    if link.kind not in ROVER_LINK.kinds:
        raise ValueError(f"{ROVER_LINK.option} must be {ROVER_LINK.forms}, got {link.text!r}")
    first, most = retry_s
    if not 0 < first <= most:
        raise ValueError(f"retry_s must be (first, most) with 0 < first <= most, got {retry_s!r}")


def _link_bytes_s(link: LinkSpec) -> float:
    """The rate of ``link`` for the telemetry budget [bytes/s]: a serial link's baud / 10,
    else `DEFAULT_LINK_BYTES_S`."""
    return link.baud / 10 if link.kind == "serial" and link.baud else DEFAULT_LINK_BYTES_S


@contextlib.asynccontextmanager
async def open_remote_rover(scenario: Scenario, role: str, link: LinkSpec, *, seed: int = 1,
                            rover_id: str | None = None, token: str | None = None,
                            report: Report | None = None,
                            retry_s: tuple[float, float] = RETRY_S,
                            nav_factory: Callable[..., Any] | None = None,
                            accept_faults: bool = False, telemetry: bool = True,
                            link_bytes_s: float | None = None,
                            ) -> AsyncIterator[RemoteRover]:
    """Run one simulated rover connected over ``link`` for the block.

    Args:
        scenario: the room and the rover's start pose.
        role: ``mapper``, ``hider`` or ``seeker``.
        link: where the server is (``tcp:HOST:PORT``, ``udpout:HOST:PORT``,
            ``serial:PORT,BAUD``), ``tcpin:HOST:PORT`` or ``pty``.
        seed: the world's noise and the actors' generators derive from it.
        rover_id: the id said in hello (default: the role).
        token: the hello token, when the server asks for one.
        report: called with one line of text for each connection event.
        retry_s: backoff between attempts: first, most [s].
        nav_factory: navigation factory for the tree (tests pass stand-ins).
        accept_faults: the opt-in to faults over the link (`RoverFaultPort`): without
            it every fault is refused and hello lists none.
        telemetry: offer telemetry in hello and send what the server asks for.
        link_bytes_s: the link's rate for the telemetry budget [bytes/s]; by default
            a serial link's baud / 10, else 57600 baud's.

    Raises:
        ValueError: unknown role, or a link kind a rover cannot use.
        OSError: ``pty`` and the system has no free pseudo-terminals.
    """
    _check_remote(role, link, retry_s)
    report = report or (lambda _text: None)
    cable = open_pty_cable() if link.kind == "pty" else None
    ports: list[RoverFaultPort] = []
    world = World(scenario, np.random.default_rng(seed),
                  on_event=lambda kind, target, detail: [
                      p.world_event(kind, target, detail) for p in ports])
    wifly = world.wifly_link(role)
    if link_bytes_s is None:
        link_bytes_s = _link_bytes_s(link)
    lane = TelemetryLane(link_bytes_s) if telemetry else None
    uplink = Uplink()
    wifly.on_server_receive = uplink.put
    try:
        async with open_actor_system(seed) as actors, trio.open_nursery() as nursery:
            nursery.start_soon(run_world, world)
            sources: list[TelemetrySource] = []

            def on_event(kind: str, path: str, detail: str) -> None:
                report(f"{kind} {path} {detail}".rstrip())
                for source in sources:
                    if "events" in source.lane.intervals:
                        source.event(kind, path, detail)
            port = RoverFaultPort(world, actors, role, accept=accept_faults, on_event=on_event)
            ports.append(port)
            spec = rover_tree(role, world.hardware(role), rover_id=rover_id, token=token,
                              nav_factory=nav_factory, hold_until_welcome=True,
                              telemetry=lane, streams=STREAMS_OF_ROLE[role], faults=port)
            tree = await actors.start_supervisor(spec, role)
            rover = RemoteRover(role, link, world, actors, tree, uplink,
                                pty_path=cable.path if cable else "", telemetry=lane,
                                faults=port)
            if lane is not None:
                sources.append(TelemetrySource(actors, tree, role, lane))
                nursery.start_soon(sources[0].run)
            if cable is not None:
                report(f"pty ready: give the server serial:{cable.path},115200")
            nursery.start_soon(_keep_connected, rover, wifly, report, retry_s, cable,
                               random.Random(seed))
            try:
                yield rover
            finally:
                nursery.cancel_scope.cancel()
    finally:
        if cable is not None:
            with trio.CancelScope(shield=True):
                await cable.aclose()


async def run_remote_rover(scenario: Scenario, role: str, link: LinkSpec, **kwargs: Any
                           ) -> None:
    """`open_remote_rover` until cancelled (the ``hideseek rover`` command)."""
    async with open_remote_rover(scenario, role, link, **kwargs):
        await trio.sleep_forever()
