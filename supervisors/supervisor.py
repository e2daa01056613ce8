"""Supervisor: Erlang/OTP ``supervisor`` semantics on Trio. This docstring is the contract.

A supervisor starts, watches and restarts an ordered list of children, each
described by a `ChildSpec`. Children are workers (an `actors.Actor` made by
``start()``) or supervisors (a `SupervisorSpec` returned by ``start()``).
Workers register as ``<supervisor name>/<child id>`` (or ``<child id>`` under
an unnamed root); the supervisor creates each worker's mailbox the first time
and keeps it across restarts, so messages sent meanwhile are not lost.

Start and stop
    Children start in spec order, each fully (its ``on_start`` done) before
    the next. A child that fails to start makes the supervisor stop the ones
    already started (reverse order) and fail its own start with the reason
    (``StartFailed`` for a root). Children stop in reverse start order.
    ``IGNORE`` returned by a child's ``start``, its spec's ``init`` hook or the
    actor's ``on_start`` (OTP's ``ignore``) is no failure: the child is kept
    (a temporary one is dropped) but not running, and its name unregistered.

Restart types (``ChildSpec.restart``)
    ``permanent``: always restarted. ``transient``: restarted only after an
    abnormal exit (anything but ``normal`` and ``shutdown``). ``temporary``:
    never restarted; forgotten (its name unregistered) when it exits.
    The exit may be the actor's own choice: ``ctx.stop()`` (``normal``),
    ``ctx.stop("shutdown")`` or ``ctx.stop("shutdown", term)`` (OTP's
    ``{shutdown, Term}``); the rules are the same.

Strategies (``SupervisorSpec.strategy``)
    ``one_for_one``: only the failed child is restarted. ``one_for_all``: the
    others are stopped (reverse order) and all are restarted in start order.
    ``rest_for_one``: the children started after the failed one are stopped
    (reverse order), then the failed one and those are restarted in order.
    A temporary child stopped this way is not restarted but forgotten. As in
    OTP, a non-temporary child that was not running is started with the others.

Intensity (``intensity`` = MaxR, ``period`` = MaxT [s])
    Every restart decision is recorded; if more than MaxR happened within the
    last MaxT seconds, the supervisor stops all its children (reverse order)
    and exits with reason ``shutdown`` (detail ``reached max restart
    intensity``, OTP's ``{shutdown, reached_max_restart_intensity}``).
    MaxR = 0 gives up at the first failure; restarts spaced wider than MaxT
    never add up. The window is the pure function `intensity_exceeded`.
    A restart whose start fails counts as another exit of that child.

Escalation
    A supervisor's exit is seen by its parent as that child exiting, and is
    handled by the parent's strategy and the child's restart type.

Auto-shutdown (``SupervisorSpec.auto_shutdown``, ``ChildSpec.significant``; OTP 24)
    ``never`` (default; significant children are refused), ``any_significant``:
    the supervisor stops its other children and exits ``shutdown`` (detail
    ``auto shutdown``) when a significant child ends by itself and is not
    restarted; ``all_significant``: when the last running significant child
    does. A significant child is transient or temporary, never permanent.
    Ending by the supervisor's hand (``terminate_child``, a sibling's
    restart, the supervisor's stop) never triggers it.

Shutdown (``ChildSpec.shutdown`` [s], None = wait forever)
    Stopping a child asks it to stop (a worker finishes its current message,
    runs ``on_stop(shutdown)``; a supervisor stops its own children first) and
    waits up to the timeout; then the child is cancelled hard and its exit
    reason is ``killed``. Supervisor children default to waiting forever.

Backoff (``SupervisorSpec.backoff``, optional)
    Before restarting, wait ``min * 2**(k-1)`` seconds capped at ``max``, times
    ``1 + jitter * u`` with ``u`` uniform in [-1, 1) drawn from the run's seeded
    generator, ``k`` being the number of restarts since the supervisor was last
    quiet for ``reset_after`` seconds.

Names and calls
    A worker's name and mailbox live across its restarts. Every exit of an
    incarnation fails the calls it held or that wait in its mailbox, with its
    exit reason (`actors.CallFailed`), in the same scheduler pass. The name is
    unregistered when the supervisor will not start the child again on its
    own: a temporary child ended, a transient one ended normally, a child was
    terminated, deleted or ignored, or the supervisor itself stopped or gave up
    (then every one of its workers). From then on ``call``, ``send`` and
    ``send_nowait`` raise `actors.NoProc` and ``cast`` returns False. The closed
    cell stays readable (``whereis``, ``names``, ``statistics``) while the
    supervisor keeps the child's spec; a dropped spec (temporary, dynamic)
    takes the name out of the registry (`actors.ActorSystem.retire`, ``forget``).

Dynamic children (serialised with restarts: one runs at a time)
    ``await start_child(spec)`` adds a child at the end and starts it (its name,
    or None when ignored; a failed start adds nothing); ``await
    terminate_child(id)`` stops it and keeps its spec (a temporary one is
    dropped); ``await restart_child(id)`` starts a kept child that is not
    running; ``await delete_child(id)`` drops the spec of a child that is not
    running; ``count_children()`` counts specs, running children, supervisors
    and workers. Errors raise `ChildError` with OTP's reason (``already_started``,
    ``already_present``, ``not_found``, ``running``, ``restarting``, a start
    failure). `supervisors.dynamic.DynamicSupervisor` runs many children of one
    spec started on demand, bounded by ``max_children``.

Introspection
    `Supervisor.which_children` lists (id, name, kind, state, restarts, last
    exit reason); a child's state is ``restarting`` from its exit until its
    restart's ``on_start`` returned (backoff included). `Supervisor.snapshot`
    gives the nested `TreeNode` records a console draws, with mailbox
    statistics for workers.

Child spec fields and defaults: ``id`` (required, unique among siblings, no
``/``), ``start`` (required, a zero-argument callable), ``restart=permanent``,
``shutdown=5.0`` for workers / None for supervisors, ``mailbox=64``,
``watchdog=None`` [s], ``type=worker``, ``significant=False``, ``init=None``
(per-incarnation hook ``init(actor)`` before ``on_start``).
Supervisor options and defaults: ``strategy=one_for_one``, ``intensity=3``,
``period=5.0`` [s], ``backoff=None``, ``auto_shutdown=never``.

The running supervisor is built in layers, one module each: `supervisors.children`
(its state, starting and stopping children), `supervisors.restart` (exits,
strategies, intensity, backoff, auto-shutdown) and, here, the supervisor itself
(its public API and its run). Specs and the pure rules are in `supervisors.spec`,
its records in `supervisors.state`.
"""

from __future__ import annotations

import trio

from actors import IGNORE, SHUTDOWN, ActorState, EventKind, ExitReason

from .restart import Restarts
from .spec import (
    AutoShutdown,
    Backoff,
    ChildCounts,
    ChildError,
    ChildInfo,
    ChildSpec,
    ChildStartError,
    ChildType,
    Restart,
    Strategy,
    SupervisorSpec,
    TreeNode,
    backoff_delay,
    check_significant,
    intensity_exceeded,
)
from .state import ChildRecord, Started

__all__ = [
    "AutoShutdown", "Backoff", "ChildCounts", "ChildError", "ChildInfo", "ChildSpec",
    "ChildStartError", "ChildType", "Restart", "Strategy", "Supervisor", "SupervisorSpec",
    "TreeNode", "backoff_delay", "intensity_exceeded",
]


class Supervisor(Restarts):
    """A running supervisor (made by `SupervisorSpec.build`; start it with
    ``ActorSystem.start_supervisor`` or as a child)."""

    # ------------------------------------------------------------------ public API
    def stop(self) -> None:
        """Ask the supervisor to stop its children (reverse order) and exit ``shutdown``."""
        self._stop_requested = True
        self._stop_event.set()
        self._wakeup.set()

    async def wait_stopped(self) -> None:
        """Wait until it has stopped."""
        await self._stopped.wait()

    def which_children(self) -> list[ChildInfo]:
        """Its children in start order: id, name, type, state, restarts, last exit."""
        return [ChildInfo(c.spec.id, c.name, c.spec.type, c.state, c.restarts, c.last_exit)
                for c in self._children.values()]

    def count_children(self) -> ChildCounts:
        """Specs known, children running, supervisors and workers (OTP's count_children)."""
        children = self._children.values()
        sups = sum(c.spec.type is ChildType.SUPERVISOR for c in children)
        active = sum(c.run is not None and not c.run.done.is_set() for c in children)
        return ChildCounts(len(self._children), active, sups, len(self._children) - sups)

    def snapshot(self) -> TreeNode:
        """The whole tree below this supervisor, for a console."""
        nodes = []
        for c in self._children.values():
            sub = c.sup.snapshot().children if c.sup is not None else ()
            stats = c.cell.mailbox.statistics() if c.cell is not None else None
            nodes.append(TreeNode(c.name, c.spec.type, c.state, c.restarts, c.last_exit,
                                  stats, sub))
        state = ActorState.STOPPED if self._stopped.is_set() else ActorState.RUNNING
        return TreeNode(self.name, ChildType.SUPERVISOR, state, 0, self.exit_reason, None,
                        tuple(nodes))

    async def start_child(self, spec: ChildSpec) -> str | None:
        """Add ``spec`` as the last child and start it (OTP's ``start_child``).

        Returns:
            The child's registered name, or None when its start returned `IGNORE`.

        Raises:
            ChildError: ``already_started`` / ``already_present`` (the id is taken,
                running or not), ``stopped`` (the supervisor is not running), or the
                start failure's `ExitReason` (nothing is added).
            ValueError: a significant child under ``auto_shutdown=never``.
        """
        if not isinstance(spec, ChildSpec):
            raise TypeError(f"spec must be a ChildSpec, got {spec!r}")
        check_significant([spec], self.spec.auto_shutdown)
        async with self._serial:
            self._check_open(spec.id)
            self._admit(spec)
            return await self._add(spec)

    async def terminate_child(self, child_id: str) -> None:
        """Stop a child (within its shutdown timeout); its spec is kept unless temporary.

        Not a failure: no restart, no intensity, no auto-shutdown.

        Raises:
            ChildError: ``not_found``, or ``stopped``.
        """
        async with self._serial:
            self._check_open(child_id)
            child = self._find(child_id)
            await self._stop_children([child])
            child.restarting = False
            self._ended(child)

    async def restart_child(self, child_id: str) -> str | None:
        """Start a kept child that is not running (OTP's ``restart_child``).

        Returns:
            Its registered name, or None when its start returned `IGNORE`.

        Raises:
            ChildError: ``not_found``, ``running``, ``restarting``, ``stopped``, or the
                start failure's `ExitReason` (the spec is kept).
        """
        async with self._serial:
            self._check_open(child_id)
            child = self._find_idle(child_id)
            started = await self._start_child(child)
            if started is IGNORE:
                self._ended(child)
                return None
            if started is not None:
                self._forget_name(child)
                raise ChildError(self.name, started, child_id)
            return child.name

    async def delete_child(self, child_id: str) -> None:
        """Drop the spec of a child that is not running (OTP's ``delete_child``).

        Raises:
            ChildError: ``not_found``, ``running``, ``restarting``, or ``stopped``.
        """
        async with self._serial:
            self._check_open(child_id)
            self._remove(self._find_idle(child_id))

    def _check_open(self, child_id: str) -> None:
        if not self._open:
            raise ChildError(self.name, "stopped", child_id)

    def _admit(self, spec: ChildSpec) -> None:
        """Refuse a new child whose id is taken."""
        existing = self._children.get(spec.id)
        if existing is not None:
            running = existing.run is not None or existing.restarting
            raise ChildError(self.name, "already_started" if running else "already_present",
                             spec.id)

    async def _add(self, spec: ChildSpec) -> str | None:
        child = ChildRecord(spec, self._child_name(spec.id))
        self._children[spec.id] = child
        started = await self._start_child(child)
        if started is IGNORE:
            self._ended(child)
            return None
        if started is not None:
            self._remove(child)
            raise ChildError(self.name, started, spec.id)
        return child.name

    def _find(self, child_id: str) -> ChildRecord:
        child = self._children.get(child_id)
        if child is None:
            raise ChildError(self.name, "not_found", child_id)
        return child

    def _find_idle(self, child_id: str) -> ChildRecord:
        child = self._find(child_id)
        if child.restarting:
            raise ChildError(self.name, "restarting", child_id)
        if child.run is not None:
            raise ChildError(self.name, "running", child_id)
        return child

    # ------------------------------------------------------------------ start
    async def run(self, *, task_status: trio.TaskStatus[Started]
                  = trio.TASK_STATUS_IGNORED) -> ExitReason:
        """Start the children, supervise them until stopped, giving up or auto-shutdown.

        Reports ``task_status.started(None)`` when every child started, or
        ``started(reason)`` after a failed start (the started ones stopped); a
        ``KeyboardInterrupt`` or an outer cancel during the start is not a failed start
        and leaves through ``nursery.start`` as itself.

        Returns:
            ``shutdown`` when stopped, `MAX_INTENSITY` when it gave up,
            ``AUTO_SHUTDOWN`` after its significant children ended, or the start failure.
        """
        trace = self.system.trace
        reason: ExitReason = SHUTDOWN
        reported = False
        try:
            async with trio.open_nursery() as nursery:
                self._nursery = nursery
                failure = await self._start_children(list(self._children.values()))
                if failure is not None:
                    reason = failure
                    await self._stop_children(list(self._children.values()))
                    return reason
                trace.emit(EventKind.START, self.name or "<root>", detail="supervisor")
                reported = True
                self._open = True
                task_status.started(None)
                reason = await self._supervise()
                async with self._serial:
                    self._open = False
                    await self._stop_children(list(self._children.values()))
                nursery.cancel_scope.cancel()
            return reason
        except BaseException:  # Ctrl-C or an outer cancel: it leaves `nursery.start` itself
            reported = True
            raise
        finally:
            self._open = False
            self.exit_reason = reason
            for child in self._children.values():  # gone with this incarnation, for good
                self._forget_name(child, keep=self._keeps_ended)
            if not reported:
                task_status.started(reason)
            trace.emit(EventKind.STOP, self.name or "<root>", detail=str(reason))
            self._stopped.set()
