"""Faults into an attached rover: over the protocol to its devices and actors, or on its link.

Two paths, one operator call (`RoverFaults.rover_fault`):

* target ``link``: a link fault (`server.link_faults`) the server applies to
  the rover's frames in both directions, whatever the firmware;
* any other target (``lidar``, ``nav`` ...): a ``fault`` frame (reliable) to
  the rover, which answers ``fault_reply`` (accepted, unsupported or
  refused); the reply comes back as a ``fault_reply`` event.

The link side is applied by `server.connections` through `_link_in` and
`_link_out`; with no fault active they hand the lines on untouched.
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import trio

from .core import ServerCore
from .link_faults import LINK_FAULTS, LINK_TARGET, LinkFaultBook
from .peers import Conn, Rover
from .protocol import FAULT, OutboxFull, make_frame

__all__ = ["RoverFaults"]

_DELAYED_MAX = 1024  # frames held for a latency fault per direction at most [frames]


class RoverFaults(ServerCore):
    """Fault injection into attached rovers (see the module docstring)."""

    def rover_fault_catalogue(self, rover_id: str) -> tuple[str, ...]:
        """``TARGET/KIND`` faults an attached rover takes: its advertised ones, then the
        link's; empty for a simulated rover (the world breaks those)."""
        rover = self._rovers.get(rover_id)
        if rover is None or rover.conn is None or rover.conn.trusted:
            return ()
        return rover.faults + tuple(f"{LINK_TARGET}/{k}" for k in LINK_FAULTS)

    def link_faults_of(self, rover_id: str) -> list[Any]:
        """The link faults in force on a rover's link (`LinkFault` records)."""
        rover = self._rovers.get(rover_id)
        return rover.link_faults.active() if rover is not None and rover.link_faults else []

    def rover_fault(self, rover_id: str, op: str, target: str, kind: str,
                    duration_s: float = 0.0, params: dict[str, float] | None = None) -> str:
        """Inject (``op="inject"``) or clear (``"clear"``, kind ``*`` = all) a fault on an
        attached rover (``rover_id``: its id, or the role it plays); returns a line saying
        what was done.

        Raises:
            ValueError: no such attached rover, a bad kind or parameter, or the
                rover's outbox is full.
        """
        rover = self._rovers.get(rover_id) or self._rovers.get(self._role.get(rover_id, ""))
        if rover is None or rover.conn is None:
            raise ValueError(f"no attached rover {rover_id!r}")
        if rover.conn.trusted:
            raise ValueError(f"{rover_id!r} is simulated here: its faults go to the world")
        if op not in ("inject", "clear"):
            raise ValueError(f"op must be inject or clear, got {op!r}")
        now = trio.current_time()
        params = dict(params or {})
        if target == LINK_TARGET:
            return self._link_fault(rover, op, kind, duration_s, params, now)
        self._fault_ids += 1
        data: dict[str, Any] = {"fault_id": self._fault_ids, "op": op, "target": target,
                                "kind": kind}
        if duration_s:
            data["duration"] = float(duration_s)
        if params:
            data["params"] = params
        try:
            rover.session.send(make_frame(FAULT, data))
        except OutboxFull as exc:
            raise ValueError(str(exc)) from None
        self._flush(rover)
        self._persist(rover)
        self._emit("fault_sent", rover.id, {"fault_id": self._fault_ids, "op": op,
                                            "target": target, "kind": kind,
                                            "duration_s": duration_s, **params})
        return f"fault {self._fault_ids} sent to {rover_id}: {op} {target} {kind}"

    def _link_fault(self, rover: Rover, op: str, kind: str, duration_s: float,
                    params: dict[str, float], now: float) -> str:
        if op == "clear":
            gone = rover.link_faults.clear(kind) if rover.link_faults else []
            for f in gone:
                self._emit("link_fault_cleared", rover.id, {"kind": f.kind, "reason": "cleared"})
            return f"{len(gone)} link fault(s) cleared on {rover.id}"
        if rover.link_faults is None:
            self._link_seeds += 1
            rover.link_faults = LinkFaultBook(self.config.seed * 1000 + self._link_seeds)
        fault = rover.link_faults.add(kind, now, duration_s, params)
        self._emit("link_fault", rover.id, {"id": fault.id, "kind": kind,
                                            "duration_s": duration_s, **fault.params})
        self._kick.set()
        return f"link fault {kind} on {rover.id}" + (f" for {duration_s:g} s" if duration_s
                                                      else " until cleared")

    def _expire_link_faults(self, now: float) -> float:
        """Clear link faults whose time is up; returns when the next one ends [s]."""
        nxt = float("inf")
        for rover in self._rovers.values():
            book = rover.link_faults
            if not book:
                continue
            for f in book.expire(now):
                self._emit("link_fault_cleared", rover.id, {"kind": f.kind, "reason": "expired"})
            for f in book.active():
                if f.duration_s > 0:
                    nxt = min(nxt, f.start_s + f.duration_s)
        return nxt

    def _book_of(self, conn: Conn) -> LinkFaultBook | None:
        """The link faults striking ``conn``: its rover's, or (before hello) those of the
        rover last bound to a link of that name."""
        rover = conn.rover
        if rover is None:
            rover = next((r for r in self._rovers.values()
                          if r.link_faults and r.last_link == conn.link), None)
        return rover.link_faults if rover is not None and rover.link_faults else None

    def _link_in(self, conn: Conn, lines: Iterable[Any], handle: Any) -> list[Any]:
        """Lines received on ``conn`` after its link faults; delayed ones go to ``handle``
        later (a latency fault)."""
        book = self._book_of(conn)
        if book is None:
            return lines
        lines = book.apply([x for x in lines if isinstance(x, bytes)])  # too-long marks go too
        delay = book.latency()
        if delay > 0 and lines:
            if len(conn.delayed) < _DELAYED_MAX:
                conn.delayed.append(lines)
                self._nursery.start_soon(self._later, delay, conn, handle)
            else:
                book.dropped += len(lines)
            return []
        return lines

    async def _later(self, delay: float, conn: Conn, handle: Any) -> None:
        await trio.sleep(delay)
        lines = conn.delayed.popleft() if conn.delayed else []
        if conn.close_reason is None and lines:
            handle(conn, lines)

    def _link_out(self, conn: Conn, data: bytes) -> tuple[bytes, float]:
        """Bytes to send on ``conn`` after its link faults, and their added delay [s]."""
        book = self._book_of(conn)
        if book is None:
            return data, 0.0
        lines = book.apply([line + b"\n" for line in data.split(b"\n")[:-1]])
        return b"".join(lines), book.latency()
