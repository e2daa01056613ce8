"""``hideseek check-rover`` (`server.conformance`): every rule judged against rovers that
keep it and rovers that break it.

In-process: a `TestRover` joined to the checker over memory streams, in virtual
time. Out of process: the real ``hideseek rover`` over TCP and over a pty, at x8.
"""

from __future__ import annotations

import json
import pathlib
import re
import signal
import socket
import subprocess
import sys
import time

import pytest
import trio

from server.conformance import RULES, Options, check_rover, parse_rover_link
from server.conformance.rules import FAIL, PASS, SKIP

from .conformance_rover import BREAKS, STREAMS, PairLink, TestRover

ROOT = pathlib.Path(__file__).resolve().parent.parent
ROLE_RULES = {r.id: r.roles for r in RULES}


async def _check(rover: TestRover, **opts) -> dict[str, str]:
    link = PairLink()
    async with trio.open_nursery() as nursery:
        nursery.start_soon(rover.run, link)
        findings, _ = await check_rover(link, Options(**opts))
        nursery.cancel_scope.cancel()
    return {f.rule: f.result for f in findings} | {"_detail": {f.rule: f.detail
                                                               for f in findings}}


def _expected(role: str, failing: set[str] = frozenset()) -> dict[str, str]:
    return {rule: FAIL if rule in failing else PASS if role in roles else SKIP
            for rule, roles in ROLE_RULES.items()}


def _results(got: dict) -> dict[str, str]:
    return {k: v for k, v in got.items() if k != "_detail"}


@pytest.mark.parametrize("role", ["mapper", "hider", "seeker"])
@pytest.mark.trio
async def test_a_rover_that_keeps_every_rule_passes_every_rule(autojump_clock, role) -> None:
    """Telemetry and faults included (listed in hello, opt-in given): all pass."""
    got = await _check(TestRover(role), role=role)
    assert _results(got) == _expected(role), got["_detail"]


@pytest.mark.trio
async def test_a_rover_without_the_opt_in_passes_by_refusing_every_fault(autojump_clock) -> None:
    """faults: [] in hello: every fault must be refused or unsupported, and is."""
    got = await _check(TestRover("hider", accept_faults=False))
    assert got["fault.opt_in"] == PASS and got["fault.reply"] == PASS
    assert got["_detail"]["fault.opt_in"] == "every fault refused (no opt-in)"


@pytest.mark.trio
async def test_telemetry_and_fault_rules_are_skipped_when_hello_lists_neither(
        autojump_clock) -> None:
    """No streams, no faults field: those rules are skipped with the reason, others pass."""
    got = await _check(TestRover("mapper", streams=None, faults=False))
    for rule in ("telemetry.asked", "telemetry.frames", "telemetry.rate", "fault.reply",
                 "fault.opt_in"):
        assert got[rule] == SKIP, rule
        assert got["_detail"][rule].startswith("hello lists no")
    assert not [r for r, v in _results(got).items() if v == FAIL]


BROKEN = [
    ("chatter", "hider", {"hello.first"}),
    ("late_acks", "hider", {"ack.prompt"}),
    ("resend_changes", "hider", {"resend.same"}),
    ("no_backoff", "mapper", {"resend.timeout"}),
    ("no_dedup", "hider", {"duplicate.suppressed"}),
    ("no_dedup", "mapper", {"duplicate.suppressed"}),
    ("no_heartbeat", "seeker", {"heartbeat.interval"}),  # without telemetry, below
    ("crash_on_malformed", "hider", {"malformed.answered", "malformed.survives"}),
    ("big_chunks", "mapper", {"map.upload"}),
    ("oversized_telemetry", "mapper", {"telemetry.frames"}),
    ("unasked_stream", "seeker", {"telemetry.asked"}),
    ("fault_without_opt_in", "hider", {"fault.opt_in"}),
]


def test_every_broken_rover_is_tested() -> None:
    """Each way of breaking a rule in `BREAKS` has its case."""
    assert {b for b, _, _ in BROKEN} == set(BREAKS) - {""}


@pytest.mark.parametrize(("breaks", "role", "failing"), BROKEN,
                         ids=[f"{b}-{r}" for b, r, _ in BROKEN])
@pytest.mark.trio
async def test_a_rover_that_breaks_one_rule_fails_that_rule_only(autojump_clock, breaks, role,
                                                                 failing) -> None:
    """The broken rule fails, naming what it saw; every other rule keeps its result."""
    quiet = breaks == "no_heartbeat"  # telemetry would fill its silences
    rover = TestRover(role, breaks=breaks, accept_faults=breaks != "fault_without_opt_in",
                      streams=None if quiet else STREAMS)
    got = await _check(rover)
    want = _expected(role, failing)
    if quiet:
        want |= {r: SKIP for r in ("telemetry.asked", "telemetry.frames", "telemetry.rate")}
    if breaks == "crash_on_malformed":
        want["malformed.reliable"] = SKIP  # nothing left to send it to
    assert _results(got) == want, got["_detail"]
