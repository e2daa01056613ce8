"""The actor runtime: domain-free, imports nothing else of the project.

Layering inside the package (each module imports only those above it):

    message   Message, ValueType, BufferPool: the seed's 96-bit message
    exits     ExitReason, IGNORE: why an actor stopped (or did not start), as data
    trace     TraceEvent, Trace, JsonLinesRecorder, seed_trio_scheduler
    clock     real_clock, scaled_clock, virtual_clock, set_rate, sleep, sleep_until
    mailbox   Mailbox: bounded, survives restarts, drains in bursts
    call      CallEnvelope, CallTimeout, CallFailed, NoProc, UnknownActor
    cell      Cell, ActorState, Monitor, Down: per-name state outliving incarnations
    actor     Actor, ActorContext, Timer: what an actor is and what it may do
    watchdog  Guard: one incarnation's handling deadline
    serving   serve: the message loop of one incarnation
    incarnation  run_actor: one incarnation's life, start to stop
    system    ActorSystem, open_actor_system: registry, sending, faults, lifetime
    running   run: trio.run where Ctrl-C reaches the program, never an actor's code

Supervision lives in the ``supervisors`` package, built on these names.
"""

from .actor import MAX_TIMERS, Actor, ActorContext, InjectedCrash, Timer
from .call import CallEnvelope, CallFailed, CallTimeout, NoProc, UnknownActor
from .cell import ActorState, Cell, Down, Monitor
from .clock import (
    real_clock,
    scaled_clock,
    set_rate,
    set_rate_soon,
    sleep,
    sleep_until,
    virtual_clock,
)
from .exits import (
    AUTO_SHUTDOWN,
    HUNG,
    IGNORE,
    KILLED,
    MAX_INTENSITY,
    NOPROC,
    NORMAL,
    SHUTDOWN,
    ExitKind,
    ExitReason,
    Ignore,
)
from .incarnation import run_actor
from .mailbox import Mailbox, MailboxClosed, MailboxStatistics
from .message import BufferPool, Message, PoolExhausted, PoolStatistics, ValueType
from .system import ActorSystem, StartFailed, SupervisorHandle, open_actor_system
from .trace import (
    EventKind,
    JsonLinesRecorder,
    Subscription,
    Trace,
    TraceEvent,
    seed_trio_scheduler,
)

__all__ = [
    "AUTO_SHUTDOWN", "Actor", "ActorContext", "ActorState", "ActorSystem", "BufferPool",
    "CallEnvelope", "CallFailed", "CallTimeout", "Cell", "Down", "EventKind", "ExitKind",
    "ExitReason", "HUNG", "IGNORE", "Ignore", "InjectedCrash", "JsonLinesRecorder", "KILLED",
    "MAX_INTENSITY", "MAX_TIMERS", "Mailbox", "MailboxClosed", "MailboxStatistics", "Message",
    "Monitor", "NOPROC", "NORMAL", "NoProc", "PoolExhausted", "PoolStatistics", "SHUTDOWN",
    "StartFailed", "Subscription", "SupervisorHandle", "Timer", "Trace", "TraceEvent",
    "UnknownActor", "ValueType", "open_actor_system", "real_clock", "run_actor", "scaled_clock",
    "seed_trio_scheduler", "set_rate", "set_rate_soon", "sleep", "sleep_until", "virtual_clock",
]
