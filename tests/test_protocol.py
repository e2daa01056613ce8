"""The pure message layer: frames, catalogue, lines, map codec, poses, exports."""

from __future__ import annotations

import math

import msgspec
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

import server.protocol as proto
from server.protocol import (
    CHUNK_B64_CHARS,
    MAX_LINE_BYTES,
    MAX_SEQ,
    TOO_LONG,
    Fault,
    Frame,
    FrameError,
    GridMap,
    LineBuffer,
    MapAssembler,
    MapChunk,
    MapError,
    Pose,
    compose,
    decode_line,
    encode_frame,
    inverse,
    make_frame,
    map_chunks,
    read_data,
)


def test_public_names_exist() -> None:
    """Every name in server.protocol.__all__ is importable."""
    for name in proto.__all__:
        assert hasattr(proto, name), name


def test_seed_frame_round_trips() -> None:
    """The seed's example frame decodes and encodes back to one line."""
    line = b'{"cmd":"store","type":"sensor_value","data":12345.678}\n'
    frame = decode_line(line)
    assert frame == Frame("store", "sensor_value", 12345.678)
    assert encode_frame(frame) == line


@pytest.mark.parametrize(
    ("line", "fault", "detail"),
    [
        (b"nope", Fault.NOT_JSON, "JSON is malformed: invalid character (byte 4)"),
        (b"\xff\xfe", Fault.NOT_UTF8, "invalid UTF-8 at byte 0"),
        (b"[1, 2]", Fault.BAD_FRAME, "Expected `object`, got `array`"),
        (b'{"cmd":"x","type":"y"}', Fault.BAD_FRAME, "Object missing required field `data`"),
        (b'{"type":"y","data":1}', Fault.BAD_FRAME, "Object missing required field `cmd`"),
        (b'{"cmd":"x","type":"y","data":1,"seq":0}', Fault.BAD_FRAME,
         "Expected `int` >= 1 - at `$.seq`"),
        (b"x" * (MAX_LINE_BYTES + 1), Fault.TOO_LONG, "1025 bytes, the limit is 1024"),
    ],
    ids=["not-json", "not-utf8", "array", "no-data", "no-cmd", "seq-zero", "too-long"],
)
def test_bad_lines_name_their_fault(line: bytes, fault: str, detail: str) -> None:
    """Each kind of bad line raises FrameError with the fault code and a readable detail."""
    with pytest.raises(FrameError) as info:
        decode_line(line)
    assert info.value.fault == fault
    assert info.value.detail == detail


def test_encode_refuses_overlong_frame() -> None:
    """A sender cannot put a frame over 1 KiB on the wire."""
    with pytest.raises(ValueError, match="the limit is 1024"):
        encode_frame(Frame("status", "status", "x" * 1100))


def test_catalogue_checks_type_and_data() -> None:
    """read_data refuses unknown cmds, wrong types and data that breaks the schema."""
    assert read_data(Frame("pose", "pose", {"x": 1, "y": 2, "heading": 90})) \
        == proto.PoseData(1, 2, 90)
    with pytest.raises(FrameError) as e1:
        read_data(Frame("dance", "none", None))
    assert (e1.value.fault, e1.value.detail) == (Fault.UNKNOWN_CMD, "unknown cmd 'dance'")
    with pytest.raises(FrameError) as e2:
        read_data(Frame("pose", "chunk", {"x": 1, "y": 2}))
    assert e2.value.fault == Fault.BAD_TYPE
    with pytest.raises(FrameError) as e3:
        read_data(Frame("hello", "rover", {"id": "m1", "role": "pilot"}))
    assert e3.value.fault == Fault.BAD_DATA
    assert "role" in e3.value.detail


def test_make_frame_validates_and_fills_type() -> None:
    """make_frame gives the catalogue's type and rejects data outside the schema."""
    f = make_frame("destination", proto.Destination(10, 20))
    assert f == Frame("destination", "pose",
                      {"x": 10.0, "y": 20.0, "heading": None, "within": None})
    with pytest.raises(ValueError, match="does not fit its schema"):
        make_frame("destination", {"x": 1, "y": 2, "within": 0})  # a search radius must be > 0
    with pytest.raises(ValueError, match="does not fit its schema"):
        make_frame("destination", {"x": 1, "y": 2, "within": proto.MAX_WITHIN_CM + 1})
    assert make_frame("start") == Frame("start", "none", None)
    with pytest.raises(ValueError, match="data of 'origin' does not fit its schema"):
        make_frame("origin", {"x": "far"})
    with pytest.raises(ValueError, match="cmd must be one of the catalogue, got 'fly'"):
        make_frame("fly")


def test_every_catalogue_entry_has_a_distinct_name() -> None:
    """The catalogue names each cmd once and covers the issue's list."""
    needed = {"hello", "heartbeat", "start", "stop", "origin", "map_request", "map", "pose",
              "status", "destination", "arrived", "invalid_spot", "found", "not_found",
              "error", "ack"}
    assert needed <= set(proto.CATALOGUE)


# -- lines -------------------------------------------------------------------------


def test_line_buffer_reassembles_pieces() -> None:
    """Lines split across pieces come out whole; CRLF and blank lines are tolerated."""
    buf = LineBuffer()
    out = list(buf.feed(b'{"a"')) + list(buf.feed(b':1}\r\n\n{"b":2}\n{"c"'))
    assert out == [b'{"a":1}', b'{"b":2}']
    assert len(buf) == 4


def test_line_buffer_bounds_an_endless_line() -> None:
    """Garbage without newlines is reported once and never held beyond the limit."""
    buf = LineBuffer(limit=16)
    out = []
    for _ in range(100):
        out += list(buf.feed(b"x" * 10))
        assert len(buf) < 16
    out += list(buf.feed(b"tail\nok\n"))
    assert out == [TOO_LONG, b"ok"]


@given(st.lists(st.binary(max_size=40), max_size=30))
@settings(max_examples=200, deadline=None)
def test_line_buffer_never_exceeds_limit(pieces: list[bytes]) -> None:
    """Whatever arrives, the buffer stays under its limit and lines have no newline."""
    buf = LineBuffer(limit=32)
    for p in pieces:
        for line in buf.feed(p):
            assert line is TOO_LONG or (b"\n" not in line and len(line) < 32)
        assert len(buf) < 32


@given(st.binary(max_size=300))
@settings(max_examples=300, deadline=None)
def test_decoder_never_crashes_on_random_bytes(data: bytes) -> None:
    """Random bytes either decode to a Frame or raise FrameError, nothing else."""
    try:
        frame = decode_line(data)
    except FrameError as exc:
        assert exc.fault in Fault.ALL
    else:
        assert isinstance(frame, Frame)
        try:
            read_data(frame)
        except FrameError as exc:
            assert exc.fault in Fault.ALL


@given(st.integers(0, 60), st.sampled_from(list(range(0, 70))))
@settings(max_examples=200, deadline=None)
def test_mutated_valid_frames_are_handled(pos: int, byte: int) -> None:
    """A valid frame with one byte changed is either valid or a named fault."""
    good = bytearray(b'{"cmd":"pose","type":"pose","data":{"x":1,"y":2,"heading":3},"seq":4}')
    good[pos % len(good)] = byte + 32
    try:
        read_data(decode_line(bytes(good)))
    except FrameError as exc:
        assert exc.fault in Fault.ALL


# -- map codec -----------------------------------------------------------------------


def _room_map(ny: int = 160, nx: int = 200) -> GridMap:
    cells = np.full((ny, nx), -1, dtype=np.int8)
    cells[10:150, 10:190] = 0
    cells[10, 10:190] = 100
    cells[149, 10:190] = 100
    cells[60:80, 90:110] = 100
    return GridMap(cells, 5.0, (-50.0, -25.0))


def test_map_round_trips_through_chunks() -> None:
    """A map cut into chunks and reassembled is the same map."""
    grid = _room_map()
    frames = map_chunks(grid, map_id=7)
    asm = MapAssembler()
    result = None
    for f in frames:
        result = asm.add(read_data(decode_line(encode_frame(f))))
    assert result is not None and result.same_as(grid)


def test_map_chunk_lines_stay_under_one_kib_with_any_seq() -> None:
    """Even with the largest seq and ack, every chunk line fits MAX_LINE_BYTES."""
    rng = np.random.default_rng(1)
    noisy = GridMap(rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=(300, 300)), 2.5,
                    (-123456.5, -654321.25))
    frames = map_chunks(noisy, map_id=2**31 - 1)
    assert len(frames) > 10
    for f in frames:
        line = encode_frame(Frame(f.cmd, f.type, f.data, seq=MAX_SEQ, ack=MAX_SEQ))
        assert len(line) <= MAX_LINE_BYTES
    assert len(frames[0].data["b64"]) == CHUNK_B64_CHARS


def test_percentages_are_classified_by_the_rule_named() -> None:
    """map_server's rule (the protocol's for a map of percentages) leaves 20..64 unknown;
    the occupancy split the constructor applies decides every observed cell at 50."""
    pct = np.array([[-1, 0, 19, 20, 49, 50, 64, 65, 100]], dtype=np.int8)
    assert GridMap.from_percentages(pct).cells.tolist() == [
        [-1, 0, 0, -1, -1, -1, -1, 100, 100]]
    assert GridMap(pct).cells.tolist() == [[-1, 0, 0, 0, 0, 100, 100, 100, 100]]
    assert GridMap(pct).codes().tolist() == [[0, 1, 1, 1, 1, 2, 2, 2, 2]]


def test_a_map_of_three_classes_is_the_same_under_both_rules() -> None:
    """A map that already holds -1 / 0 / 100 (every map that crossed the wire) is
    unchanged by either classification."""
    cells = _room_map().cells
    assert np.array_equal(GridMap.split(cells), cells)
    assert np.array_equal(GridMap.trinary(cells), cells)


def test_a_malformed_map_is_a_map_error_naming_the_fault() -> None:
    """Out-of-range cells, a bad resolution or origin and an oversized grid each raise
    MapError (a ValueError) saying what is wrong."""
    with pytest.raises(MapError, match=r"cells must hold -1..100, got 101 at \[0, 1\]"):
        GridMap(np.array([[0, 101]]))
    with pytest.raises(MapError, match="resolution_cm must be a positive number"):
        GridMap(np.zeros((2, 2), np.int8), 0.0)
    with pytest.raises(MapError, match="origin_cm must be finite"):
        GridMap(np.zeros((2, 2), np.int8), 5.0, (float("nan"), 0.0))
    with pytest.raises(MapError, match="cells must be a non-empty 2-D array"):
        GridMap(np.zeros((0, 3), np.int8))


def test_assembler_reports_missing_and_restarts_on_new_map() -> None:
    """Missing chunks are listed; a chunk of another map discards the old pieces."""
    frames = map_chunks(_room_map(300, 300), map_id=1)
    rng = np.random.default_rng(0)
    noisy = GridMap(rng.choice(np.array([-1, 0, 100], dtype=np.int8), size=(100, 100)), 5, (0, 0))
    frames = map_chunks(noisy, map_id=1)
    asm = MapAssembler()
    chunks = [msgspec.convert(f.data, MapChunk) for f in frames]
    assert asm.add(chunks[0]) is None
    assert asm.missing() == list(range(1, len(chunks)))
    other = map_chunks(_room_map(), map_id=2)
    asm.add(msgspec.convert(other[0].data, MapChunk))
    assert asm.map_id == 2


def test_assembler_rejects_corrupt_map() -> None:
    """A chunk whose bytes were altered fails the CRC check with a clear error."""
    frames = map_chunks(_room_map(), map_id=3)
    data = dict(frames[0].data)
    data["b64"] = ("A" if data["b64"][0] != "A" else "B") + data["b64"][1:]
    bad = msgspec.convert(data, MapChunk)
    asm = MapAssembler()
    chunks = [bad] + [msgspec.convert(f.data, MapChunk) for f in frames[1:]]
    with pytest.raises(MapError, match="CRC mismatch"):
        for c in chunks:
            asm.add(c)


def test_decode_runs_rejects_wrong_cell_count() -> None:
    """Runs that do not fill the map exactly are refused."""
    raw = proto.encode_runs(np.array([1, 1, 2], dtype=np.uint8))
    assert proto.decode_runs(raw, 3).tolist() == [1, 1, 2]
    with pytest.raises(MapError, match="runs hold 3 cells, the map has 4"):
        proto.decode_runs(raw, 4)


@given(st.lists(st.integers(0, 2), min_size=1, max_size=2000))
@settings(max_examples=100, deadline=None)
def test_run_coding_round_trips(codes: list[int]) -> None:
    """Any code sequence survives run-length coding."""
    arr = np.array(codes, dtype=np.uint8)
    assert proto.decode_runs(proto.encode_runs(arr), arr.size).tolist() == codes


# -- poses -----------------------------------------------------------------------------


def test_compose_and_inverse() -> None:
    """A pose composed with its inverse is the identity; composition rotates then shifts."""
    a = Pose(100.0, 50.0, 90.0)
    p = compose(a, Pose(10.0, 0.0, 0.0))
    assert p.x == pytest.approx(100.0) and p.y == pytest.approx(60.0) and p.heading_deg == 90.0
    z = compose(a, inverse(a))
    assert max(abs(z.x), abs(z.y), abs(z.heading_deg)) < 1e-9
    assert proto.wrap_deg(270.0) == -90.0 and proto.wrap_deg(-180.0) == 180.0
    assert math.isclose(proto.relative(a, p).x, 10.0)
