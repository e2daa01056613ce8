"""Supervision as data: child specs, supervisor options, records, and the pure rules.

The behaviour these describe is the contract in `supervisors.supervisor`'s
docstring; this module holds only what is checked when a spec is built and the
rules that need no clock (the intensity window, the backoff delay, the restart
decision).
"""

from __future__ import annotations

import enum
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from actors import ActorState, ActorSystem, ExitReason, MailboxStatistics

if TYPE_CHECKING:
    from .supervisor import Supervisor

__all__ = [
    "Restart", "Strategy", "ChildType", "AutoShutdown", "ChildSpec", "Backoff",
    "SupervisorSpec", "ChildInfo", "ChildCounts", "TreeNode", "ChildError", "ChildStartError",
    "intensity_exceeded", "backoff_delay", "should_restart",
]


class Restart(enum.StrEnum):
    """When a child is restarted."""

    PERMANENT = "permanent"
    TRANSIENT = "transient"
    TEMPORARY = "temporary"


class Strategy(enum.StrEnum):
    """Which children are restarted when one exits."""

    ONE_FOR_ONE = "one_for_one"
    ONE_FOR_ALL = "one_for_all"
    REST_FOR_ONE = "rest_for_one"


class ChildType(enum.StrEnum):
    """A child is an actor (worker) or a nested supervisor."""

    WORKER = "worker"
    SUPERVISOR = "supervisor"


class AutoShutdown(enum.StrEnum):
    """When a supervisor ends because its ``significant`` children ended (OTP 24)."""

    NEVER = "never"  #: significant children are not allowed
    ANY_SIGNIFICANT = "any_significant"  #: when any significant child ends by itself
    ALL_SIGNIFICANT = "all_significant"  #: when the last running significant child does


def _enum(cls: type[enum.StrEnum], name: str, value: Any) -> Any:
    try:
        return cls(value)
    except ValueError:
        allowed = ", ".join(m.value for m in cls)
        raise ValueError(f"{name} must be one of {allowed}, got {value!r}") from None


@dataclass(frozen=True, slots=True)
class ChildSpec:
    """How to start and supervise one child (see `supervisors.supervisor` for the rules).

    Raises:
        ValueError: a field out of its range (the message names it), or a
            ``significant`` child that is ``permanent`` (OTP's bad combination).
        TypeError: ``start`` or ``init`` is not callable.
    """

    id: str
    start: Callable[..., Any]  #: makes an Actor (worker) or a SupervisorSpec (supervisor)
    restart: Restart = Restart.PERMANENT
    shutdown: float | None = -1.0  #: [s]; None waits forever; -1 means the type's default
    mailbox: int = 64  #: mailbox depth [messages] (workers)
    watchdog: float | None = None  #: handling deadline per message [s] (workers)
    type: ChildType = ChildType.WORKER
    significant: bool = False  #: its own exit may end the supervisor (see AutoShutdown)
    init: Callable[[Any], Any] | None = None
    """Per-incarnation start hook (workers): ``init(actor)``, sync or async, runs after the
    actor's ``ctx`` is set and before its ``on_start``; raising fails the start, returning
    ``IGNORE`` ignores it. Lets a tree wire an actor to its registered name and system
    without touching the actor's class."""

    def __post_init__(self) -> None:
        if not isinstance(self.id, str) or not self.id or "/" in self.id:
            raise ValueError(f"id must be a non-empty string without '/', got {self.id!r}")
        if not callable(self.start):
            raise TypeError(f"start must be callable, got {self.start!r}")
        if self.init is not None and not callable(self.init):
            raise TypeError(f"init must be callable or None, got {self.init!r}")
        object.__setattr__(self, "restart", _enum(Restart, "restart", self.restart))
        object.__setattr__(self, "type", _enum(ChildType, "type", self.type))
        if self.shutdown == -1.0:
            default = 5.0 if self.type is ChildType.WORKER else None
            object.__setattr__(self, "shutdown", default)
        if self.shutdown is not None and not self.shutdown >= 0:
            raise ValueError(f"shutdown must be >= 0 [s] or None, got {self.shutdown!r}")
        if isinstance(self.mailbox, bool) or not isinstance(self.mailbox, int) or self.mailbox < 1:
            raise ValueError(f"mailbox must be an int >= 1, got {self.mailbox!r}")
        if self.watchdog is not None and not self.watchdog > 0:
            raise ValueError(f"watchdog must be > 0 [s] or None, got {self.watchdog!r}")
        if self.significant and self.restart is Restart.PERMANENT:
            raise ValueError(f"a significant child must be transient or temporary, "
                             f"got permanent for {self.id!r}")


@dataclass(frozen=True, slots=True)
class Backoff:
    """Restart backoff: ``min``..``max`` [s], relative ``jitter``, reset after quiet [s]."""

    min: float = 0.01
    max: float = 1.0
    jitter: float = 0.1
    reset_after: float = 10.0

    def __post_init__(self) -> None:
        if not 0 <= self.min <= self.max:
            raise ValueError(
                f"backoff needs 0 <= min <= max, got min={self.min!r} max={self.max!r}")
        if not 0 <= self.jitter < 1:
            raise ValueError(f"jitter must be in [0, 1), got {self.jitter!r}")
        if not self.reset_after > 0:
            raise ValueError(f"reset_after must be > 0 [s], got {self.reset_after!r}")


def check_options(intensity: Any, period: Any) -> None:
    """Raise ValueError for an intensity or period out of range (both supervisor kinds)."""
    if isinstance(intensity, bool) or not isinstance(intensity, int) or intensity < 0:
        raise ValueError(f"intensity must be an int >= 0, got {intensity!r}")
    if not period > 0:
        raise ValueError(f"period must be > 0 [s], got {period!r}")


@dataclass(frozen=True, slots=True)
class SupervisorSpec:
    """A supervisor's children (in start order) and options."""

    children: Sequence[ChildSpec]
    strategy: Strategy = Strategy.ONE_FOR_ONE
    intensity: int = 3  #: MaxR: restarts allowed within ``period``
    period: float = 5.0  #: MaxT [s]
    backoff: Backoff | None = None
    auto_shutdown: AutoShutdown = AutoShutdown.NEVER

    def __post_init__(self) -> None:
        object.__setattr__(self, "children", tuple(self.children))
        object.__setattr__(self, "strategy", _enum(Strategy, "strategy", self.strategy))
        object.__setattr__(self, "auto_shutdown",
                           _enum(AutoShutdown, "auto_shutdown", self.auto_shutdown))
        for c in self.children:
            if not isinstance(c, ChildSpec):
                raise TypeError(f"children must be ChildSpec, got {c!r}")
        ids = [c.id for c in self.children]
        dup = sorted({i for i in ids if ids.count(i) > 1})
        if dup:
            raise ValueError(f"child ids must be unique, got duplicates {dup}")
        check_options(self.intensity, self.period)
        check_significant(self.children, self.auto_shutdown)

    def build(self, system: ActorSystem, name: str) -> Supervisor:
        """A supervisor for this spec registered under ``name`` (runtime use)."""
        from .supervisor import Supervisor
        return Supervisor(self, system, name)


def check_significant(children: Sequence[ChildSpec], auto_shutdown: AutoShutdown) -> None:
    """Raise ValueError for a significant child under ``auto_shutdown=never`` (as OTP)."""
    if auto_shutdown is AutoShutdown.NEVER:
        bad = [c.id for c in children if c.significant]
        if bad:
            raise ValueError(f"significant children need auto_shutdown any_significant or "
                             f"all_significant, got never for {bad}")


class ChildStartError(RuntimeError):
    """A child's ``start`` returned the wrong kind of object for its ``type``."""


class ChildError(RuntimeError):
    """Raised by the dynamic-children calls of a supervisor when OTP would return an error.

    Attributes:
        reason: ``already_started``, ``already_present``, ``not_found``, ``running``,
            ``restarting``, ``max_children``, ``not_supported``, ``stopped``, or the
            `ExitReason` of a child that failed to start.
    """

    def __init__(self, supervisor: str, reason: Any, child: str = "") -> None:
        where = f"child {child!r} of " if child else ""
        super().__init__(f"{where}supervisor {supervisor or '<root>'!r}: {reason}")
        self.reason = reason


@dataclass(frozen=True, slots=True)
class ChildInfo:
    """One row of `Supervisor.which_children`."""

    id: str
    name: str  #: registered name (workers) or the nested supervisor's name
    type: ChildType
    state: ActorState
    restarts: int
    last_exit: ExitReason | None


@dataclass(frozen=True, slots=True)
class ChildCounts:
    """`Supervisor.count_children`, as OTP's ``count_children``."""

    specs: int  #: children known, running or not
    active: int  #: children running now
    supervisors: int  #: children of type supervisor, running or not
    workers: int  #: children of type worker, running or not


@dataclass(frozen=True, slots=True)
class TreeNode:
    """A supervision tree snapshot for a console (nested)."""

    name: str
    kind: ChildType
    state: ActorState
    restarts: int
    last_exit: ExitReason | None
    mailbox: MailboxStatistics | None = None  #: workers only
    children: tuple[TreeNode, ...] = ()


# ============================================================================ pure rules


def intensity_exceeded(restarts: Sequence[float], now: float, period: float,
                       max_restarts: int) -> tuple[bool, list[float]]:
    """Record a restart at ``now`` and say whether the intensity is exceeded.

    Args:
        restarts: times [s] of earlier restarts (any order).
        now: the time of this restart [s].
        period: MaxT [s]; restarts more than this long ago no longer count.
        max_restarts: MaxR.

    Returns:
        (exceeded, restart times still inside the window including ``now``).
    """
    window = [t for t in restarts if now - t <= period] + [now]  # inclusive, as OTP
    return len(window) > max_restarts, window


def backoff_delay(backoff: Backoff, consecutive: int, u: float) -> float:
    """The wait [s] before the ``consecutive``-th (1-based) restart; ``u`` in [-1, 1)."""
    base = min(backoff.max, backoff.min * 2.0 ** min(consecutive - 1, 60))
    return max(0.0, base * (1.0 + backoff.jitter * u))


def should_restart(restart: Restart, reason: ExitReason) -> bool:
    """The restart decision, one case per restart type."""
    if restart is Restart.PERMANENT:
        return True
    if restart is Restart.TRANSIENT:
        return reason.abnormal
    return False  # temporary
