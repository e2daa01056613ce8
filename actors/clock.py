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
from collections.abc import Callable
from typing import Any

import trio
from trio.lowlevel import Abort, checkpoint, current_task, reschedule, wait_task_rescheduled

try:  # the class `trio.testing` exports, from its own module: `trio.testing` imports
    # pytest where it is installed (0.06 CPU s of every game's start)
    from trio._core._mock_clock import MockClock
except ImportError:  # pragma: no cover - another Trio: its public name
    from trio.testing import MockClock

try:  # Trio's internal run context: shortcuts of `virtual_clock` and `sleep_until`
    from trio._core._run import GLOBAL_RUN_CONTEXT
except ImportError:  # pragma: no cover - another Trio: its own ways are used
    GLOBAL_RUN_CONTEXT = None

__all__ = ["real_clock", "scaled_clock", "virtual_clock", "set_rate", "set_rate_soon", "sleep",
           "sleep_until"]


def real_clock() -> None:
    """Trio's default clock: pass the result as ``trio.run(..., clock=real_clock())``."""
    return None


def virtual_clock() -> MockClock:
    """A clock that jumps to the next deadline as soon as all tasks are blocked.

    It is Trio's `MockClock` with three shortcuts on the hot path, same values
    (Trio's class cannot be subclassed, so the instance gets them). Why: Trio reads
    the clock several times per scheduler round and per sleep, and a `MockClock`
    reads the real clock each time only to multiply the elapsed real time by its
    rate, 0 here; it asks how long to sleep until the next deadline in every round
    with nothing to run (a method that reads the time through another); and its
    jump to the next deadline built Trio's whole run statistics (together about 2 %
    of a game). While the rate is 0 the time is the virtual base, the sleep is 0 or
    "forever" (Trio's own 999999999 s) and the jump adds to the base what
    ``MockClock.jump`` adds; the jump reads the next deadline from the runner as
    ``current_statistics`` does (Trio's own path when that internal is missing). A
    rate set later (the console) goes through Trio's own methods.
    """
    clock = MockClock(autojump_threshold=0)
    trio_time = clock.current_time
    trio_sleep_time = clock.deadline_to_sleep_time
    trio_jump = clock._autojump  # noqa: SLF001 - Trio's own path, the fallback

    def current_time() -> float:
        if clock._rate == 0.0:  # noqa: SLF001
            return clock._virtual_base  # noqa: SLF001 - what Trio's formula gives at rate 0
        return trio_time()

    def deadline_to_sleep_time(deadline: float) -> float:
        if clock._rate == 0.0:  # noqa: SLF001 - Trio's answers at rate 0
            return 0 if deadline - clock._virtual_base <= 0 else 999999999  # noqa: SLF001
        return trio_sleep_time(deadline)

    def autojump() -> None:
        try:
            deadlines = GLOBAL_RUN_CONTEXT.runner.deadlines
        except AttributeError:
            trio_jump()
            return
        jump = deadlines.next_deadline() - current_time()
        if 0 < jump < math.inf:
            clock._virtual_base += jump  # noqa: SLF001 - `MockClock.jump` for jump > 0

    clock.current_time = current_time  # type: ignore[method-assign]
    clock.deadline_to_sleep_time = deadline_to_sleep_time  # type: ignore[method-assign]
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


def deadline_heap() -> object | None:
    """Trio's heap of deadlines (`Deadlines`) of the running loop, or None where the
    shortcuts that use it are off (another Trio version).

    Guest mode (the console) uses it too: Trio wakes a sleeping guest run when a
    deadline changes because the host may change one between batches, but a sleep
    enters its deadline from inside a batch, after which Trio computes its next
    timeout anyway."""
    try:
        return GLOBAL_RUN_CONTEXT.runner.deadlines
    except AttributeError:
        return None


try:  # Trio's instrument registry, made cheaper to ask by `fast_instruments`
    from trio._core._instrumentation import Instruments as _TrioInstruments
except ImportError:  # pragma: no cover - another Trio
    _TrioInstruments = None


if _TrioInstruments is not None:
    class _DictInstruments(dict, _TrioInstruments):  # type: ignore[misc]
        """Trio's `Instruments` that is its own ``data`` dict, so that ``name in it``
        is the dict's C lookup instead of `collections.UserDict.__contains__`."""

        def __init__(self, old: Any) -> None:
            dict.__init__(self, old.data)
            self.data = self


def fast_instruments() -> None:
    """Make the running loop's "is any instrument installed for this hook?" cheap.

    Why: Trio asks it around every task step, every reschedule and every I/O wait
    (``"before_task_step" in runner.instruments``), and its registry is a
    `collections.UserDict`, whose ``in`` is a Python-level call: 1-2 % of a game.
    The replacement holds the same hooks (Trio's own methods add, remove and call
    instruments on it) and answers ``in`` from the dict itself. No effect on the
    order of events. Without Trio's internals this does nothing.
    """
    try:
        runner = GLOBAL_RUN_CONTEXT.runner
    except AttributeError:
        return
    if _TrioInstruments is not None and not isinstance(runner.instruments, _DictInstruments):
        runner.instruments = _DictInstruments(runner.instruments)


try:  # Trio's epoll I/O manager, whose empty polls `skip_idle_io_polls` leaves out
    from trio._core._io_epoll import EpollIOManager as _TrioEpoll
except ImportError:  # pragma: no cover - another Trio, or not Linux
    _TrioEpoll = None


def skip_idle_io_polls() -> None:
    """Leave out the running loop's I/O poll in a scheduler round that may not wait
    (timeout 0) while nothing can be ready: no file descriptor is waited on but the
    wake-up socket of Trio's entry queue, and that queue is empty.

    Why: Trio polls epoll once per scheduler round, about 70,000 times a headless game
    on the virtual clock (whose rounds never wait), and the poll finds nothing every
    time (about 1.5 % of a game). What could it find? Another task's socket (then it
    polls), or the entry queue's wake-up byte, which `run_sync_soon` (threads, the
    campaign's CPU guard, Ctrl-C) writes after queuing its call: the call is seen in
    the queue first, and the round polls. A round that polls or skips the poll finds
    no events and goes on alike, so the games are the same. Without Trio's epoll
    manager this does nothing; guest mode and rounds that wait poll as before.
    """
    try:
        runner = GLOBAL_RUN_CONTEXT.runner
    except AttributeError:
        return
    io = runner.io_manager
    if _TrioEpoll is None or type(io) is not _TrioEpoll:
        return  # another manager, or already done
    entry = runner.entry_queue
    queued, queued_once = entry.queue, entry.idempotent_queue
    wake_fd = entry.wakeup.wakeup_sock.fileno()
    registered = io._registered  # noqa: SLF001 - Trio's fd -> waiters, never replaced
    nothing: list[Any] = []  # epoll's "no events" (falsy: the timeout expired)

    class _SkipIdlePolls(_TrioEpoll):  # type: ignore[misc, valid-type]
        """Trio's epoll manager whose rounds that cannot wait or find anything skip
        the system call (same slots: the running manager becomes one in place)."""

        __slots__ = ()

        def get_events(self, timeout: float) -> Any:
            if timeout == 0 and not queued and not queued_once and (
                    not registered or (len(registered) == 1 and wake_fd in registered)):
                return nothing
            return _TrioEpoll.get_events(self, timeout)

    io.__class__ = _SkipIdlePolls


def time_reader() -> Callable[[], float]:
    """What ``trio.current_time()`` calls in the end: the running loop's clock's own
    ``current_time`` (same values, without Trio's two wrapper calls), or
    ``trio.current_time`` itself where Trio's internals are missing. Read it inside a
    run (the clock is the run's); for callers that read the time per message."""
    try:
        return GLOBAL_RUN_CONTEXT.runner.clock.current_time
    except AttributeError:
        return trio.current_time


class HeapEntry:
    """An entry of Trio's deadline heap that is not a cancel scope (the protocol that
    `_Alarm` and the actors' watchdog guard share).

    Trio's `Deadlines` heap holds ``(deadline, id, scope)`` and, when the deadline
    is due, calls ``scope._cancel(reason)`` if ``scope._registered_deadline`` still
    equals it (`Deadlines.expire`; `next_deadline` and the autojump read the same
    field). A subclass answers those two; ``_registered_deadline`` is ``inf`` while
    the entry is not in the heap (Trio counts the live entries when it prunes, so an
    entry leaves the heap exactly once per time it entered).
    """

    __slots__ = ("_registered_deadline", "_deadlines")

    def __init__(self, deadlines: Any) -> None:
        self._registered_deadline = math.inf
        self._deadlines = deadlines

    def _enter(self, deadline: float) -> None:
        """Put the entry into the heap at ``deadline`` (it must not be in it)."""
        self._registered_deadline = deadline
        self._deadlines.add(deadline, self)

    def _leave(self) -> None:
        """Take the entry out of the heap, if it is in it."""
        if self._registered_deadline != math.inf:
            self._deadlines.remove(self._registered_deadline, self)
            self._registered_deadline = math.inf

    def _cancel(self, reason: Any) -> None:  # pragma: no cover - subclasses answer it
        raise NotImplementedError


class _Alarm(HeapEntry):
    """A sleeping task's entry in Trio's deadline heap, in place of a cancel scope:
    its ``_cancel`` (the deadline is due) reschedules the sleeper, at the moment a
    scope's cancellation would have."""

    __slots__ = ("_task",)

    def __init__(self, task: object, deadlines: Any, deadline: float) -> None:
        # in the heap at once (what `HeapEntry._enter` does, without its two calls: an
        # alarm is made for every sleep of a game)
        self._task = task
        self._deadlines = deadlines
        self._registered_deadline = deadline
        deadlines.add(deadline, self)

    def _cancel(self, _reason: object) -> None:
        """The deadline is due (called by Trio's `Deadlines.expire`): wake the sleeper."""
        self._leave()
        reschedule(self._task)  # type: ignore[arg-type]

    def abort(self, _raise_cancel: object) -> Abort:
        """Cancelled from outside while sleeping: leave the heap, let Trio raise."""
        self._leave()
        return Abort.SUCCEEDED


def _alarm_until(deadline: float) -> _Alarm | None:
    """An alarm in the running loop's deadline heap that wakes the current task at
    ``deadline``, or None where a cancel scope must do it (another Trio, no run, or
    ``deadline`` already due). Reads Trio's run context once, and the clock itself
    instead of through ``trio.current_time()``'s two wrappers (same value)."""
    try:
        runner = GLOBAL_RUN_CONTEXT.runner
        now = runner.clock.current_time()
    except AttributeError:
        return None
    if not now < deadline < math.inf:  # due, or never: a scope (Trio keeps no infinite deadline)
        return None
    return _Alarm(GLOBAL_RUN_CONTEXT.task, runner.deadlines, deadline)


async def sleep_until(deadline: float) -> None:
    """`trio.sleep_until` with the same wake-ups, cheaper.

    Why: every timer tick and world step is a sleep (about 150 per simulated
    second in a game), and Trio's sleep is a cancel scope (made, entered, its
    deadline registered, exited) whose expiry builds a ``Cancelled`` exception and
    throws it through the sleeping coroutine. Here the sleeper puts an `_Alarm`
    into Trio's deadline heap and parks; when the deadline is due Trio's own expiry
    pass wakes it with a plain value, at the moment it would have cancelled the
    scope (so in the same scheduler batch: the same game, same trace hash). A
    cancellation from outside (a timer cancelled, an actor killed) raises
    ``Cancelled`` as before. Without Trio's internals (another Trio version) and
    for a deadline already due, a cancel scope does it, still without the
    exception when its own deadline fires.

    Raises:
        ValueError: ``deadline`` is NaN.
    """
    if deadline != deadline:
        raise ValueError("deadline must not be NaN")
    alarm = _alarm_until(deadline)
    if alarm is None:
        await _scope_sleep_until(deadline)
    else:
        await wait_task_rescheduled(alarm.abort)


async def _scope_sleep_until(deadline: float) -> None:
    """`sleep_until` with a cancel scope whose own deadline wakes the task with a value
    (its abort function reschedules it) instead of raising ``Cancelled``."""
    task = current_task()
    with trio.CancelScope(deadline=deadline) as scope:
        def abort(_raise_cancel: object) -> Abort:
            if scope.cancel_called:  # our deadline (maybe an outer cancel too: as Trio)
                reschedule(task)
                return Abort.FAILED
            return Abort.SUCCEEDED  # only an outer scope: raise Cancelled
        await wait_task_rescheduled(abort)


async def sleep(seconds: float) -> None:
    """`trio.sleep` with `sleep_until`'s wake-ups (0 is a checkpoint, as in Trio); its
    body is repeated here rather than awaited, one coroutine fewer per sleep.

    Raises:
        ValueError: ``seconds`` is negative or NaN.
    """
    if not seconds >= 0:
        raise ValueError("`seconds` must be non-negative")
    if seconds == 0:
        await checkpoint()
        return
    try:  # the run's clock read directly (`trio.current_time()` wraps it twice)
        deadline = GLOBAL_RUN_CONTEXT.runner.clock.current_time() + seconds
    except AttributeError:
        deadline = trio.current_time() + seconds  # another Trio (outside a run: raises)
    alarm = _alarm_until(deadline)
    if alarm is None:
        await _scope_sleep_until(deadline)
    else:
        await wait_task_rescheduled(alarm.abort)
