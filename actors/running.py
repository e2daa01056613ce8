"""`run`: ``trio.run`` for a program of actors, where Ctrl-C reaches the program, not an actor.

By default Trio raises ``KeyboardInterrupt`` wherever the signal finds the program,
and in an actor system that is nearly always inside some actor's code. There it
does harm three ways: it can be taken for the actor's own failure (an actor that
was starting is reported as failed to start, and the program ends with that error
instead of stopping); it can be lost (raised inside a weak-reference callback or
a finaliser, Python prints "Exception ignored" and the program goes on); and it
leaves the actor's state half-updated for the cleanup that runs next.

`run` asks Trio to deliver it to the main task at a checkpoint instead
(``restrict_keyboard_interrupt_to_checkpoints``): the main task's wait is
aborted with ``KeyboardInterrupt``, which leaves through its nurseries and
cancels every actor at a checkpoint of its own, as any cancellation does. The
program sees what Trio gives for Ctrl-C otherwise (the interrupt, in exception
groups, beside ``Cancelled``); what does not survive is an interrupt of
synchronous code that never reaches a checkpoint (it waits for one).
"""

from __future__ import annotations

from collections.abc import Awaitable, Callable
from typing import Any, TypeVar

import trio

__all__ = ["run"]

T = TypeVar("T")


def run(main: Callable[..., Awaitable[T]], *args: Any, clock: trio.abc.Clock | None = None
        ) -> T:
    """``trio.run(main, *args, clock=clock)``, Ctrl-C delivered at the main task's checkpoint."""
    return trio.run(main, *args, clock=clock, restrict_keyboard_interrupt_to_checkpoints=True)
