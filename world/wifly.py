"""WiFly link model: a rover's UART-speed radio link to the server.

Each direction is a `Pipe`: bytes written wait in a bounded send buffer; every
tick up to ``wifly_bytes_s * dt`` bytes leave as one chunk, which is lost with
probability ``wifly_loss``, has each byte corrupted with probability
``wifly_corrupt``, and arrives ``wifly_latency_s`` later. While the link is
down (a fault, or `WiflyLink.disconnect`), bytes written and bytes in flight
are dropped and counted. Rover side: ``hardware.wifly_write`` and Int B; server
side: `WiflyLink.server_write` and `WiflyLink.on_server_receive`.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

#: at most this many chunks in flight per direction (older ones are dropped)
MAX_IN_FLIGHT = 1024


@dataclass(frozen=True, slots=True)
class PipeStats:
    """Counters of one direction."""

    buffered: int
    in_flight: int
    sent_bytes: int
    delivered_bytes: int
    dropped_bytes: int
    lost_chunks: int
    corrupted_bytes: int


class Pipe:
    """One direction of a link: buffer, throughput, latency, loss, corruption."""

    def __init__(self, capacity: int) -> None:
        self.capacity = capacity
        self.buffer = bytearray()
        self.in_flight: deque[tuple[float, bytes]] = deque()
        self._budget = 0.0
        self.sent = self.delivered = self.dropped = self.lost = self.corrupted = 0

    def write(self, data: bytes, connected: bool) -> None:
        """Queue bytes to send; what does not fit (or a down link) is dropped."""
        if not connected:
            self.dropped += len(data)
            return
        room = self.capacity - len(self.buffer)
        if len(data) > room:
            self.dropped += len(data) - max(room, 0)
            data = data[:max(room, 0)]
        self.buffer += data

    def drop_all(self) -> None:
        """Lose everything buffered and in flight (the link went down)."""
        self.dropped += len(self.buffer) + sum(len(c) for _, c in self.in_flight)
        self.buffer.clear()
        self.in_flight.clear()

    def tick(self, now: float, dt: float, rate: float, latency: float, loss: float,
             corrupt: float, rng: np.random.Generator) -> list[bytes]:
        """Send this tick's chunk and return the chunks due for delivery by ``now + dt``."""
        self._budget = min(self._budget, 1.0) + rate * dt
        n = min(int(self._budget), len(self.buffer))
        if n:
            self._budget -= n
            chunk = bytes(self.buffer[:n])
            del self.buffer[:n]
            self.sent += n
            if loss > 0 and rng.random() < loss:
                self.lost += 1
            else:
                if corrupt > 0:
                    mask = rng.random(n) < corrupt
                    k = int(mask.sum())
                    if k:
                        arr = np.frombuffer(chunk, dtype=np.uint8).copy()
                        arr[mask] ^= rng.integers(1, 256, size=k, dtype=np.uint8)
                        chunk = arr.tobytes()
                        self.corrupted += k
                if len(self.in_flight) >= MAX_IN_FLIGHT:
                    self.dropped += len(self.in_flight.popleft()[1])
                self.in_flight.append((now + dt + latency, chunk))
        out = []
        end = now + dt + 1e-12
        while self.in_flight and self.in_flight[0][0] <= end:
            chunk = self.in_flight.popleft()[1]
            self.delivered += len(chunk)
            out.append(chunk)
        return out

    def stats(self) -> PipeStats:
        return PipeStats(len(self.buffer), len(self.in_flight), self.sent, self.delivered,
                         self.dropped, self.lost, self.corrupted)


class WiflyLink:
    """The server's end of one rover's WiFly link (the rover's end is its hardware).

    Attributes:
        on_server_receive: called with each chunk of bytes that reaches the server.
    """

    def __init__(self, role: str, capacity: int) -> None:
        self.role = role
        self.up = Pipe(capacity)
        """Rover -> server."""
        self.down = Pipe(capacity)
        """Server -> rover."""
        self.on_server_receive: Callable[[bytes], None] | None = None
        self._switched_on = True
        self._fault_down = False

    @property
    def connected(self) -> bool:
        """True when the radio link is up (not disconnected and no ``down`` fault)."""
        return self._switched_on and not self._fault_down

    def server_write(self, data: bytes) -> None:
        """Bytes from the server to the rover (arrive as Int B)."""
        self.down.write(bytes(data), self.connected)

    def rover_write(self, data: bytes) -> None:
        """Bytes from the rover to the server (``hardware.wifly_write``)."""
        self.up.write(bytes(data), self.connected)

    def disconnect(self) -> None:
        """Take the link down (as if the access point vanished) until `connect`."""
        self._switched_on = False
        self._went_down()

    def connect(self) -> None:
        """Bring a `disconnect`-ed link back up."""
        self._switched_on = True

    def set_fault_down(self, down: bool) -> None:
        """Used by the world for the ``wifly down`` fault."""
        was = self.connected
        self._fault_down = down
        if was and not self.connected:
            self._went_down()

    def _went_down(self) -> None:
        self.up.drop_all()
        self.down.drop_all()

    def statistics(self) -> dict[str, PipeStats]:
        """Counters per direction: ``up`` (rover to server) and ``down``."""
        return {"up": self.up.stats(), "down": self.down.stats()}

    def __repr__(self) -> str:
        u, d = self.up.stats(), self.down.stats()
        return (f"<WiflyLink {self.role} connected={self.connected} up={u.delivered_bytes}B "
                f"down={d.delivered_bytes}B dropped={u.dropped_bytes + d.dropped_bytes}B>")
