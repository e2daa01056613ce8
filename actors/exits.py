"""Why an actor or supervisor stopped: exit reasons as data, not prose.

Follows Erlang/OTP: ``normal`` and ``shutdown`` are the expected exits (a
``transient`` child is not restarted after them); everything else is abnormal.
A supervisor that gives up (restart intensity reached) exits with ``shutdown``
carrying the detail ``reached max restart intensity``, exactly as OTP's
``{shutdown, reached_max_restart_intensity}``; its parent restarts it if its
restart type says so (``permanent``).
"""

from __future__ import annotations

import enum
from dataclasses import dataclass

__all__ = ["ExitKind", "ExitReason", "NORMAL", "SHUTDOWN", "KILLED", "HUNG", "MAX_INTENSITY"]


class ExitKind(enum.StrEnum):
    """The kind of an exit."""

    NORMAL = "normal"  #: the actor finished on its own (``handle`` asked to stop)
    SHUTDOWN = "shutdown"  #: stopped on request by its supervisor, or gave up (supervisor)
    KILLED = "killed"  #: did not stop within its shutdown timeout and was cancelled hard
    HUNG = "hung"  #: spent longer than its watchdog deadline on one message
    CRASH = "crash"  #: an exception escaped ``handle``/``on_start``/``on_stop``
    START_FAILED = "start_failed"  #: its start (factory or ``on_start``) failed


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
