"""Why an actor or supervisor stopped: exit reasons as data, not prose.

Follows Erlang/OTP: ``normal`` and ``shutdown`` are the expected exits (a
``transient`` child is not restarted after them); everything else is abnormal.
A supervisor that gives up (restart intensity reached) exits with ``shutdown``
carrying the detail ``reached max restart intensity``, exactly as OTP's
``{shutdown, reached_max_restart_intensity}``; its parent restarts it if its
restart type says so (``permanent``).

An actor chooses its own exit with ``ctx.stop()`` (``normal``),
``ctx.stop("shutdown")`` or ``ctx.stop("shutdown", term)`` (OTP's
``{shutdown, Term}``: kind ``shutdown``, the term as detail); restart types then
apply as to any other exit. ``noproc`` is not an exit of an actor but the reason
a caller gets for a name that is not (or no longer) registered, as OTP's
``{noproc, ...}``.

`IGNORE` is what a start hook returns to say "do not start this child", as an
OTP ``init/1`` returning ``ignore``: the child is not running and that is no
failure.
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["ExitKind", "ExitReason", "NORMAL", "SHUTDOWN", "KILLED", "HUNG", "MAX_INTENSITY",
           "AUTO_SHUTDOWN", "NOPROC", "IGNORE", "Ignore"]


class ExitKind(enum.StrEnum):
    """The kind of an exit."""

    NORMAL = "normal"  #: the actor finished on its own (``handle`` asked to stop)
    SHUTDOWN = "shutdown"  #: stopped on request by its supervisor, or gave up (supervisor)
    KILLED = "killed"  #: did not stop within its shutdown timeout and was cancelled hard
    HUNG = "hung"  #: spent longer than its watchdog deadline on one message
    CRASH = "crash"  #: an exception escaped ``handle``/``on_start``/``on_stop``
    START_FAILED = "start_failed"  #: its start (factory or ``on_start``) failed
    NOPROC = "noproc"  #: (callers only) no actor is registered under the name


@dataclass(frozen=True, slots=True)
class ExitReason:
    """One exit: its kind and a short detail (exception type and text for crashes)."""

    kind: ExitKind
    detail: str = ""

    @classmethod
    def crash(cls, exc: BaseException) -> ExitReason:
        """The reason for an exception that escaped an actor's code."""
        return cls(ExitKind.CRASH, f"{type(exc).__name__}: {exc}")

    @classmethod
    def start_failed(cls, why: str) -> ExitReason:
        """The reason for a child that could not be started."""
        return cls(ExitKind.START_FAILED, why)

    @classmethod
    def shutdown(cls, term: object = None) -> ExitReason:
        """``shutdown``, or OTP's ``{shutdown, term}`` with the term as detail."""
        return cls(ExitKind.SHUTDOWN, "" if term is None else str(term))

    @property
    def abnormal(self) -> bool:
        """True unless the exit was ``normal`` or ``shutdown`` (OTP's transient rule)."""
        return self.kind not in (ExitKind.NORMAL, ExitKind.SHUTDOWN)

    def __str__(self) -> str:
        return f"{self.kind.value}({self.detail})" if self.detail else self.kind.value


NORMAL = ExitReason(ExitKind.NORMAL)
SHUTDOWN = ExitReason(ExitKind.SHUTDOWN)
KILLED = ExitReason(ExitKind.KILLED)
HUNG = ExitReason(ExitKind.HUNG)
MAX_INTENSITY = ExitReason(ExitKind.SHUTDOWN, "reached max restart intensity")
AUTO_SHUTDOWN = ExitReason(ExitKind.SHUTDOWN, "auto shutdown")
NOPROC = ExitReason(ExitKind.NOPROC)


class Ignore:
    """The type of `IGNORE` (one instance)."""

    __slots__ = ()

    def __repr__(self) -> str:
        return "IGNORE"


IGNORE = Ignore()
"""Returned by a child's ``start``, its spec's ``init`` hook or an actor's ``on_start``:
do not start this child (OTP's ``ignore``)."""
