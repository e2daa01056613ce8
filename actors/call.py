"""Request/reply between tasks and actors: the envelope and its errors.

``await system.call(name, request, timeout=...)`` puts a `CallEnvelope` in the
actor's mailbox and parks the caller. The actor's ``handle(request)`` return
value is the reply. When the timeout passes first, the envelope is marked
abandoned and the caller gets `CallTimeout`; a reply made later never reaches
it (it is dropped and traced as ``late_reply``). When the actor fails while
handling the call, the caller gets `CallFailed` at once instead of waiting.
"""

from __future__ import annotations

from typing import Any

import outcome
import trio

__all__ = ["CallEnvelope", "CallTimeout", "CallFailed", "UnknownActor"]


class UnknownActor(LookupError):
    """Raised when a name is not registered in the actor system."""


class CallTimeout(TimeoutError):
    """Raised by ``call`` when no reply came within the timeout."""


class CallFailed(RuntimeError):
    """Raised by ``call`` when the actor exited while handling the request.

    Attributes:
        reason: the actor's `ExitReason`.
    """

    def __init__(self, name: str, reason: Any) -> None:
        super().__init__(f"actor {name!r} exited while handling the call: {reason}")
        self.reason = reason


class CallEnvelope:
    """A request waiting in a mailbox, with the parked caller to wake."""

    __slots__ = ("request", "task", "abandoned", "answered")

    def __init__(self, request: Any) -> None:
        self.request = request
        self.task = trio.lowlevel.current_task()
        self.abandoned = False  # the caller gave up (timeout or cancel)
        self.answered = False  # a reply or failure was delivered

    def _abort(self, raise_cancel: Any) -> trio.lowlevel.Abort:
        self.abandoned = True
        return trio.lowlevel.Abort.SUCCEEDED

    async def wait(self) -> Any:
        """Park the caller until the reply (runtime use)."""
        return await trio.lowlevel.wait_task_rescheduled(self._abort)

    def reply(self, value: Any) -> bool:
        """Wake the caller with ``value``; False when it already gave up."""
        if self.abandoned or self.answered:
            return False
        self.answered = True
        trio.lowlevel.reschedule(self.task, outcome.Value(value))
        return True

    def fail(self, exc: BaseException) -> bool:
        """Wake the caller with ``exc`` raised; False when it already gave up."""
        if self.abandoned or self.answered:
            return False
        self.answered = True
        trio.lowlevel.reschedule(self.task, outcome.Error(exc))
        return True

    def __repr__(self) -> str:
        return f"call({self.request!r})"
