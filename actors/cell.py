"""The per-name record of an actor: its mailbox and state, which outlive its task.

A cell is made by the runtime for a registered name the first time its
supervisor starts it, and kept across restarts: the mailbox, the counters, the
monitors, the per-actor random generator and pending faults belong to the
cell, the `Actor` instance to one incarnation.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np
import trio

from .call import CallEnvelope, CallFailed, NoProc
from .exits import NOPROC, ExitReason
from .mailbox import Mailbox

if TYPE_CHECKING:
    from .actor import Actor

__all__ = ["ActorState", "Cell", "Down", "Monitor"]


class ActorState(enum.StrEnum):
    """Where an actor is in its life."""

    STARTING = "starting"  #: the factory or on_start is running
    RUNNING = "running"  #: handling messages
    RESTARTING = "restarting"  #: exited; its supervisor will start it again (mailbox kept)
    STOPPED = "stopped"  #: exited and not (yet) to be restarted


@dataclass(frozen=True, slots=True)
class Down:
    """A monitor's notice: the actor ``name`` exited with ``reason`` at ``time`` [s]."""

    name: str
    reason: ExitReason
    time: float


class Monitor:
    """Receives a `Down` notice every time the monitored actor exits.

    Bounded: when ``capacity`` notices are waiting, later ones are dropped and
    counted in ``dropped``. Use as a context manager or call `close`.
    """

    def __init__(self, cell: Cell, capacity: int) -> None:
        if capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {capacity!r}")
        self._cell = cell
        self._send, self._receive = trio.open_memory_channel[Down](capacity)
        self.dropped = 0

    def _notify(self, down: Down) -> None:
        try:
            self._send.send_nowait(down)
        except trio.WouldBlock:
            self.dropped += 1

    async def receive(self) -> Down:
        """Wait for the next notice."""
        return await self._receive.receive()

    def receive_nowait(self) -> Down:
        """The next notice if one waits.

        Raises:
            trio.WouldBlock: no notice is waiting.
        """
        return self._receive.receive_nowait()

    def close(self) -> None:
        """Stop monitoring (idempotent)."""
        if self in self._cell.monitors:
            self._cell.monitors.remove(self)

    def __enter__(self) -> Monitor:
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


class Cell:
    """Runtime record of one registered actor (made by `ActorSystem.ensure_cell`).

    Restart counts are not kept here: the supervisor that restarts a child
    counts them (`supervisors.supervisor.Supervisor.which_children`).
    """

    __slots__ = ("name", "mailbox", "state", "last_exit", "monitors", "rng",
                 "actor", "crash_pending", "hang_pending", "stop_requested", "watchdog",
                 "current", "supervisor", "scope")

    def __init__(self, name: str, mailbox: Mailbox, rng: np.random.Generator) -> None:
        self.name = name
        self.mailbox = mailbox
        self.state = ActorState.STOPPED
        self.last_exit: ExitReason | None = None
        self.monitors: list[Monitor] = []
        self.rng = rng
        self.actor: Actor | None = None  # None when no incarnation is running
        self.crash_pending = False  # inject_crash: the next handling raises
        self.hang_pending = 0.0  # inject_hang: the next handling blocks this long [s]
        self.stop_requested = False  # graceful stop asked by the supervisor
        self.watchdog: float | None = None  # handling deadline per message [s]
        self.current: Any = None  # the message (or burst) being handled, for poison reports
        self.supervisor = ""  # the owning supervisor's name, for reports
        self.scope: trio.CancelScope | None = None  # the running incarnation's kill switch

    @property
    def closed(self) -> bool:
        """True once the name is unregistered (`ActorSystem.retire` or ``forget``)."""
        return self.mailbox.closed

    def fail_calls(self, reason: ExitReason) -> int:
        """Fail the calls waiting in the mailbox with ``reason`` (their callers raise
        `CallFailed`, or `NoProc` for ``noproc``) and take them out; returns how many.

        Called when the incarnation that would have answered them exits, and when the
        name is unregistered: a call is tied to its callee's life, as in OTP.
        """
        calls = self.mailbox.take_all(CallEnvelope)
        for envelope in calls:
            envelope.fail(NoProc(self.name) if reason is NOPROC
                          else CallFailed(self.name, reason))
        return len(calls)

    def notify_down(self, reason: ExitReason) -> None:
        """Deliver a `Down` notice to every monitor."""
        down = Down(self.name, reason, trio.current_time())
        for monitor in tuple(self.monitors):
            monitor._notify(down)

    def __repr__(self) -> str:
        return (f"<Cell {self.name!r} {self.state.value} "
                f"last_exit={self.last_exit}>")
