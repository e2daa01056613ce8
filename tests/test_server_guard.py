"""The clock-free helpers that bound hostile peers: per-address backoff, burst counting."""

from __future__ import annotations

from server.guard import BurstLog, PeerBackoff


def test_peer_backoff_blocks_after_threshold_and_doubles() -> None:
    """Five failures block for 1 s, the next five for 2 s ...; a success after the block
    forgets the address, one during it does not end it."""
    b = PeerBackoff(threshold=5, first_s=1.0, most_s=4.0)
    assert [b.failed("a", 0.0) for _ in range(5)] == [0, 0, 0, 0, 1.0]
    assert b.blocked_for("a", 0.5) == 0.5 and b.blocked_for("b", 0.5) == 0
    assert [b.failed("a", 2.0) for _ in range(5)][-1] == 2.0
    assert [b.failed("a", 5.0) for _ in range(5)][-1] == 4.0
    assert [b.failed("a", 9.0) for _ in range(5)][-1] == 4.0  # capped at most_s
    b.succeeded("a", 10.0)  # blocked until 13 s: a token-holder sharing the address
    assert b.blocked_for("a", 12.5) == 0.5
    b.succeeded("a", 13.0)
    assert b.blocked_for("a", 13.0) == 0 and len(b) == 0


def test_peer_backoff_table_is_bounded() -> None:
    """A flood of addresses forgets the least recently seen: the table holds the last
    100 addresses that failed, each still blocked, and none of the earlier ones."""
    b = PeerBackoff(threshold=1, first_s=60.0, capacity=100)
    addrs = [f"10.0.{k // 256}.{k % 256}" for k in range(10_000)]
    for a in addrs:
        b.failed(a, 0.0)
    assert len(b) == 100
    assert [a for a in addrs if b.blocked_for(a, 1.0) > 0] == addrs[-100:]


def test_peer_backoff_forgets_the_least_recently_seen_first() -> None:
    """A failure makes an address the most recently seen: at the cap the table forgets
    the address whose last failure is oldest, not the first one it learned."""
    b = PeerBackoff(threshold=1, first_s=60.0, capacity=3)
    for a in ("a", "b", "c"):
        b.failed(a, 0.0)
    b.failed("a", 1.0)  # a seen again: b is now the least recently seen
    b.failed("d", 2.0)
    assert {a for a in "abcd" if b.blocked_for(a, 3.0) > 0} == {"a", "c", "d"}
    b.failed("e", 3.0)
    assert {a for a in "abcde" if b.blocked_for(a, 4.0) > 0} == {"a", "d", "e"}
    b.failed("f", 4.0)
    assert {a for a in "abcdef" if b.blocked_for(a, 5.0) > 0} == {"d", "e", "f"}


def test_burst_log_reports_the_first_then_one_summary_per_interval() -> None:
    """The first occurrence is reported at once; the rest come as one summary when due."""
    log = BurstLog(interval_s=10.0, links=2)
    assert log.add("bad_frame", "not_json", "tcp:a", 0.0)
    assert not any(log.add("bad_frame", "not_json" if k % 2 else "too_long", f"tcp:{k % 50}",
                           1.0) for k in range(1000))
    assert log.due(5.0) == [] and log.next_due() == 10.0
    assert log.due(10.0) == ["bad_frame"]
    summary = log.take("bad_frame", 10.0)
    assert summary["count"] == 1000 and summary["faults"] == {"not_json": 500, "too_long": 500}
    assert len(summary["busiest"]) == 2 and summary["links"] <= 9  # 8 named + "other links"
    assert log.pending() == [] and log.total["bad_frame"] == 1001
    assert not log.add("bad_frame", "not_json", "tcp:a", 12.0)  # within the interval
    assert log.add("auth_failed", "auth", "tcp:a", 12.0)  # another kind: its own burst
