"""Invariants every campaign game must keep, and the probes that observe them.

A fault campaign (`supervisors.harness.campaign`) plays many seeded games under
faults and checks, in each, what must hold whatever went wrong:

* **liveness**: the game ended (found, or not found after its guesses)
  within its simulated-time budget; no firmware actor is left dead; no
  supervisor gave up (escalated) because of a single fault;
* **no loss**: every reliable frame (one with ``seq``) a rover put on the
  air reached the server's game logic exactly once; the map the server
  stored equals the last map the mapper put on the air (assembled from the
  chunks as they left the rover, before any link fault);
* **honesty**: no firmware or server object holds a reference into the
  world other than the rover's own hardware interface and the calibration
  record it was built with (the import rules of tests/test_layers.py,
  asserted on the live objects; a firmware actor keeping the frozen
  `Scenario`, the room's ground truth, is caught);
* **truth**: a game that ended ``found`` found the hider: when the seeker's
  ``found`` report reached the server, a healthy IR sensor would have seen
  the hider (ground truth, `world.World.hider_in_ir_view`);
* **determinism**: the same game played twice gives the same trace hash.

Each broken invariant is a `Violation` whose ``name`` says which
(``liveness.ended``, ``no_loss.lost`` ...), so a failure list reads as a
diagnosis. The checks are pure functions of what the probes recorded, so
they are tested without running a game.

The probes are taps, like a logic analyser on the rover's UART: they see
copies of bytes and calls and change nothing (they never await, so a
tapped run keeps its trace hash). `DeliveryProbe` decodes the bytes each
rover writes to its WiFly link and observes what the server delivers to its
game logic through `server.Server.observe_frames`. `install_passage_counter`
is a metric, not an invariant: it counts the rovers' trips through narrow
passages, which campaigns report.
"""

from __future__ import annotations

import json
import sys
import types
from collections import Counter
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from actors import ActorState, EventKind, Trace, TraceEvent
from server.protocol import (
    MAP,
    TOO_LONG,
    Frame,
    FrameError,
    LineBuffer,
    MapAssembler,
    MapError,
    decode_line,
    read_data,
)
from world.params import ROLES
from world.passages import PassageCounter, narrow_passages

__all__ = [
    "Violation", "Delivery", "DeliveryProbe", "TraceCounts", "check_ended", "check_actors_alive",
    "check_no_escalation", "check_exactly_once", "check_maps_equal", "check_honesty",
    "check_module_honesty", "check_determinism", "install_passage_counter", "UNRELIABLE_CMDS",
]

#: frames that are re-sent by design on every (re)connection: not subject to no-loss
UNRELIABLE_CMDS = frozenset({"hello", "ack", "heartbeat"})
#: at most this many keys are listed in a violation's detail
_LIST_MAX = 5
#: objects visited at most by the honesty walk, per root
_WALK_MAX = 20_000


@dataclass(frozen=True, slots=True)
class Violation:
    """One broken invariant: ``name`` says which (``liveness.ended`` ...), ``detail`` how."""

    name: str
    detail: str

    def __str__(self) -> str:
        return f"{self.name}: {self.detail}"


# ---------------------------------------------------------------------------- probes

def _frame_key(frame: Frame) -> str:
    """Identity of a reliable frame: sender's seq plus content (a rebooted rover reuses seqs)."""
    data = json.dumps(frame.data, sort_keys=True, separators=(",", ":"), default=repr)
    return f"{frame.seq}|{frame.cmd}|{data}"


@dataclass(frozen=True, slots=True)
class Delivery:
    """What one rover sent reliably and what the server delivered, by frame key."""

    due: set[str]
    """Keys first sent early enough that they must have been delivered by now."""
    sent: set[str]
    """Every key the rover sent (late ones included)."""
    delivered: Counter
    """Key -> times the server's game logic got it."""


@dataclass
class _RoleTap:
    lines: LineBuffer = field(default_factory=LineBuffer)
    first_sent: dict[str, float] = field(default_factory=dict)
    """key -> simulated time the rover first wrote it [s]."""
    delivered: Counter = field(default_factory=Counter)
    """key -> times the server's game logic got it."""
    assembler: MapAssembler = field(default_factory=MapAssembler)
    maps: list[Any] = field(default_factory=list)
    """Maps as the rover put them on the air (assembled from first sendings), bounded."""


class DeliveryProbe:
    """Records reliable frames each rover sends and each the server delivers.

    Install with `DeliveryProbe.install(system, clock)` right after the
    system opened; ``clock`` is ``trio.current_time``.
    """

    def __init__(self, clock: Callable[[], float]) -> None:
        self._clock = clock
        self.taps: dict[str, _RoleTap] = {}
        self.unknown_rover_frames = 0
        """Frames delivered for a rover id whose role the probe could not tell."""

    @classmethod
    def install(cls, system: Any, clock: Callable[[], float],
                roles: Iterable[str] = ("mapper", "hider", "seeker")) -> DeliveryProbe:
        """Tap every rover's uplink and the server's frame handler of ``system`` (a SimSystem)."""
        probe = cls(clock)
        for role in roles:
            link = system.world.wifly_link(role)
            tap = probe.taps.setdefault(role, _RoleTap())
            link.rover_write = probe._uplink(tap, link.rover_write)
        system.server.observe_frames(probe._delivered)
        return probe

    def _uplink(self, tap: _RoleTap, write: Callable[[bytes], None]) -> Callable[[bytes], None]:
        def rover_write(data: bytes) -> None:
            self.note_sent(tap, bytes(data))
            write(data)
        return rover_write

    def _delivered(self, rover_id: str, role: str, frame: Frame) -> None:
        self.note_delivered(role, frame)

    def note_sent(self, tap: _RoleTap, data: bytes) -> None:
        """Decode bytes a rover wrote; remember each reliable frame's first sending."""
        for line in tap.lines.feed(data):
            if line is TOO_LONG:
                continue  # the server rejects it too; the rover's resend is what counts
            try:
                frame = decode_line(line)
            except FrameError:
                continue
            if frame.seq is None or frame.cmd in UNRELIABLE_CMDS:
                continue
            key = _frame_key(frame)
            if key in tap.first_sent:
                continue  # a resend
            tap.first_sent[key] = self._clock()
            if frame.cmd == MAP:
                self._map_chunk(tap, frame)

    @staticmethod
    def _map_chunk(tap: _RoleTap, frame: Frame) -> None:
        try:
            grid = tap.assembler.add(read_data(frame))
        except (FrameError, MapError):
            return  # the server refuses such a map as well
        if grid is not None:
            tap.maps = [*tap.maps[-3:], grid]

    def uploaded_map(self, role: str = "mapper") -> Any | None:
        """The last whole map ``role`` sent, as it left the rover (None if none)."""
        tap = self.taps.get(role)
        return tap.maps[-1] if tap is not None and tap.maps else None

    def note_delivered(self, role: str, frame: Frame) -> None:
        """Count a frame the server's game logic received from ``role``."""
        if frame.seq is None or frame.cmd in UNRELIABLE_CMDS:
            return
        tap = self.taps.get(role)
        if tap is None:
            self.unknown_rover_frames += 1
            return
        tap.delivered[_frame_key(frame)] += 1

    def pending(self, before: float) -> int:
        """Reliable frames first sent before ``before`` [s] that have not been delivered yet."""
        return sum(1 for tap in self.taps.values() for k, t in tap.first_sent.items()
                   if t < before and tap.delivered[k] == 0)

    def sent_and_delivered(self, before: float) -> dict[str, Delivery]:
        """Per role: what was sent (before ``before`` [s], and at all) and delivered."""
        return {role: Delivery({k for k, t in tap.first_sent.items() if t < before},
                               set(tap.first_sent), Counter(tap.delivered))
                for role, tap in self.taps.items()}


class TraceCounts:
    """Counts lifecycle events of a run (restarts, crashes, hangs, escalations).

    A trace subscriber: it only counts, so the run's trace hash is unchanged.
    """

    def __init__(self, trace: Trace) -> None:
        self.counts: Counter = Counter()
        self.escalations: list[str] = []
        """Supervisors that gave up, in order (bounded)."""
        self.refused_faults: list[str] = []
        self._sub = trace.subscribe(self._on_event)

    def _on_event(self, event: TraceEvent) -> None:
        self.counts[event.kind.value] += 1
        if event.kind == EventKind.ESCALATE and len(self.escalations) < 100:
            self.escalations.append(f"{event.actor} at {event.time:.1f} s")
        elif (event.kind == EventKind.FAULT and event.detail.startswith("refused")
              and len(self.refused_faults) < 100):
            self.refused_faults.append(f"{event.actor}: {event.detail}")

    def close(self) -> None:
        """Stop counting."""
        self._sub.close()


class FoundProbe:
    """Notes, for each ``found`` report the server's game logic receives from the seeker,
    whether the hider truly was in view of the seeker's IR sensor then (a frame observer:
    it never awaits, so the run keeps its trace hash)."""

    def __init__(self, in_view: Callable[[], bool]) -> None:
        self.founds: list[bool] = []
        """One entry per ``found`` report: the hider was in view."""
        self._in_view = in_view

    @classmethod
    def install(cls, system: Any) -> FoundProbe:
        probe = cls(system.world.hider_in_ir_view)
        system.server.observe_frames(probe._delivered)
        return probe

    def _delivered(self, _rover_id: str, role: str, frame: Frame) -> None:
        if role == "seeker" and frame.cmd == "found" and len(self.founds) < 100:
            self.founds.append(self._in_view())


def install_passage_counter(system: Any) -> PassageCounter:
    """Count each rover's entries into the room's narrow passages and whether it got
    through (`world.passages`), from the true poses after every world tick (a step
    observer: it never awaits nor draws, so the run keeps its trace hash)."""
    counter = PassageCounter(narrow_passages(system.scenario))
    world = system.world

    def sample() -> None:
        for role in ROLES:
            p = world.true_pose(role)
            counter.update(role, p.x, p.y)

    if counter.passages:
        world.observe_steps(sample)
    return counter


# ---------------------------------------------------------------------------- checks

def check_found_is_true(outcome: str, founds: list[bool]) -> list[Violation]:
    """Truth: a game that ended ``found`` ended on a report of a hider truly in view."""
    if outcome != "found" or (founds and founds[-1]):
        return []
    detail = "no found report was seen" if not founds else \
        "the seeker reported found with the hider out of its IR sensor's view"
    return [Violation("truth.false_found", detail)]


def check_ended(outcome: str, reason: str) -> list[Violation]:
    """Liveness: the game ended as found or not found (not failed, e.g. by a phase timeout)."""
    if outcome in ("found", "not_found"):
        return []
    return [Violation("liveness.ended", reason or f"outcome {outcome!r}")]


def check_actors_alive(states: dict[str, str]) -> list[Violation]:
    """Liveness: every firmware actor (name ``role/actor``) is running at the end."""
    dead = sorted(f"{n} {s}" for n, s in states.items()
                  if "/" in n and s != ActorState.RUNNING.value)
    if not dead:
        return []
    return [Violation("liveness.actor_dead", ", ".join(dead[:_LIST_MAX])
                      + (f" (+{len(dead) - _LIST_MAX} more)" if len(dead) > _LIST_MAX else ""))]


def check_no_escalation(escalations: list[str], faults_fired: int) -> list[Violation]:
    """Liveness: no supervisor gave up when at most one fault was injected.

    With several overlapping faults a supervisor reaching its restart
    intensity is the designed behaviour, so it is not a violation then.
    """
    if not escalations or faults_fired > 1:
        return []
    return [Violation("liveness.gave_up", "; ".join(escalations[:_LIST_MAX]))]


def check_exactly_once(per_role: dict[str, Delivery]) -> list[Violation]:
    """No loss: each reliable frame a rover sent was delivered exactly once, none invented.

    Only frames in ``due`` must have arrived; frames sent in the last moments
    (after the cut) may still be in flight, but none may arrive twice and
    none may arrive that the rover never sent.
    """
    out: list[Violation] = []
    for role, d in sorted(per_role.items()):
        lost = sorted(k for k in d.due if d.delivered[k] == 0)
        dup = sorted(k for k, n in d.delivered.items() if n > 1)
        phantom = sorted(k for k, n in d.delivered.items() if n and k not in d.sent)
        if lost:
            out.append(Violation("no_loss.lost", f"{role}: {len(lost)} of {len(d.due)} reliable "
                                 f"frames never delivered, e.g. {_short(lost)}"))
        if dup:
            out.append(Violation("no_loss.duplicate",
                                 f"{role}: {len(dup)} frames delivered more than once, "
                                 f"e.g. {_short(dup)}"))
        if phantom:
            out.append(Violation("no_loss.phantom",
                                 f"{role}: {len(phantom)} frames delivered that the rover never "
                                 f"sent (corrupted yet valid?), e.g. {_short(phantom)}"))
    return out


def _short(keys: list[str]) -> str:
    return ", ".join(k[:60] for k in keys[:2])


def check_maps_equal(stored: Any, uploaded: Any) -> list[Violation]:
    """No loss: the map the server stored equals the one the mapper uploaded.

    Both are `GridMap`-like (``cells``, ``resolution_cm``, ``origin_cm``);
    None means there was none (no map is fine only when neither has one).
    """
    if stored is None and uploaded is None:
        return []
    if stored is None or uploaded is None:
        which = "the server stored no map" if stored is None else "the mapper uploaded none"
        return [Violation("no_loss.map", which)]
    if (stored.cells.shape != uploaded.cells.shape
            or not np.array_equal(stored.cells, uploaded.cells)):
        diff = (int((stored.cells != uploaded.cells).sum())
                if stored.cells.shape == uploaded.cells.shape
                else f"shape {stored.cells.shape} vs {uploaded.cells.shape}")
        return [Violation("no_loss.map", f"stored map differs from the uploaded one: {diff} cells")]
    if (float(stored.resolution_cm) != float(uploaded.resolution_cm)
            or tuple(map(float, stored.origin_cm)) != tuple(map(float, uploaded.origin_cm))):
        return [Violation("no_loss.map", "stored map placement (resolution/origin) differs")]
    return []


def _module_of(obj: Any) -> str:
    return getattr(type(obj), "__module__", "") or ""


def _world_object(obj: Any) -> bool:
    """An object whose class lives in the world package (state or value record)."""
    module = _module_of(obj)
    return module == "world" or module.startswith("world.")


def _frozen(obj: Any) -> bool:
    params = getattr(type(obj), "__dataclass_params__", None)
    return params is not None and bool(params.frozen)


def _not_walked(obj: Any) -> bool:
    """The actor runtime and Trio: domain-free, they hold every actor; not the firmware's reach."""
    module = _module_of(obj)
    return (module.startswith(("trio", "actors.", "_contextvars"))
            and not module.startswith("actors.firmware"))


def _children(obj: Any) -> Iterable[Any]:
    if isinstance(obj, dict):
        yield from obj.keys()
        yield from obj.values()
    elif isinstance(obj, (list, tuple, set, frozenset)) or type(obj).__name__ == "deque":
        yield from obj
    else:
        d = getattr(obj, "__dict__", None)
        if isinstance(d, dict):
            yield from d.values()
        for cls in type(obj).__mro__:
            for slot in getattr(cls, "__slots__", ()):
                if isinstance(slot, str) and slot not in ("__dict__", "__weakref__"):
                    try:
                        yield getattr(obj, slot)
                    except AttributeError:
                        pass


_LEAVES = (str, bytes, bytearray, int, float, bool, type(None), np.ndarray, np.generic,
           types.FunctionType, types.MethodType, types.BuiltinFunctionType, type,
           types.ModuleType)


def check_honesty(roots: dict[str, Any], allowed: dict[str, Any]) -> list[Violation]:
    """Honesty: nothing reachable from a root (firmware actor, server) is a world object,
    except what is allowed for that root: its rover's hardware interface and the
    calibration record it is built with.

    A frozen world record is accepted only when its type is the type of an
    allowed frozen record (the rover's ``HardwareSpec`` is the contract's own type; the
    frozen `Scenario`, which is the room's ground truth, is not). The walk
    follows containers and instance attributes (not functions, bound methods
    or modules: the simulated link hands the server a bound write method,
    bytes only), does not enter the actor runtime or Trio (they are
    domain-free and hold every actor) and stops at ``_WALK_MAX`` objects per
    root.

    Args:
        roots: name -> object to walk from.
        allowed: name -> the world object that root may hold (its rover's
            hardware), a tuple of such objects (hardware and its spec), or None.
    """
    out: list[Violation] = []
    for name, root in roots.items():
        ok = allowed.get(name)
        oks = tuple(o for o in (ok if isinstance(ok, tuple) else (ok,)) if o is not None)
        value_types = {type(o) for o in oks if _frozen(o)}
        seen: set[int] = set()
        stack = [(root, name)]
        while stack and len(seen) < _WALK_MAX:
            obj, path = stack.pop()
            if id(obj) in seen or isinstance(obj, _LEAVES):
                continue
            seen.add(id(obj))
            if any(obj is o for o in oks) or (obj is not root and _not_walked(obj)):
                continue
            if _world_object(obj) and not (_frozen(obj) and type(obj) in value_types):
                out.append(Violation("honesty", f"{path} holds a world object "
                                     f"{type(obj).__module__}.{type(obj).__name__}"))
                break
            stack.extend((child, f"{path}.{type(child).__name__}") for child in _children(obj))
    return out


def check_module_honesty(prefixes: tuple[str, ...] = ("actors.firmware", "server")
                         ) -> list[Violation]:
    """Honesty: no loaded firmware or server module has a world name in its globals."""
    out = []
    for name, module in list(sys.modules.items()):
        if module is None or not any(name == p or name.startswith(p + ".") for p in prefixes):
            continue
        for attr, value in list(vars(module).items()):
            where = (value.__name__ if isinstance(value, types.ModuleType)
                     else getattr(value, "__module__", "") or "")
            if where == "world" or where.startswith("world."):
                out.append(Violation("honesty", f"module {name} holds {attr} from {where}"))
    return out


def check_determinism(first: str, second: str | None) -> list[Violation]:
    """Determinism: a replay of the game gave the same trace hash (None: not replayed)."""
    if second is None or first == second:
        return []
    return [Violation("determinism", f"trace hash {first[:12]} then {second[:12]}")]
