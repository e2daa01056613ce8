"""The clock-free helpers that bound hostile peers: per-address backoff, burst counting."""

from __future__ import annotations

from server.guard import BurstLog, PeerBackoff


def test_peer_backoff_blocks_after_threshold_and_doubles() -> None:
    """Five failures block for 1 s, the next five for 2 s ...; success forgets the address."""
    b = PeerBackoff(threshold=5, first_s=1.0, most_s=4.0)
    assert [b.failed("a", 0.0) for _ in range(5)] == [0, 0, 0, 0, 1.0]
    assert b.blocked_for("a", 0.5) == 0.5 and b.blocked_for("b", 0.5) == 0
    assert [b.failed("a", 2.0) for _ in range(5)][-1] == 2.0
    assert [b.failed("a", 5.0) for _ in range(5)][-1] == 4.0
    assert [b.failed("a", 9.0) for _ in range(5)][-1] == 4.0  # capped at most_s
    b.succeeded("a")
    assert b.blocked_for("a", 9.5) == 0 and len(b) == 0


def test_peer_backoff_table_is_bounded() -> None:
    """A flood of addresses forgets the least recently seen."""
    b = PeerBackoff(capacity=100)
    for k in range(10_000):
        b.failed(f"10.0.{k // 256}.{k % 256}", 0.0)
    assert len(b) == 100


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
