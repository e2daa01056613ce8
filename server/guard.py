"""Bounds against hostile peers: per-address auth backoff and burst-summarised counting.

Two small, clock-free helpers the server uses on untrusted links (every call
that depends on time takes ``now`` [s]):

* `PeerBackoff`: authentication failures per peer address. After
  ``threshold`` failures an address is blocked for a while, doubling per
  block up to ``most_s``; a success outside a block clears it. The table is
  bounded (the least recently seen address is forgotten first), so a flood of
  addresses cannot grow it.
* `BurstLog`: counts occurrences (bad frames, auth failures) by kind, fault
  and link. The first one after a quiet period is reported at once; the rest
  are summed and reported as one summary when the interval is over, so a
  flood costs one stored row per interval, not one per frame.
"""

from __future__ import annotations

from collections import Counter, OrderedDict
from dataclasses import dataclass, field
from typing import Any

__all__ = ["PeerBackoff", "BurstLog"]


@dataclass(slots=True)
class _Peer:
    failures: int = 0
    blocks: int = 0
    blocked_until: float = 0.0


@dataclass
class PeerBackoff:
    """Auth failures per peer address, with a doubling block (see the module docstring)."""

    threshold: int = 5
    """Failures that block an address."""
    first_s: float = 1.0
    """Length of the first block [s]; each later one doubles."""
    most_s: float = 60.0
    """Longest block [s]."""
    capacity: int = 4096
    """Addresses remembered at most."""
    _peers: OrderedDict[str, _Peer] = field(default_factory=OrderedDict)

    def blocked_for(self, addr: str, now: float) -> float:
        """Seconds the address stays blocked (0 when it is not)."""
        peer = self._peers.get(addr)
        return max(0.0, peer.blocked_until - now) if peer else 0.0

    def failed(self, addr: str, now: float) -> float:
        """Count one failure; return the length of the block it starts [s], or 0."""
        peer = self._peers.pop(addr, None) or _Peer()
        self._peers[addr] = peer
        while len(self._peers) > self.capacity:
            self._peers.popitem(last=False)
        peer.failures += 1
        if peer.failures < self.threshold:
            return 0.0
        peer.failures = 0
        block = min(self.first_s * 2 ** peer.blocks, self.most_s)
        peer.blocks += 1
        peer.blocked_until = now + block
        return block

    def succeeded(self, addr: str, now: float) -> None:
        """An authenticated hello: forget the address's failures, unless it is blocked now
        (a rover that proves its token from an address it shares with a guesser ends
        no block the guesser earned)."""
        if self.blocked_for(addr, now) == 0:
            self._peers.pop(addr, None)

    def __len__(self) -> int:
        return len(self._peers)


class BurstLog:
    """Counts of one kind of trouble, reported once per burst (see the module docstring).

    Args:
        interval_s: shortest time between two reports of the same kind [s].
        links: distinct links named in one summary at most (the busiest).
    """

    def __init__(self, interval_s: float = 10.0, links: int = 5) -> None:
        self.interval_s = interval_s
        self.links = links
        self.total: Counter[str] = Counter()
        """Every occurrence ever counted, by kind."""
        self._faults: dict[str, Counter[str]] = {}
        self._by_link: dict[str, Counter[str]] = {}
        self._last_report: dict[str, float] = {}

    def add(self, kind: str, fault: str, link: str, now: float) -> bool:
        """Count one occurrence; True when it should be reported now (the first of a burst)."""
        self.total[kind] += 1
        last = self._last_report.get(kind)
        if last is None or now - last >= self.interval_s:
            if not self._faults.get(kind):
                self._last_report[kind] = now
                return True
        faults = self._faults.setdefault(kind, Counter())
        faults[fault] += 1
        by_link = self._by_link.setdefault(kind, Counter())
        if link in by_link or len(by_link) < 4 * self.links:
            by_link[link] += 1
        else:
            by_link["(other links)"] += 1
        return False

    def due(self, now: float) -> list[str]:
        """Kinds with a summary waiting whose interval is over."""
        return [k for k, c in self._faults.items()
                if c and now - self._last_report.get(k, now) >= self.interval_s]

    def pending(self) -> list[str]:
        """Kinds with a summary waiting, due or not (for a final report)."""
        return [k for k, c in self._faults.items() if c]

    def take(self, kind: str, now: float) -> dict[str, Any]:
        """The summary of ``kind`` since its last report; the counts start again."""
        faults = self._faults.pop(kind, Counter())
        by_link = self._by_link.pop(kind, Counter())
        self._last_report[kind] = now
        return {"count": sum(faults.values()), "faults": dict(faults.most_common()),
                "links": len(by_link),
                "busiest": {k: n for k, n in by_link.most_common(self.links)}}

    def next_due(self) -> float | None:
        """When the earliest waiting summary is due [s], None when none waits."""
        times = [self._last_report[k] + self.interval_s for k, c in self._faults.items() if c]
        return min(times) if times else None
