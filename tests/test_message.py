"""The seed's 96-bit message and the buffer pool."""

from __future__ import annotations

import struct

import pytest
from hypothesis import given
from hypothesis import strategies as st

from actors import BufferPool, Message, PoolExhausted, ValueType

u32 = st.integers(0, 2**32 - 1)
i32 = st.integers(-(2**31), 2**31 - 1)
i16 = st.integers(-(2**15), 2**15 - 1)
f32 = st.floats(width=32, allow_nan=False)


@given(u32, i32)
def test_int_round_trip(command: int, value: int) -> None:
    """An int32 message packs to 12 bytes and unpacks equal."""
    m = Message.int(command, value)
    data = m.pack()
    assert len(data) == 12
    assert Message.unpack(data) == m


@given(u32, u32, u32)
def test_uint_and_custom_type_round_trip(command: int, vtype: int, value: int) -> None:
    """Any type outside the float/int32 encodings reads as uint32 and round-trips."""
    if vtype in (ValueType.INT32, ValueType.FLOAT32):
        vtype = ValueType.UINT32
    m = Message(command, vtype, value)
    assert Message.unpack(m.pack()) == m


@given(u32, f32)
def test_float_round_trip(command: int, value: float) -> None:
    """A float32 message round-trips exactly (it is stored at float32)."""
    m = Message.float(command, value)
    assert Message.unpack(m.pack()) == m


@given(u32, i16, i16)
def test_pair_round_trip(command: int, a: int, b: int) -> None:
    """Two int16 values survive packing in one value and the 12-byte round trip."""
    m = Message.pair(command, a, b)
    assert Message.unpack(m.pack()).as_pair() == (a, b)


def test_float_is_stored_rounded_to_float32() -> None:
    """0.1 is held as the nearest float32, not the float64."""
    m = Message.float(1, 0.1)
    assert m.value == struct.unpack("<f", struct.pack("<f", 0.1))[0]
    assert m.value != 0.1


def test_pack_is_little_endian_fields_in_order() -> None:
    """command, type, value as three little-endian 32-bit words."""
    assert Message.int(1, -2).pack() == struct.pack("<IIi", 1, ValueType.INT32, -2)


@pytest.mark.parametrize(
    ("make", "error"),
    [
        (lambda: Message(-1, 0, 0), "command must be in 0..4294967295 (uint32), got -1"),
        (lambda: Message(2**32, 0, 0), "command must be in 0..4294967295 (uint32), got 4294967296"),
        (lambda: Message(0, 2**32, 0), "type must be in 0..4294967295 (uint32), got 4294967296"),
        (lambda: Message.int(0, 2**31), "value must be in -2147483648..2147483647 (int32), "
                                        "got 2147483648"),
        (lambda: Message.uint(0, -1), "value must be in 0..4294967295 (uint32), got -1"),
        (lambda: Message.float(0, 1e39), "value must fit float32"),
        (lambda: Message.pair(0, 40000, 0), "a must be in -32768..32767 (int16), got 40000"),
        (lambda: Message.pair(0, 0, -40000), "b must be in -32768..32767 (int16), got -40000"),
    ],
)
def test_out_of_range_names_the_field(make, error: str) -> None:
    """A value 32 bits cannot hold is rejected when the message is made."""
    with pytest.raises(ValueError, match=error.replace("(", r"\(").replace(")", r"\)")):
        make()


def test_wrong_types_are_type_errors() -> None:
    """Strings and bools are not numbers here."""
    with pytest.raises(TypeError, match="command must be an int"):
        Message("1", 0, 0)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="value must be an int"):
        Message.int(1, 1.5)  # type: ignore[arg-type]
    with pytest.raises(TypeError, match="value must be an int"):
        Message.int(1, True)


def test_unpack_wrong_length() -> None:
    """Only exactly 12 bytes unpack."""
    with pytest.raises(ValueError, match="a packed message is 12 bytes, got 11"):
        Message.unpack(b"\0" * 11)


def test_message_is_frozen() -> None:
    """Messages are immutable (shared between actors)."""
    m = Message.int(1, 2)
    with pytest.raises(AttributeError):
        m.value = 3  # type: ignore[misc]


def test_as_pair_needs_int16x2() -> None:
    with pytest.raises(ValueError, match="as_pair needs type INT16X2"):
        Message.int(1, 2).as_pair()


def test_buffer_pool_put_take_and_exhaustion() -> None:
    """A full pool raises PoolExhausted and counts it; take releases a slot."""
    pool = BufferPool(2, name="lidar")
    h1 = pool.put(b"one")
    h2 = pool.put(b"two")
    with pytest.raises(PoolExhausted):
        pool.put(b"three")
    assert pool.statistics().exhausted == 1
    assert pool.take(h1) == b"one"
    h3 = pool.put(b"three")
    assert pool.take(h3) == b"three" and pool.take(h2) == b"two"
    s = pool.statistics()
    assert (s.in_use, s.puts, s.takes, s.high_water) == (0, 3, 3, 2)
    handle_msg = Message.handle(7, h3)
    assert Message.unpack(handle_msg.pack()).value == h3


def test_buffer_pool_rejects_stale_handles() -> None:
    """A handle already taken (or reused by a later put) is refused."""
    pool = BufferPool(1)
    h = pool.put("a")
    pool.take(h)
    h_new = pool.put("b")
    assert h_new != h
    with pytest.raises(KeyError):
        pool.take(h)
    assert pool.take(h_new) == "b"


def test_buffer_pool_capacity_checked() -> None:
    with pytest.raises(ValueError, match="capacity must be in 1..65535, got 0"):
        BufferPool(0)
