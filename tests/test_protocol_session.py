"""The sans-IO reliable session: seq, cumulative ack, resend, duplicates, liveness."""

from __future__ import annotations

import numpy as np
import pytest

from server.protocol import (
    Frame,
    OutboxFull,
    ReliableSession,
    decode_line,
    encode_frame,
    make_frame,
    session_id_for,
)


def _status(i: int) -> Frame:
    return Frame("status", "status", {"state": f"s{i}"})


def _frames(data: bytes) -> list[Frame]:
    return [decode_line(line) for line in data.splitlines()]


def _pair(**kw) -> tuple[ReliableSession, ReliableSession]:
    a, b = ReliableSession(**kw), ReliableSession(**kw)
    # both have heard each other once, as after hello/welcome
    b.feed(a.transmit(0.0), 0.0)
    a.feed(b.transmit(0.0), 0.0)
    return a, b


def _run(a: ReliableSession, b: ReliableSession, *, until: float, step: float = 0.05,
         loss=None, rng=None) -> list[Frame]:
    """Exchange bytes both ways each step; ``loss(rng)`` True drops a whole transmission."""
    got: list[Frame] = []
    t = 0.0
    while t < until:
        t = round(t + step, 6)
        ab = a.transmit(t)
        if ab and not (loss and loss(rng)):
            got += b.feed(ab, t)
        ba = b.transmit(t)
        if ba and not (loss and loss(rng)):
            a.feed(ba, t)
    return got


def test_reliable_frames_get_seq_and_are_acknowledged() -> None:
    """A reliable frame leaves with seq 1; the peer's bare ack empties the window; RTT sampled."""
    a, b = _pair()
    a.send(make_frame("arrived", {"x": 1, "y": 2, "heading": 0}))
    line = a.transmit(0.1)
    assert [(f.cmd, f.seq) for f in _frames(line)] == [("arrived", 1)]
    assert [f.cmd for f in b.feed(line, 0.1)] == ["arrived"]
    reply = b.transmit(0.1)
    assert [(f.cmd, f.ack) for f in _frames(reply)] == [("ack", 1)]
    assert a.stats(0.1).unacked == 1
    a.feed(reply, 0.15)
    s = a.stats(0.15)
    assert s.unacked == 0 and s.rtt_s == pytest.approx(0.05)


def _encode(frames: list[Frame]) -> bytes:
    return b"".join(encode_frame(f) for f in frames)


def test_unreliable_frames_carry_no_seq() -> None:
    """Telemetry leaves without seq and is not resent."""
    a, b = _pair()
    a.send(make_frame("pose", {"x": 1, "y": 2, "heading": 3}))
    out = _frames(a.transmit(0.1))
    assert [(f.cmd, f.seq) for f in out] == [("pose", None)]
    assert [f.cmd for f in _frames(a.transmit(5.0))] == ["heartbeat"]


def test_duplicates_are_dropped_and_acknowledged_again() -> None:
    """The same seq received twice is delivered once and acked both times."""
    a, b = _pair()
    a.send(_status(1), reliable=True)
    line = a.transmit(0.1)
    assert len(b.feed(line, 0.1)) == 1
    b.transmit(0.1)
    assert b.feed(line, 0.2) == []
    assert [(f.cmd, f.ack) for f in _frames(b.transmit(0.2))] == [("ack", 1)]
    assert b.stats(0.2).duplicates == 1


def test_out_of_order_frames_are_held_and_gap_counted_as_lost() -> None:
    """Seq 2 and 3 before 1 are held; 1 releases all three in order; lost counts the gap."""
    a, b = _pair()
    for i in range(3):
        a.send(_status(i), reliable=True)
    f1, f2, f3 = _frames(a.transmit(0.1))
    assert b.feed(_encode([f2, f3]), 0.1) == []
    assert b.stats(0.1).lost == 1
    assert [f.seq for f in b.feed(_encode([f1]), 0.2)] == [1, 2, 3]
    assert b.ack_value == 3


def test_lost_frame_is_resent_after_timeout_and_counted() -> None:
    """A frame whose transmission is lost arrives later by resend."""
    a, b = _pair()
    a.send(_status(0), reliable=True)
    a.transmit(0.1)  # lost on the way
    got = _run(a, b, until=3.0)
    assert [f.data["state"] for f in got] == ["s0"]
    assert a.stats(3.0).resent >= 1 and a.stats(3.0).unacked == 0


def test_all_frames_arrive_in_order_over_a_lossy_link() -> None:
    """With 30% of transmissions lost both ways, 100 frames arrive once each, in order."""
    rng = np.random.default_rng(42)
    a, b = _pair()
    for i in range(100):
        a.send(_status(i), reliable=True)
    got = _run(a, b, until=300.0, loss=lambda r: r.random() < 0.3, rng=rng)
    assert [f.data["state"] for f in got] == [f"s{i}" for i in range(100)]
    s = a.stats(300.0)
    assert s.resent > 0 and s.unacked == 0 and s.queued == 0


def test_window_bounds_frames_in_flight() -> None:
    """No more than `window` reliable frames are unacknowledged at once."""
    a, _ = _pair(window=4)
    for i in range(10):
        a.send(_status(i), reliable=True)
    assert [f.seq for f in _frames(a.transmit(0.1))] == [1, 2, 3, 4]
    assert a.stats(0.1).queued == 6


def test_outbox_full_is_refused_with_a_clear_error() -> None:
    """A full outbox raises OutboxFull and counts the drop."""
    a = ReliableSession(outbox_limit=2)
    a.send(_status(0), reliable=True)
    a.send(_status(1), reliable=True)
    with pytest.raises(OutboxFull, match=r"outbox full \(2 frames\): 'status' not queued"):
        a.send(_status(2), reliable=True)
    assert a.stats(0).dropped == 1


def test_heartbeat_when_idle_and_link_down_after_silence() -> None:
    """An idle session beats every heartbeat_s; the link is down 5 s after the peer fell silent."""
    a, b = _pair()
    assert a.is_up(4.9) and not a.is_up(5.0)
    assert [f.cmd for f in _frames(a.transmit(1.0))] == ["heartbeat"]
    assert a.transmit(1.5) == b""
    assert a.next_deadline(1.5) == pytest.approx(2.0)
    b.feed(a.transmit(7.0), 7.0)
    assert b.is_up(7.0)
    assert b.last_heard == 7.0 == b.stats(9.0).last_heard  # when, not whether


def test_stalled_link_stops_resending_and_resumes_when_peer_is_heard() -> None:
    """After max_tries unanswered sends the link is down and quiet; hearing the peer resumes."""
    a, b = _pair(max_tries=3, down_after_s=1000.0, heartbeat_s=999.0)
    a.send(_status(0), reliable=True)
    sends = 0
    for k in range(1, 400):
        out = a.transmit(k * 0.1)
        sends += sum(f.cmd == "status" for f in _frames(out)) if out else 0
        b.transmit(k * 0.1)  # b hears nothing, a hears nothing
        if k < 3:
            a.feed(b"", k * 0.1)
    assert sends == 3
    s = a.stats(40.0)
    assert s.stalls == 1 and not s.up
    a.feed(_encode([Frame("heartbeat", "beat", None)]), 40.0)
    assert [f.cmd for f in _frames(a.transmit(40.0))] == ["status"]


def test_reset_peer_restarts_in_order_reception() -> None:
    """After reset_peer(1) a rebooted peer's seq 1 is delivered, not dropped as duplicate."""
    a, b = _pair()
    for i in range(3):
        a.send(_status(i), reliable=True)
    b.feed(a.transmit(0.1), 0.1)
    assert b.ack_value == 3
    fresh = ReliableSession()
    b.reset_peer(fresh.seq_base)
    fresh.feed(b.transmit(0.2), 0.2)
    fresh.send(_status(9), reliable=True)
    assert [f.data["state"] for f in b.feed(fresh.transmit(0.3), 0.3)] == ["s9"]


def _three_delivered(session_id: int = 7) -> tuple[ReliableSession, ReliableSession]:
    """a (session ``session_id``) has announced itself to b and b took seq 1-3."""
    a, b = ReliableSession(session_id=session_id), ReliableSession(session_id=70)
    b.reset_peer(a.seq_base, a.session_id)
    a.feed(b.transmit(0.0), 0.0)
    for i in range(3):
        a.send(_status(i), reliable=True)
    assert [f.data["state"] for f in b.feed(a.transmit(0.1), 0.1)] == ["s0", "s1", "s2"]
    return a, b


def test_a_welcome_of_the_same_session_after_frames_at_its_seq_base_does_not_rewind() -> None:
    """A welcome (same session id) naming seq 1 after seq 1-3 were delivered keeps reception
    at 4: the next frame is delivered and acknowledged, and a resend of 2 stays a duplicate."""
    a, b = _three_delivered()
    stale_base = 1  # a's seq_base when it answered a hello that crossed seq 1-3
    a.feed(b.transmit(0.2), 0.2)  # ack 3: a drops 1-3 from its window for good
    assert a.stats(0.2).unacked == 0
    b.reset_peer(stale_base, a.session_id)
    assert b.ack_value == 3
    a.send(_status(3), reliable=True)
    assert [f.data["state"] for f in b.feed(a.transmit(0.3), 0.3)] == ["s3"]
    assert [f.ack for f in _frames(b.transmit(0.3))] == [4]
    resent = encode_frame(Frame("status", "status", {"state": "s1"}, seq=2))
    assert b.feed(resent, 0.4) == []
    assert b.stats(0.4).duplicates == 1


def test_the_same_session_with_a_higher_seq_base_skips_forward() -> None:
    """The same session naming a seq_base ahead of reception moves it there (never back)."""
    a, b = _three_delivered()
    b.reset_peer(6, a.session_id)
    assert b.ack_value == 5
    assert b.feed(encode_frame(Frame("status", "status", {"state": "x"}, seq=6)), 0.2) != []


def test_a_new_session_with_a_lower_seq_base_restarts_reception() -> None:
    """A rebooted peer (a new session id) saying seq_base 1 after 1-3 were delivered gets
    its new seq 1 delivered, not dropped as a duplicate."""
    a, b = _three_delivered()
    rebooted = ReliableSession(session_id=8)
    b.reset_peer(rebooted.seq_base, rebooted.session_id)
    assert b.ack_value == 0 and b.peer_session == 8
    rebooted.feed(b.transmit(0.2), 0.2)
    rebooted.send(_status(9), reliable=True)
    assert [f.data["state"] for f in b.feed(rebooted.transmit(0.3), 0.3)] == ["s9"]


@pytest.mark.parametrize("before", [None, 7], ids=["never-said", "said-before"])
def test_a_peer_without_a_session_restarts_reception_at_every_announcement(before) -> None:
    """An announcement without a session id restarts reception at seq_base, as it always
    did, whatever was said before (a peer whose firmware sends none)."""
    a, b = _three_delivered()
    b.reset_peer(1, before)
    b.reset_peer(1)
    assert b.ack_value == 0 and b.peer_session is None
    b.reset_peer(1)
    assert b.ack_value == 0
    again = encode_frame(Frame("status", "status", {"state": "n1"}, seq=1))
    assert [f.data["state"] for f in b.feed(again, 0.2)] == ["n1"]


def test_session_ids_are_deterministic_and_new_per_owner_and_instant() -> None:
    """session_id_for repeats for the same owner and instant and differs otherwise."""
    assert session_id_for("seeker", 12.5) == session_id_for("seeker", 12.5)
    ids = {session_id_for(o, t) for o in ("seeker", "hider") for t in (0.0, 12.5, 12.50001)}
    assert len(ids) == 6
    assert all(0 <= i < 2 ** 32 for i in ids)
    assert ReliableSession(now=3.0).session_id == session_id_for("", 3.0)


@pytest.mark.parametrize("bad", [-1, 2 ** 32])
def test_a_session_id_outside_32_bits_is_refused(bad: int) -> None:
    """session_id must fit 32 unsigned bits."""
    with pytest.raises(ValueError, match=rf"^session_id must be in \[0, 2\*\*32\), got {bad}$"):
        ReliableSession(session_id=bad)


def test_bad_lines_are_answered_and_counted() -> None:
    """Garbage gets one error frame per bad line naming the fault; the session stays usable."""
    a = ReliableSession()
    assert a.feed(b"garbage\n{\"cmd\":1}\n" + b"z" * 2000 + b"\n", 0.0) == []
    errors = _frames(a.transmit(0.0))
    assert [f.data["fault"] for f in errors] == ["not_json", "bad_frame", "too_long"]
    assert a.stats(0.0).bad_frames == 3


def test_bad_parameters_are_refused() -> None:
    """A heartbeat not shorter than the down time is a configuration error."""
    with pytest.raises(ValueError, match="need 0 < heartbeat_s < down_after_s, got 5, 5"):
        ReliableSession(heartbeat_s=5, down_after_s=5)


def test_a_reliable_frame_corrupted_inside_its_envelope_is_resent_not_lost() -> None:
    """A frame whose seq survives but whose cmd was corrupted is answered with error,
    not acknowledged nor delivered; the sender's resend then delivers the frame."""
    a, b = _pair()
    a.send(make_frame("destination", {"x": 200.0, "y": 150.0, "heading": None}))
    line = a.transmit(0.1)
    corrupted = line.replace(b'"destination"', b'"des?ination"')
    assert corrupted != line
    assert b.feed(corrupted, 0.1) == []
    reply = _frames(b.transmit(0.1))
    assert [f.cmd for f in reply] == ["error"]
    assert all(f.ack in (None, 0) for f in reply)
    a.feed(b"".join(encode_frame(f) for f in reply), 0.1)
    assert a.stats(0.1).unacked == 1
    got = _run(a, b, until=5.0)
    assert [(f.cmd, f.seq) for f in got] == [("destination", 1)]
    assert a.stats(5.0).unacked == 0
