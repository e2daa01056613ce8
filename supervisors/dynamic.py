"""A dynamic supervisor: many children of one spec, started on demand (OTP's
``simple_one_for_one``, Elixir's ``DynamicSupervisor``).

::

    spec = DynamicSupervisorSpec(ChildSpec("session", Session, restart="transient"),
                                 max_children=64)
    sessions = await system.start_supervisor(spec, "sessions")
    name = await sessions.start_child(rover_id, id=rover_id)   # Session(rover_id)
    await sessions.terminate_child(rover_id)

It starts with no children. ``start_child(*args, id=None, **kwargs)`` starts a
child from the template: ``template.start(*args, **kwargs)`` makes it, and it
registers as ``<supervisor>/<id>`` (``id`` defaults to ``<template id>-<n>``, n
counting from 1). Everything else is the `Supervisor` contract with strategy
``one_for_one``: restart types, intensity, backoff, significant children and
auto-shutdown, names and calls. What differs, as in OTP:

* ``max_children`` bounds the children running or restarting: one more
  ``start_child`` raises `ChildError` (``max_children``);
* a child that ends and is not restarted, or is terminated, is dropped
  (its spec is not kept); ``restart_child`` and ``delete_child`` raise
  `ChildError` (``not_supported``);
* children start in call order and stop in reverse order.
"""

from __future__ import annotations

import dataclasses
import functools
from dataclasses import dataclass
from typing import Any

from actors import ActorSystem

from .spec import (
    AutoShutdown,
    Backoff,
    ChildError,
    ChildSpec,
    Strategy,
    _enum,
    check_options,
    check_significant,
)
from .supervisor import Supervisor

__all__ = ["DynamicSupervisorSpec", "DynamicSupervisor"]


@dataclass(frozen=True, slots=True)
class DynamicSupervisorSpec:
    """The template of a dynamic supervisor's children, its bound and its options.

    Raises:
        ValueError: ``max_children`` < 1, or an option out of range (as `SupervisorSpec`).
        TypeError: ``child`` is not a `ChildSpec`.
    """

    child: ChildSpec  #: the template; ``start`` receives ``start_child``'s arguments
    max_children: int | None = None  #: None: unbounded
    intensity: int = 3  #: MaxR: restarts allowed within ``period``
    period: float = 5.0  #: MaxT [s]
    backoff: Backoff | None = None
    auto_shutdown: AutoShutdown = AutoShutdown.NEVER

    def __post_init__(self) -> None:
        if not isinstance(self.child, ChildSpec):
            raise TypeError(f"child must be a ChildSpec, got {self.child!r}")
        if self.max_children is not None and (
                isinstance(self.max_children, bool) or not isinstance(self.max_children, int)
                or self.max_children < 1):
            raise ValueError(f"max_children must be an int >= 1 or None, "
                             f"got {self.max_children!r}")
        object.__setattr__(self, "auto_shutdown",
                           _enum(AutoShutdown, "auto_shutdown", self.auto_shutdown))
        check_options(self.intensity, self.period)
        check_significant([self.child], self.auto_shutdown)

    @property
    def children(self) -> tuple[ChildSpec, ...]:
        """None at start: children come from `DynamicSupervisor.start_child`."""
        return ()

    @property
    def strategy(self) -> Strategy:
        """Always ``one_for_one``."""
        return Strategy.ONE_FOR_ONE

    def build(self, system: ActorSystem, name: str) -> DynamicSupervisor:
        """A dynamic supervisor for this spec registered under ``name`` (runtime use)."""
        return DynamicSupervisor(self, system, name)


class DynamicSupervisor(Supervisor):
    """A running dynamic supervisor (made by `DynamicSupervisorSpec.build`)."""

    _keeps_ended = False  # ended children are dropped, as in simple_one_for_one

    def __init__(self, spec: DynamicSupervisorSpec, system: ActorSystem, name: str) -> None:
        super().__init__(spec, system, name)
        self._made = 0  # children made so far (default ids)

    async def start_child(self, *args: Any, id: str | None = None,  # noqa: A002 - OTP's word
                          **kwargs: Any) -> str | None:
        """Start one more child: ``template.start(*args, **kwargs)`` under ``id``.

        Returns:
            Its registered name, or None when its start returned `IGNORE`.

        Raises:
            ChildError: ``max_children``, ``already_started`` (the id is taken),
                ``stopped``, or the start failure's `ExitReason`.
            ValueError: ``id`` is empty or contains ``/``.
        """
        template: ChildSpec = self.spec.child
        start = functools.partial(template.start, *args, **kwargs) if args or kwargs \
            else template.start
        async with self._serial:
            self._check_open(id or template.id)
            bound = self.spec.max_children
            if bound is not None and len(self._children) >= bound:
                raise ChildError(self.name, "max_children", id or template.id)
            if id is None:
                self._made += 1
                while f"{template.id}-{self._made}" in self._children:
                    self._made += 1
                child_id = f"{template.id}-{self._made}"
            else:
                child_id = id
            spec = dataclasses.replace(template, id=child_id, start=start)
            self._admit(spec)
            return await self._add(spec)

    async def restart_child(self, child_id: str) -> str | None:
        """Not supported by a dynamic supervisor (OTP: ``simple_one_for_one``).

        Raises:
            ChildError: always, reason ``not_supported``.
        """
        raise ChildError(self.name, "not_supported", child_id)

    async def delete_child(self, child_id: str) -> None:
        """Not supported by a dynamic supervisor (OTP: ``simple_one_for_one``).

        Raises:
            ChildError: always, reason ``not_supported``.
        """
        raise ChildError(self.name, "not_supported", child_id)
