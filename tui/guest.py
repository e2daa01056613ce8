"""Trio hosted as a guest on the running asyncio loop (Textual's), in one thread.

Why guest mode: the system is a Trio program and Textual runs on asyncio.
Guest mode interleaves the two schedulers in one thread, so a Textual handler
may call synchronous Trio operations directly (``send_nowait`` on a memory
channel, ``CancelScope.cancel``) and they wake Trio even when it is idle, with
no locks and no cross-thread hops (a Trio thread instead cost 5-8 ms of UI lag,
see ``shared/notes/measured-facts.md``). Trio talks back with ``App.post_message``
or plain calls, since it is the same thread.

Trio's guest mode hands every scheduler batch back to the host loop (one
asyncio callback and one poll of asyncio's selector per batch). A simulation
at full speed runs many thousand small batches a second, and that hand-off
cost a tenth to a fifth of its speed, so `TrioGuest` runs batches that are
ready at once back to back while the host loop has nothing ready to run (a
key, a message, a callback), for up to `BURST_S` of wall time; then the host
loop gets its turn. A key is handled as soon as it arrives; a host timer may
fire up to `BURST_S` late.

What this is not: ``trio.from_thread`` must not be used from the asyncio side
(it hangs forever in guest mode); and the guest run must finish before the
asyncio loop closes, or Trio warns that the run was abandoned. `TrioGuest.stop`
is the one way to end it: cancel the root scope, then wait for the run;
`quit_on_signals` makes SIGTERM and SIGINT take that way too.
"""

from __future__ import annotations

import asyncio
import signal
import time
from collections.abc import Awaitable, Callable, Sized

import outcome
import trio

__all__ = ["TrioGuest", "quit_on_signals"]

#: How long `TrioGuest.stop` waits for a cancelled run before giving up [s, wall].
STOP_TIMEOUT_S = 5.0
#: Longest run of back-to-back Trio batches before the host loop gets a turn [s, wall].
BURST_S = 0.004


class TrioGuest:
    """One Trio run hosted on the current asyncio loop.

    Args:
        on_done: called (on the asyncio side) with the run's `outcome.Outcome`
            when it ends for any reason, including an exception in the system.
    """

    def __init__(self, on_done: Callable[[outcome.Outcome], object] | None = None) -> None:
        self._on_done = on_done
        self._scope: trio.CancelScope | None = None
        self._cancel_requested = False
        self._finished: asyncio.Future[outcome.Outcome] | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._bursting = False  # inside `_burst`: Trio's next batch joins this burst
        self._next: Callable[[], object] | None = None  # that batch
        self._host_ready: Sized | None = None  # the host loop's ready callbacks
        self._busy_s = 0.0  # wall time spent running Trio's batches [s]

    @property
    def started(self) -> bool:
        """`start` was called."""
        return self._finished is not None

    @property
    def finished(self) -> bool:
        """The guest run has ended (never true before `start`)."""
        return self._finished is not None and self._finished.done()

    @property
    def busy_s(self) -> float:
        """Wall time spent running Trio's batches so far [s]: the rest of the thread's time
        went to the host (the console's frames), or to other processes."""
        return self._busy_s

    @property
    def outcome(self) -> outcome.Outcome | None:
        """How the run ended, None while it runs."""
        return self._finished.result() if self.finished else None  # type: ignore[union-attr]

    def start(self, async_fn: Callable[..., Awaitable[object]], *args: object,
              clock: trio.abc.Clock | None = None) -> None:
        """Start ``async_fn(*args)`` as the root task of a guest Trio run.

        Must be called from a coroutine or callback of the running asyncio loop.

        Raises:
            RuntimeError: when already started, or when no asyncio loop is running.
        """
        if self._finished is not None:
            raise RuntimeError("this TrioGuest was already started")
        loop = asyncio.get_running_loop()
        self._loop = loop
        # asyncio's queue of callbacks ready to run (private; a loop without one gets
        # fixed-length bursts): a burst ends as soon as the host has work
        self._host_ready = getattr(loop, "_ready", None)
        self._finished = loop.create_future()

        async def root() -> None:
            with trio.CancelScope() as scope:
                self._scope = scope
                if self._cancel_requested:
                    scope.cancel()
                await async_fn(*args)

        trio.lowlevel.start_guest_run(
            root,
            run_sync_soon_threadsafe=loop.call_soon_threadsafe,
            run_sync_soon_not_threadsafe=self._soon,
            done_callback=self._done,
            host_uses_signal_set_wakeup_fd=True,
            clock=clock,
        )

    def cancel(self) -> None:
        """Cancel the run's root scope (synchronous; takes effect at Trio's next checkpoint)."""
        self._cancel_requested = True
        if self._scope is not None:
            self._scope.cancel()

    async def stop(self, timeout_s: float = STOP_TIMEOUT_S) -> outcome.Outcome | None:
        """Cancel the run and wait until it has finished; idempotent.

        Returns:
            The run's outcome, or None when it was never started or did not
            finish within ``timeout_s`` wall seconds.
        """
        if self._finished is None:
            return None
        self.cancel()
        try:
            return await asyncio.wait_for(asyncio.shield(self._finished), timeout_s)
        except TimeoutError:
            return None

    def _soon(self, fn: Callable[[], object]) -> None:
        """Trio's ``run_sync_soon_not_threadsafe``: it asks for its next batch here."""
        if self._bursting:
            self._next = fn
        else:
            assert self._loop is not None
            self._loop.call_soon(self._burst, fn)

    def _burst(self, fn: Callable[[], object]) -> None:
        """Run Trio batches that are ready at once while the host has nothing ready,
        for up to `BURST_S`; then let the host loop run and continue on its next turn."""
        assert self._loop is not None
        start = time.perf_counter()
        deadline = start + BURST_S
        host_ready = self._host_ready
        pending: Callable[[], object] | None = fn
        self._bursting = True
        try:
            while pending is not None:
                self._next = None
                pending()
                pending = self._next
                if pending is not None and (host_ready or time.perf_counter() >= deadline):
                    break
        except BaseException:
            pending = self._next  # never lose the batch Trio asked for
            raise
        finally:
            self._busy_s += time.perf_counter() - start
            self._bursting = False
            self._next = None
            if pending is not None:
                self._loop.call_soon(self._burst, pending)

    def _done(self, result: outcome.Outcome) -> None:
        assert self._finished is not None
        if not self._finished.done():
            self._finished.set_result(result)
        if self._on_done is not None:
            self._on_done(result)


def quit_on_signals(quit_: Callable[[], object]) -> tuple[signal.Signals, ...]:
    """SIGTERM and SIGINT quit the console as ``q`` does (the system stopped, status 0):
    handled by the asyncio loop, so neither interrupts Textual or Trio mid-step. Returns
    the signals handled (none outside the main thread, where asyncio cannot)."""
    loop = asyncio.get_running_loop()
    done = []
    for sig in (signal.SIGTERM, signal.SIGINT):
        try:
            loop.add_signal_handler(sig, quit_)
        except (NotImplementedError, RuntimeError, ValueError):
            continue
        done.append(sig)
    return tuple(done)
