"""Link faults the server applies to an attached rover's frames: loss, corruption, latency, down.

The ground side's answer when a rover cannot break its own radio (``tc netem``
is the model): frames from and to one rover id, on whatever link speaks for it
(serial, TCP, UDP), are dropped, corrupted, delayed or cut. The kinds and
parameters are the simulated WiFly's (``world/faults.py``, device ``wifly``;
the server may not import the world, so ``tests/test_link_faults.py`` checks
that the two tables agree):

========  ==========================  =========================================
kind      parameter (default)         effect, per frame (one line)
========  ==========================  =========================================
down      none                        every frame both ways is dropped
loss      percent (20)                each frame is dropped with that chance
corrupt   per_byte (0.01)             each byte but the newline is flipped with that chance
latency   added_s (0.2)               each frame arrives that much later
========  ==========================  =========================================

Randomness comes from one seeded generator per book; a book with no active
fault draws nothing, so a game without link faults is unchanged. Time is
Trio's (the caller passes ``now``).
"""

from __future__ import annotations

import random
from dataclasses import dataclass, field

__all__ = ["LINK_FAULTS", "LINK_TARGET", "LinkFault", "LinkFaultBook", "check_link_fault"]

LINK_FAULTS: dict[str, dict[str, float]] = {
    "down": {},
    "loss": {"percent": 20.0},
    "corrupt": {"per_byte": 0.01},
    "latency": {"added_s": 0.2},
}
"""kind -> {parameter: default}, as the simulated WiFly's device faults."""
LINK_TARGET = "link"
"""The target name of a link fault (``mapper/link loss``)."""


@dataclass(frozen=True, slots=True)
class LinkFault:
    """One active link fault."""

    id: int
    kind: str
    start_s: float
    duration_s: float
    """0 = until cleared."""
    params: dict[str, float] = field(default_factory=dict)

    def expired(self, now: float) -> bool:
        return self.duration_s > 0 and now >= self.start_s + self.duration_s


def check_link_fault(kind: str, duration_s: float, params: dict[str, float]) -> dict[str, float]:
    """The parameters with defaults filled in.

    Raises:
        ValueError: unknown kind or parameter, or a value out of range.
    """
    if kind not in LINK_FAULTS:
        raise ValueError(f"link fault kind must be one of {', '.join(LINK_FAULTS)}, "
                         f"got {kind!r}")
    if not isinstance(duration_s, (int, float)) or isinstance(duration_s, bool) \
            or not 0 <= duration_s <= 86400:
        raise ValueError(f"fault duration must be within 0..86400 s, got {duration_s!r}")
    out = dict(LINK_FAULTS[kind])
    for name, value in params.items():
        if name not in out:
            allowed = ", ".join(out) or "none"
            raise ValueError(f"link fault {kind!r} has no parameter {name!r} "
                             f"(parameters: {allowed})")
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value >= 0:
            raise ValueError(f"link fault parameter {name} must be a number >= 0, got {value!r}")
        out[name] = float(value)
    return out


class LinkFaultBook:
    """The active link faults of one rover id, applied frame by frame.

    Args:
        seed: seeds the book's generator (loss and corruption draws).
    """

    def __init__(self, seed: int) -> None:
        self._rng = random.Random(seed)
        self._active: dict[int, LinkFault] = {}
        self._next_id = 1
        self.dropped = 0
        """Frames dropped by ``down`` and ``loss`` so far (both ways)."""
        self.corrupted = 0
        """Bytes flipped so far."""

    def __bool__(self) -> bool:
        return bool(self._active)

    def add(self, kind: str, now: float, duration_s: float, params: dict[str, float]) -> LinkFault:
        """Start a fault (parameters checked by `check_link_fault`)."""
        full = check_link_fault(kind, duration_s, params)
        fault = LinkFault(self._next_id, kind, now, float(duration_s), full)
        self._next_id += 1
        self._active[fault.id] = fault
        return fault

    def clear(self, kind: str = "*") -> list[LinkFault]:
        """Remove the faults of ``kind`` (``*``: all); returns them."""
        gone = [f for f in self._active.values() if kind in ("*", f.kind)]
        for f in gone:
            del self._active[f.id]
        return gone

    def expire(self, now: float) -> list[LinkFault]:
        """Remove and return the faults whose time is up."""
        gone = [f for f in self._active.values() if f.expired(now)]
        for f in gone:
            del self._active[f.id]
        return gone

    def active(self) -> list[LinkFault]:
        return list(self._active.values())

    def _find(self, kind: str) -> LinkFault | None:
        found = None
        for f in self._active.values():
            if f.kind == kind:
                found = f
        return found

    def latency(self) -> float:
        """Added delay of each frame now [s]."""
        f = self._find("latency")
        return f.params["added_s"] if f else 0.0

    def apply(self, lines: list[bytes]) -> list[bytes]:
        """The lines that pass the faults now, corrupted where they strike (in order)."""
        if not self._active:
            return lines
        if self._find("down") is not None:
            self.dropped += len(lines)
            return []
        loss = self._find("loss")
        corrupt = self._find("corrupt")
        p_loss = min(loss.params["percent"], 100.0) / 100.0 if loss else 0.0
        p_byte = min(corrupt.params["per_byte"], 1.0) if corrupt else 0.0
        out = []
        for line in lines:
            if p_loss and self._rng.random() < p_loss:
                self.dropped += 1
                continue
            if p_byte:
                line = self._corrupt(line, p_byte)
            out.append(line)
        return out

    def _corrupt(self, line: bytes, p: float) -> bytes:
        body = bytearray(line)
        end = len(body) - 1 if body.endswith(b"\n") else len(body)
        for i in range(end):
            if self._rng.random() < p:
                flipped = body[i] ^ self._rng.randrange(1, 256)
                body[i] = flipped if flipped != 0x0A else flipped ^ 0x01  # no new line ends
                self.corrupted += 1
        return bytes(body)
