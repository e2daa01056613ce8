"""How every command stops on Ctrl-C, SIGINT and SIGTERM: one line, exit status 0.

`install` makes SIGTERM raise SIGINT, so both signals reach a command as
Python's ``KeyboardInterrupt``. Every command runs Trio through
`actors.running.run`, which delivers that exception to the main task at its
next checkpoint (never inside an actor's code, where it could be taken for a
failure or lost); it travels out through every nursery on its way, and Trio's
nurseries wrap what leaves them in a ``BaseExceptionGroup`` (strict exception
groups), so what reaches the command line is a group holding the interrupt (and
the ``Cancelled`` of tasks stopped beside it), never a bare ``KeyboardInterrupt``.
`is_interrupt` tells such a stop from a failure; the command line
(`tui.cli.main`) uses it once for every command and prints `stopped_line`. The
work below (a game's store and recording, a server's database) closes on the
way out, as the exception passes through its ``with`` blocks and ``finally``
clauses.

The Textual consoles (``play``, ``replay``) handle both signals in their asyncio
loop instead (`tui.guest.quit_on_signals`): the console quits as ``q`` does.
"""

from __future__ import annotations

import signal
import sys

__all__ = ["install", "is_interrupt", "leaves", "stopped_line"]


def install() -> None:
    """SIGTERM stops a command as Ctrl-C does: SIGINT is raised in its place.

    A shell starts background jobs with SIGINT ignored; Python's handler is put
    back, so both signals stop the command there too.
    """
    if signal.getsignal(signal.SIGINT) is signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    if signal.getsignal(signal.SIGTERM) is signal.SIG_DFL:
        signal.signal(signal.SIGTERM, lambda _sig, _frame: signal.raise_signal(signal.SIGINT))


def leaves(exc: BaseException) -> list[BaseException]:
    """The exceptions inside (nested) exception groups; ``[exc]`` for a plain one."""
    if isinstance(exc, BaseExceptionGroup):
        return [leaf for e in exc.exceptions for leaf in leaves(e)]
    return [exc]


def is_interrupt(exc: BaseException) -> bool:
    """Whether ``exc`` is a stop by signal: a ``KeyboardInterrupt``, or a group holding at
    least one and otherwise only Trio's ``Cancelled`` (tasks stopped beside it)."""
    trio = sys.modules.get("trio")  # not imported by this process: no Cancelled to meet
    stops = (KeyboardInterrupt, trio.Cancelled) if trio is not None else (KeyboardInterrupt,)
    found = leaves(exc)
    return any(isinstance(e, KeyboardInterrupt) for e in found) and all(
        isinstance(e, stops) for e in found)


def stopped_line(command: str) -> str:
    """The one line a command stopped by a signal prints (on standard error)."""
    return f"hideseek {command}: stopped"
