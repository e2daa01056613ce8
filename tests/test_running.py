"""`actors.running.run`: Ctrl-C reaches the program at the main task's checkpoint, never
inside an actor's code, where it would be taken for the actor's failure or lost."""

from __future__ import annotations

import signal

import pytest
import trio

from actors import Actor, open_actor_system, running, virtual_clock
from supervisors import ChildSpec, SupervisorSpec
from tui.stopping import is_interrupt, leaves


class Signalled(Actor):
    """Ctrl-C arrives in the middle of its handler (the signal raised by the handler)."""

    def __init__(self, log: list[str]) -> None:
        self.log = log

    async def handle(self, message):
        signal.raise_signal(signal.SIGINT)
        self.log.append("handled")  # where a plain trio.run raises the interrupt
        return message


async def _game(log: list[str]) -> None:
    async with open_actor_system() as system:
        await system.start_supervisor(SupervisorSpec([ChildSpec("a", lambda: Signalled(log))]))
        system.send_nowait("a", "go")
        await trio.sleep_forever()


def test_ctrl_c_in_an_actor_handler_stops_the_program_after_the_handler() -> None:
    """The handler runs to its end; the interrupt leaves ``run`` as a stop."""
    log: list[str] = []
    with pytest.raises(BaseException) as info:  # noqa: PT011 - the interrupt, in groups
        running.run(_game, log, clock=virtual_clock())
    assert is_interrupt(info.value), leaves(info.value)
    assert log == ["handled"]


def test_plain_trio_run_raises_ctrl_c_inside_the_handler() -> None:
    """What `run` is for: Trio's default raises the interrupt in the actor's code."""
    log: list[str] = []
    with pytest.raises(BaseException) as info:  # noqa: PT011
        trio.run(_game, log, clock=virtual_clock())
    assert is_interrupt(info.value), leaves(info.value)
    assert log == []
