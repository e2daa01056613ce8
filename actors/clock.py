"""The three clocks of a run, all read through ``trio.current_time()``.

* `real_clock`: Trio's default clock (returns None, Trio's default).
* `scaled_clock`: real time times a factor (``MockClock(rate=N)``), for the
  console; `set_rate` changes the factor while running.
* `virtual_clock`: time jumps ahead whenever every task is idle
  (``MockClock(autojump_threshold=0)``): headless runs and tests, a whole game
  in seconds, repeatable for a seed.

Nothing in the project reads the wall clock; a headless run is simply
``trio.run(main, clock=virtual_clock())``.
"""

from __future__ import annotations

import math

import trio
from trio.lowlevel import Abort, checkpoint, current_task, reschedule, wait_task_rescheduled
from trio.testing import MockClock

try:  # Trio's internal run context: the autojump's shortcut (see `virtual_clock`)
    from trio._core._run import GLOBAL_RUN_CONTEXT
except ImportError:  # pragma: no cover - another Trio: its own autojump is used
    GLOBAL_RUN_CONTEXT = None

__all__ = ["real_clock", "scaled_clock", "virtual_clock", "set_rate", "set_rate_soon", "sleep",
           "sleep_until"]


def real_clock() -> None:
    """Trio's default clock: pass the result as ``trio.run(..., clock=real_clock())``."""
    return None


def virtual_clock() -> MockClock:
    """A clock that jumps to the next deadline as soon as all tasks are blocked.

    It is Trio's `MockClock` with two shortcuts on the hot path, same values (Trio's
    class cannot be subclassed, so the instance gets them). Why: Trio reads the clock
    several times per scheduler round and per sleep, and a `MockClock` reads the real
    clock each time only to multiply the elapsed real time by its rate, 0 here; and
    its jump to the next deadline built Trio's whole run statistics (together about
    2 % of a game). While the rate is 0 the time is the virtual base; the jump reads
    the next deadline from the runner as ``current_statistics`` does (Trio's own
    path when that internal is missing). A rate set later (the console) goes through
    Trio's code as before.
    """
    clock = MockClock(autojump_threshold=0)
    trio_time = clock.current_time
    trio_jump = clock._autojump  # noqa: SLF001 - Trio's own path, the fallback

    def current_time() -> float:
        if clock._rate == 0.0:  # noqa: SLF001
            return clock._virtual_base  # noqa: SLF001 - what Trio's formula gives at rate 0
        return trio_time()

    def autojump() -> None:
        try:
            deadlines = GLOBAL_RUN_CONTEXT.runner.deadlines
        except AttributeError:
            trio_jump()
            return
        jump = deadlines.next_deadline() - current_time()
        if 0 < jump < math.inf:
            clock.jump(jump)

    clock.current_time = current_time  # type: ignore[method-assign]
    clock._autojump = autojump  # type: ignore[method-assign]  # noqa: SLF001
    return clock


def _check_rate(rate: float) -> float:
    if isinstance(rate, bool) or not isinstance(rate, (int, float)):
        raise TypeError(f"rate must be a number, got {rate!r}")
    if not rate > 0 or rate == float("inf"):
        raise ValueError(f"rate must be a finite number > 0, got {rate!r}")
    return float(rate)


def scaled_clock(rate: float) -> MockClock:
    """A clock running ``rate`` times faster than real time (``rate`` > 0).

    Raises:
        ValueError: ``rate`` is not a finite number > 0.
    """
    return MockClock(rate=_check_rate(rate))


def set_rate(clock: MockClock, rate: float) -> None:
    """Change a scaled clock's factor; call from inside Trio (a task or ``run_sync_soon``).

    Trio computes its next sleep from the clock each scheduler round, so the
    change takes effect at once when made from inside the run. Made from
    outside (another thread, a UI loop), a sleeping Trio would not notice:
    use `set_rate_soon` there.

    Raises:
        ValueError: ``rate`` is not a finite number > 0.
    """
    clock.rate = _check_rate(rate)


def set_rate_soon(token: trio.lowlevel.TrioToken, clock: MockClock, rate: float) -> None:
    """Change a scaled clock's factor from outside Trio, waking the run to notice.

    Raises:
        ValueError: ``rate`` is not a finite number > 0 (raised here, not in Trio).
    """
    rate = _check_rate(rate)
    token.run_sync_soon(set_rate, clock, rate)


async def sleep_until(deadline: float) -> None:
    """`trio.sleep_until` with the same wake-ups, cheaper: the deadline wakes the task
    instead of raising and catching ``Cancelled``.

    Why: every timer tick and world step is a sleep; Trio's sleep is a cancel scope
    whose expiry builds a ``Cancelled`` exception and throws it through the sleeping
    coroutine. Here the scope's abort function, when its own deadline fired,
    reschedules the task with a plain value at that same moment (so the same
    scheduler batch, the same game) and the scope exits normally. A cancellation from
    outside (a timer cancelled, an actor killed) still raises ``Cancelled`` as before.

    Raises:
        ValueError: ``deadline`` is NaN.
    """
    if deadline != deadline:
        raise ValueError("deadline must not be NaN")
    task = current_task()
    with trio.CancelScope(deadline=deadline) as scope:
        def abort(_raise_cancel: object) -> Abort:
            if scope.cancel_called:  # our deadline (maybe an outer cancel too: as Trio)
                reschedule(task)
                return Abort.FAILED
            return Abort.SUCCEEDED  # only an outer scope: raise Cancelled
        await wait_task_rescheduled(abort)


async def sleep(seconds: float) -> None:
    """`trio.sleep` built on `sleep_until` (0 is a checkpoint, as in Trio).

    Raises:
        ValueError: ``seconds`` is negative or NaN.
    """
    if not seconds >= 0:
        raise ValueError("`seconds` must be non-negative")
    if seconds == 0:
        await checkpoint()
    else:
        await sleep_until(trio.current_time() + seconds)
