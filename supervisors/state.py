"""A supervisor's records: one per child, one per running incarnation, and its lock.

Internal to `supervisors.supervisor` (the contract is there); kept apart so that
each module holds one idea.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import trio

from actors import ActorState, Cell, ExitReason, Ignore

from .spec import ChildSpec

if TYPE_CHECKING:
    from .supervisor import Supervisor

__all__ = ["Run", "ChildRecord", "Serial", "Started"]

Started = ExitReason | Ignore | None
"""What starting a child gives: None (running), `IGNORE`, or the start failure."""


class Run:
    """One running incarnation of a child."""

    __slots__ = ("child", "done", "reason", "stopping", "scope", "sup")

    def __init__(self, child: ChildRecord) -> None:
        self.child = child
        self.done = trio.Event()  # set when the incarnation's task ended
        self.reason: ExitReason | Ignore | None = None  # its exit reason, once done
        self.stopping = False  # the supervisor asked it to stop: its exit is no failure
        self.scope: trio.CancelScope | None = None  # kill switch (supervisor children)
        self.sup: Supervisor | None = None  # the nested supervisor (supervisor children)


class ChildRecord:
    """The supervisor's record of one child."""

    __slots__ = ("spec", "name", "run", "restarts", "last_exit", "cell", "sup", "restarting")

    def __init__(self, spec: ChildSpec, name: str) -> None:
        self.spec = spec
        self.name = name
        self.run: Run | None = None  # None when not running (also during its restart)
        self.restarts = 0
        self.last_exit: ExitReason | None = None
        self.cell: Cell | None = None  # workers: the latest registered cell (owns the mailbox)
        self.sup: Supervisor | None = None  # supervisors: the latest incarnation
        self.restarting = False  # from its exit until its restart's start returned

    @property
    def state(self) -> ActorState:
        if self.restarting:
            return ActorState.RESTARTING
        if self.run is not None and not self.run.done.is_set():
            if self.cell is not None:
                return self.cell.state
            return ActorState.RUNNING
        return ActorState.STOPPED


class Serial:
    """One holder at a time (restart handling, dynamic-children calls, the final stop).

    Why not `trio.Lock`: its acquire is a checkpoint even when free, one more
    scheduler pass on every restart. This one takes a free lock at once.
    """

    __slots__ = ("_held", "_lot")

    def __init__(self) -> None:
        self._held = False
        self._lot = trio.lowlevel.ParkingLot()

    async def __aenter__(self) -> None:
        while self._held:
            await self._lot.park()
        self._held = True

    async def __aexit__(self, *exc: object) -> None:
        self.release()

    def try_acquire(self) -> bool:
        """Take it if free (no waiting); True when taken."""
        if self._held:
            return False
        self._held = True
        return True

    def release(self) -> None:
        self._held = False
        self._lot.unpark()
