"""The seed's internal message: three 32-bit fields, and the buffer pool for bulk data.

Every internal queue of the rover firmware carries the same 96-bit message
(DESIGN.md section 3): ``command`` (what to do / what this is), ``type`` (how
to read ``value``) and ``value`` (any 32-bit quantity). Values are checked
when the message is made, so a message that exists always packs; floats are
held at float32 precision, so a value read back after ``unpack`` is the same.

Bulk data does not fit 32 bits: it goes into a `BufferPool` and travels as a
``HANDLE`` value, like a pointer to a static buffer in C firmware. The pool has
a fixed number of slots; a pool that runs dry raises `PoolExhausted`, which the
caller counts as an overflow, just like a full queue.
"""

from __future__ import annotations

import enum
import struct
from dataclasses import dataclass
from typing import Any

__all__ = ["ValueType", "Message", "BufferPool", "PoolExhausted", "PoolStatistics"]

_UINT32_MAX = 0xFFFF_FFFF
_INT32_MIN, _INT32_MAX = -(2**31), 2**31 - 1
_INT16_MIN, _INT16_MAX = -(2**15), 2**15 - 1
_F32 = struct.Struct("<f")
_PACK_INT = struct.Struct("<IIi")
_PACK_UINT = struct.Struct("<III")
_PACK_FLOAT = struct.Struct("<IIf")
_FLOAT32_MAX = 3.4028234663852886e38
_EMPTY = object()  # marks a free pool slot


class ValueType(enum.IntEnum):
    """How the 32-bit ``value`` field is read (the message's ``type`` field)."""

    INT32 = 0  #: signed 32-bit integer
    UINT32 = 1  #: unsigned 32-bit integer
    FLOAT32 = 2  #: IEEE 754 single precision
    INT16X2 = 3  #: two signed 16-bit integers, ``a`` in the low half, ``b`` in the high half
    HANDLE = 4  #: unsigned 32-bit handle into a `BufferPool`


_SIGNED = frozenset((ValueType.INT32,))
_FLOATS = frozenset((ValueType.FLOAT32,))


_set = object.__setattr__  # builds a frozen Message whose fields were already checked


def _to_float32(value: float) -> float:
    return _F32.unpack(_F32.pack(value))[0]


def _checked(cls: type, command: int, vtype: int, value: int | float) -> Message:
    """A Message whose fields the caller has already checked (and rounded): the
    constructors' fast path, which skips ``__post_init__`` (firmware makes these by
    the thousand per simulated minute)."""
    m = object.__new__(cls)
    _set(m, "command", command)
    _set(m, "type", vtype)
    _set(m, "value", value)
    return m


@dataclass(frozen=True, slots=True)
class Message:
    """One internal message: ``command`` (uint32), ``type`` (uint32), ``value`` (32 bits).

    ``type`` values outside `ValueType` are allowed (an application may define
    its own encodings) and are read as unsigned 32-bit integers.

    Raises:
        TypeError: ``command``/``type`` not an int, or ``value`` not a number.
        ValueError: a field out of its 32-bit range; the message names the field.
    """

    command: int
    type: int
    value: int | float

    def __post_init__(self) -> None:
        for field in ("command", "type"):
            v = getattr(self, field)
            if isinstance(v, bool) or not isinstance(v, int):
                raise TypeError(f"{field} must be an int, got {v!r}")
            if not 0 <= v <= _UINT32_MAX:
                raise ValueError(f"{field} must be in 0..{_UINT32_MAX} (uint32), got {v!r}")
        v = self.value
        if self.type in _FLOATS:
            if isinstance(v, bool) or not isinstance(v, (int, float)):
                raise TypeError(f"value must be a float for FLOAT32, got {v!r}")
            if v != v or abs(v) == float("inf"):
                stored = float(v)
            elif abs(v) > _FLOAT32_MAX:
                raise ValueError(f"value must fit float32 (|v| <= {_FLOAT32_MAX:g}), got {v!r}")
            else:
                stored = _to_float32(float(v))
            object.__setattr__(self, "value", stored)
            return
        if isinstance(v, bool) or not isinstance(v, int):
            raise TypeError(f"value must be an int for type {self.type}, got {v!r}")
        if self.type in _SIGNED:
            if not _INT32_MIN <= v <= _INT32_MAX:
                raise ValueError(f"value must be in {_INT32_MIN}..{_INT32_MAX} (int32), got {v!r}")
        elif not 0 <= v <= _UINT32_MAX:
            raise ValueError(f"value must be in 0..{_UINT32_MAX} (uint32), got {v!r}")

    # ------------------------------------------------------------------ constructors
    @classmethod
    def int(cls, command: int, value: int) -> Message:
        """A signed 32-bit integer value."""
        if isinstance(command, int) and type(command) is not bool and type(value) is int \
                and 0 <= command <= _UINT32_MAX \
                and _INT32_MIN <= value <= _INT32_MAX:
            return _checked(cls, command, ValueType.INT32, value)
        return cls(command, ValueType.INT32, value)

    @classmethod
    def uint(cls, command: int, value: int) -> Message:
        """An unsigned 32-bit integer value."""
        if isinstance(command, int) and type(command) is not bool and type(value) is int \
                and 0 <= command <= _UINT32_MAX \
                and 0 <= value <= _UINT32_MAX:
            return _checked(cls, command, ValueType.UINT32, value)
        return cls(command, ValueType.UINT32, value)

    @classmethod
    def float(cls, command: int, value: float) -> Message:
        """A float32 value (stored rounded to float32)."""
        if isinstance(command, int) and type(command) is not bool and type(value) is float \
                and 0 <= command <= _UINT32_MAX \
                and -_FLOAT32_MAX <= value <= _FLOAT32_MAX:
            return _checked(cls, command, ValueType.FLOAT32, _to_float32(value))
        return cls(command, ValueType.FLOAT32, value)

    @classmethod
    def handle(cls, command: int, handle: int) -> Message:
        """A handle into a `BufferPool`."""
        if isinstance(command, int) and type(command) is not bool and type(handle) is int \
                and 0 <= command <= _UINT32_MAX \
                and 0 <= handle <= _UINT32_MAX:
            return _checked(cls, command, ValueType.HANDLE, handle)
        return cls(command, ValueType.HANDLE, handle)

    @classmethod
    def pair(cls, command: int, a: int, b: int) -> Message:
        """Two signed 16-bit integers packed in one value (``a`` low, ``b`` high).

        Raises:
            ValueError: ``a`` or ``b`` outside -32768..32767.
        """
        if (type(a) is int and type(b) is int and isinstance(command, int)
                and type(command) is not bool and 0 <= command <= _UINT32_MAX
                and _INT16_MIN <= a <= _INT16_MAX and _INT16_MIN <= b <= _INT16_MAX):
            # every field is known valid: skip __post_init__ (ISRs make these by the thousand)
            m = object.__new__(cls)
            _set(m, "command", command)
            _set(m, "type", ValueType.INT16X2)
            _set(m, "value", (a & 0xFFFF) | ((b & 0xFFFF) << 16))
            return m
        for field, v in (("a", a), ("b", b)):
            if isinstance(v, bool) or not isinstance(v, int):
                raise TypeError(f"{field} must be an int, got {v!r}")
            if not _INT16_MIN <= v <= _INT16_MAX:
                raise ValueError(
                    f"{field} must be in {_INT16_MIN}..{_INT16_MAX} (int16), got {v!r}")
        return cls(command, ValueType.INT16X2, (a & 0xFFFF) | ((b & 0xFFFF) << 16))

    def as_pair(self) -> tuple[int, int]:
        """The two int16 halves of an ``INT16X2`` value.

        Raises:
            ValueError: the message's type is not ``INT16X2``.
        """
        if self.type != ValueType.INT16X2:
            raise ValueError(f"as_pair needs type INT16X2, got type {self.type}")
        v = int(self.value)
        a, b = v & 0xFFFF, (v >> 16) & 0xFFFF
        return (a - 0x10000 if a & 0x8000 else a, b - 0x10000 if b & 0x8000 else b)

    # ------------------------------------------------------------------ wire format
    def pack(self) -> bytes:
        """The 12-byte little-endian form: command, type, value (uint32, uint32, 32 bits)."""
        if self.type in _FLOATS:
            return _PACK_FLOAT.pack(self.command, self.type, self.value)
        if self.type in _SIGNED:
            return _PACK_INT.pack(self.command, self.type, self.value)
        return _PACK_UINT.pack(self.command, self.type, self.value)

    @classmethod
    def unpack(cls, data: bytes | bytearray | memoryview) -> Message:
        """The message packed in ``data`` (exactly 12 bytes).

        Raises:
            ValueError: ``data`` is not 12 bytes long.
        """
        if len(data) != 12:
            raise ValueError(f"a packed message is 12 bytes, got {len(data)}")
        command, vtype, _ = _PACK_UINT.unpack(data)
        if vtype in _FLOATS:
            return cls(command, vtype, _PACK_FLOAT.unpack(data)[2])
        if vtype in _SIGNED:
            return cls(command, vtype, _PACK_INT.unpack(data)[2])
        return cls(command, vtype, _PACK_UINT.unpack(data)[2])


# ---------------------------------------------------------------------- buffer pool
class PoolExhausted(Exception):
    """Raised by `BufferPool.put` when every slot is taken (count it as an overflow)."""


@dataclass(frozen=True, slots=True)
class PoolStatistics:
    """Counters of a `BufferPool`."""

    name: str
    in_use: int  #: slots holding a buffer now
    capacity: int  #: number of slots
    puts: int  #: successful puts since creation
    takes: int  #: successful takes since creation
    exhausted: int  #: puts refused because the pool was full
    high_water: int  #: most slots ever in use at once


class BufferPool:
    """A fixed number of slots for immutable bulk data, addressed by uint32 handles.

    The sender puts an immutable object and sends the handle in a `Message`;
    the receiver takes it back, which releases the slot. A handle is never
    reused while its slot is taken, and a stale handle is rejected (handles
    carry a generation count in their upper bits).

    Args:
        capacity: number of slots (1..65535).
        name: shown in statistics and repr.
    """

    __slots__ = ("_name", "_capacity", "_items", "_gens", "_free", "_puts", "_takes",
                 "_exhausted", "_high")

    def __init__(self, capacity: int, *, name: str = "pool") -> None:
        if isinstance(capacity, bool) or not isinstance(capacity, int):
            raise TypeError(f"capacity must be an int, got {capacity!r}")
        if not 1 <= capacity <= 0xFFFF:
            raise ValueError(f"capacity must be in 1..65535, got {capacity!r}")
        self._name = name
        self._capacity = capacity
        self._items: list[Any] = [_EMPTY] * capacity
        self._gens = [0] * capacity
        self._free = list(range(capacity - 1, -1, -1))
        self._puts = self._takes = self._exhausted = self._high = 0

    def put(self, obj: Any) -> int:
        """Store ``obj`` and return its handle.

        Raises:
            PoolExhausted: every slot is in use.
        """
        if not self._free:
            self._exhausted += 1
            raise PoolExhausted(f"buffer pool {self._name!r} is full ({self._capacity} slots)")
        slot = self._free.pop()
        self._items[slot] = obj
        self._puts += 1
        self._high = max(self._high, self._capacity - len(self._free))
        return (self._gens[slot] << 16) | slot

    def take(self, handle: int) -> Any:
        """Return the object behind ``handle`` and release its slot.

        Raises:
            KeyError: the handle is unknown, already taken, or stale.
        """
        slot, gen = handle & 0xFFFF, (handle >> 16) & 0xFFFF
        if not 0 <= slot < self._capacity or self._gens[slot] != gen or self._items[slot] is _EMPTY:
            raise KeyError(f"buffer pool {self._name!r} has no buffer for handle {handle!r}")
        obj = self._items[slot]
        self._items[slot] = _EMPTY
        self._gens[slot] = (gen + 1) & 0xFFFF
        self._free.append(slot)
        self._takes += 1
        return obj

    def statistics(self) -> PoolStatistics:
        """Current counters."""
        return PoolStatistics(self._name, self._capacity - len(self._free), self._capacity,
                              self._puts, self._takes, self._exhausted, self._high)

    def __repr__(self) -> str:
        s = self.statistics()
        return (f"<BufferPool {s.name!r} {s.in_use}/{s.capacity} in use, "
                f"{s.exhausted} exhausted>")
