"""Request/reply between tasks and actors: the envelope and its errors.

``await system.call(name, request, timeout=...)`` puts a `CallEnvelope` in the
actor's mailbox and parks the caller. The actor's ``handle(request)`` return
value is the reply. The call is tied to the callee's life, as OTP's
``gen_server:call``:

* when the timeout passes first, the envelope is marked abandoned and the
  caller gets `CallTimeout`; a reply made later never reaches it (it is
  dropped and traced as ``late_reply``);
* when the callee exits while handling the call or while the call waits in its
  mailbox (crash, hang, killed, shutdown, its own stop), the caller gets
  `CallFailed` with the exit reason at once, in the same scheduler pass;
* when the name is not registered, or is unregistered while the call waits,
  the caller gets `NoProc` (a `CallFailed` with reason ``noproc`` that is also
  an `UnknownActor`).

Why the timeout is an entry in Trio's deadline heap and not a cancel scope:
entering and leaving a ``move_on_after`` scope was most of a call's cost. The
envelope itself sits in the heap (as `actors.clock.sleep_until`'s alarms do);
when its deadline is due, Trio's expiry pass calls `CallEnvelope._cancel`,
which wakes the caller with `CallTimeout` at the moment the scope would have
cancelled it. A reply takes the entry out of the heap.
"""

from __future__ import annotations

import math
from typing import Any

import outcome
import trio

from .clock import HeapEntry
from .exits import NOPROC

__all__ = ["CallEnvelope", "CallTimeout", "CallFailed", "NoProc", "UnknownActor"]


class UnknownActor(LookupError):
    """Raised when a name is not registered in the actor system."""


class CallTimeout(TimeoutError):
    """Raised by ``call`` when no reply came within the timeout."""


class CallFailed(RuntimeError):
    """Raised by ``call`` when the callee exited while holding or queueing the request.

    Attributes:
        reason: the callee's `ExitReason` (``noproc`` for `NoProc`).
    """

    def __init__(self, name: str, reason: Any) -> None:
        super().__init__(f"actor {name!r} exited while handling the call: {reason}")
        self.reason = reason


class NoProc(CallFailed, UnknownActor):
    """Raised by ``call``, ``send`` and ``send_nowait`` when no actor is registered
    under the name, or it was unregistered (gone for good) while the call waited.

    Both a `CallFailed` (reason ``noproc``) and an `UnknownActor`.
    """

    def __init__(self, name: str) -> None:
        RuntimeError.__init__(self, f"no actor registered as {name!r} (noproc)")
        self.reason = NOPROC


class CallEnvelope(HeapEntry):
    """A request waiting in a mailbox, with the parked caller to wake.

    Made by `ActorSystem.call`; an actor never sees it (its ``handle`` gets the
    request).
    """

    __slots__ = ("request", "task", "abandoned", "answered", "callee", "timeout")

    def __init__(self, request: Any, callee: str = "", timeout: float = math.inf,
                 deadlines: Any = None) -> None:
        self._registered_deadline = math.inf
        self._deadlines = deadlines  # Trio's heap, or None: the caller's own scope times out
        self.request = request
        self.task = trio.lowlevel.current_task()
        self.abandoned = False  # the caller gave up (timeout or cancel)
        self.answered = False  # a reply or failure was delivered
        self.callee = callee
        self.timeout = timeout

    def _abort(self, raise_cancel: Any) -> trio.lowlevel.Abort:
        if self._registered_deadline != math.inf:
            self._leave()
        self.abandoned = True
        return trio.lowlevel.Abort.SUCCEEDED

    def _cancel(self, reason: Any) -> None:
        """The deadline is due (called by Trio's `Deadlines.expire`): time the call out."""
        self._leave()
        if not (self.abandoned or self.answered):
            self.abandoned = True
            trio.lowlevel.reschedule(self.task, outcome.Error(CallTimeout(
                f"no reply from {self.callee!r} within {self.timeout} s")))

    async def wait(self, deadline: float = math.inf) -> Any:
        """Park the caller until the reply, a failure or ``deadline`` (runtime use).

        Raises:
            CallTimeout: ``deadline`` passed (only with Trio's heap, see the module).
        """
        if deadline != math.inf and self._deadlines is not None:
            self._enter(deadline)
        return await trio.lowlevel.wait_task_rescheduled(self._abort)

    def reply(self, value: Any) -> bool:
        """Wake the caller with ``value``; False when it already gave up."""
        if self.abandoned or self.answered:
            return False
        self.answered = True
        if self._registered_deadline != math.inf:
            self._leave()
        trio.lowlevel.reschedule(self.task, outcome.Value(value))
        return True

    def fail(self, exc: BaseException) -> bool:
        """Wake the caller with ``exc`` raised; False when it already gave up."""
        if self.abandoned or self.answered:
            return False
        self.answered = True
        if self._registered_deadline != math.inf:
            self._leave()
        trio.lowlevel.reschedule(self.task, outcome.Error(exc))
        return True

    def __repr__(self) -> str:
        return f"call({self.request!r})"
