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
import trio.testing

from server.conformance import RULES, Options, check_rover, parse_rover_link
from server.conformance.rules import FAIL, PASS, SKIP
from tests.raw_client import free_port

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
    ("new_session", "hider", {"reconnect.resume", "resync.hello_first"}),
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


# -- the real rover, out of process ----------------------------------------------------

SPEED = 8  # the rover's and the checker's clock rate
SLACK = "1.0"  # timing bounds widened for a loaded host at x8 (the in-process tests are exact)
_ALWAYS_OPTIONAL = ("telemetry.", "fault.")  # run once the rover lists them, else skipped


def _hideseek(*argv: str, **kwargs) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-m", "tui.cli", *argv], cwd=ROOT, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, **kwargs)


def _judge_real(role: str, out: str, rc: int) -> None:
    """No rule fails; every rule of the role passes but the optional sections."""
    report = json.loads(out.strip().splitlines()[-1])
    results = {r["rule"]: r for r in report["rules"]}
    assert rc == 0 and report["failed"] == 0, [r for r in report["rules"]
                                              if r["result"] == FAIL]
    for rule, roles in ROLE_RULES.items():
        got = results[rule]["result"]
        if role not in roles:
            assert got == SKIP
        elif rule.startswith(_ALWAYS_OPTIONAL):
            assert got in (PASS, SKIP), results[rule]
        else:
            assert got == PASS, results[rule]
    assert report["passed"] + report["skipped"] == len(RULES)


def _stop(proc: subprocess.Popen) -> str:
    proc.send_signal(signal.SIGINT)
    out, _ = proc.communicate(timeout=20)
    return out


def test_hideseek_rover_over_tcp_passes_every_rule_it_supports() -> None:
    """``hideseek rover --role hider --link tcpin:`` (x8) checked over ``tcp:``: every rule
    of a hider passes; the sections it does not list are skipped."""
    port = free_port()
    rover = _hideseek("rover", "--role", "hider", "--scenario", "empty", "--link",
                      f"tcpin:127.0.0.1:{port}", "--speed", str(SPEED))
    try:
        for _ in range(100):  # until the rover listens
            check = subprocess.run(
                [sys.executable, "-m", "tui.cli", "check-rover", f"tcp:127.0.0.1:{port}",
                 "--role", "hider", "--speed", str(SPEED), "--slack", SLACK, "--json",
                 "--timeout", "300"],
                cwd=ROOT, capture_output=True, text=True, timeout=120)
            if check.returncode != 2:
                break
            time.sleep(0.2)
    finally:
        log = _stop(rover)
    assert check.returncode != 2, check.stderr
    _judge_real("hider", check.stdout, check.returncode)
    assert "lost the server" in log  # the link was dropped and made again


def test_hideseek_rover_over_a_pty_passes_every_rule_it_supports() -> None:
    """``hideseek rover --role mapper --link pty`` (x8) checked over ``serial:PTY,115200``:
    every rule of a mapper passes, the link dropped by closing and reopening the port."""
    rover = _hideseek("rover", "--role", "mapper", "--scenario", "empty", "--link", "pty",
                      "--speed", str(SPEED))
    try:
        path = ""
        assert rover.stdout is not None
        for line in rover.stdout:
            found = re.search(r"serial:(\S+),115200", line)
            if found:
                path = found.group(1)
                break
        assert path, "the rover printed no pty path"
        check = subprocess.run(
            [sys.executable, "-m", "tui.cli", "check-rover", f"serial:{path},115200", "--speed",
             str(SPEED), "--slack", SLACK, "--json", "--timeout", "300"],
            cwd=ROOT, capture_output=True, text=True, timeout=120)
    finally:
        _stop(rover)
    _judge_real("mapper", check.stdout, check.returncode)


@pytest.mark.parametrize(("link", "message"), [
    ("pty", "LINK must be tcp:HOST:PORT (connect to a rover waiting with --link tcpin:), "
            "tcpin:HOST:PORT (wait for a rover to connect), udpin:HOST:PORT or udp:HOST:PORT "
            "(receive its datagrams there) or serial:PORT[,BAUD] or PORT[,BAUD] (a serial "
            "port; a /dev/serial/by-id/ name survives a renumbered adapter), got 'pty'"),
    ("tcp:127.0.0.1:notaport", "tcp port must be a number, got 'notaport' in "
                               "'tcp:127.0.0.1:notaport'"),
    ("serial:/dev/hideseek-no-such-port,9600", "cannot open serial port "
     "/dev/hideseek-no-such-port at 9600 baud"),
])
def test_bad_or_unreachable_link_is_one_line_and_status_2(link, message) -> None:
    """A bad link string or a missing port: one line naming it, exit status 2."""
    done = subprocess.run([sys.executable, "-m", "tui.cli", "check-rover", link],
                          cwd=ROOT, capture_output=True, text=True, timeout=60)
    assert done.returncode == 2 and done.stdout == ""
    lines = done.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith("hideseek check-rover: ")
    assert message in lines[0]


def test_nothing_listening_at_a_tcp_link_is_status_2() -> None:
    """``tcp:`` to a port nobody listens on: one line naming the address, status 2."""
    port = free_port()
    done = subprocess.run([sys.executable, "-m", "tui.cli", "check-rover",
                           f"tcp:127.0.0.1:{port}"], cwd=ROOT, capture_output=True, text=True,
                          timeout=60)
    assert done.returncode == 2
    assert done.stderr.startswith(f"hideseek check-rover: cannot open tcp:127.0.0.1:{port}: ")


def test_the_package_exports_its_public_names() -> None:
    """What `server.conformance` promises is there."""
    import server.conformance as conformance

    for name in conformance.__all__:
        assert hasattr(conformance, name), name


def test_a_finding_names_a_rule_of_the_registry_and_a_failure_overrides_a_pass() -> None:
    """Unknown rule ids are refused; a rule checked twice keeps its failure."""
    from server.conformance.rules import Findings

    found = Findings()
    with pytest.raises(ValueError, match="rule must be one of the registry, got 'hello.nope'"):
        found.ok("hello.nope", "x")
    found.ok("ack.prompt", "fine")
    found.fail("ack.prompt", "late")
    found.ok("ack.prompt", "fine again")
    (ack,) = [f for f in found.final("not reached") if f.rule == "ack.prompt"]
    assert (ack.result, ack.detail) == (FAIL, "late")
    assert {f.result for f in found.final("not reached") if f.rule != "ack.prompt"} == {SKIP}


def test_a_rover_that_never_speaks_fails_hello_and_skips_the_rest(autojump_clock) -> None:
    """Nothing on the link: hello.first fails saying so, every other rule is skipped."""

    class Mute:
        spec = parse_rover_link("tcp:127.0.0.1:7")
        kind, can_drop, speaks_first = "tcp_out", True, False

        async def open(self, nursery, wait_s):
            self.pair = trio.testing.memory_stream_pair()
            return self.pair[0]

        async def aclose(self):
            pass

    async def main():
        return await check_rover(Mute(), Options(connect_s=3.0))

    findings, _ = trio.run(main, clock=autojump_clock)
    by = {f.rule: f for f in findings}
    assert by["hello.first"].result == FAIL
    assert by["hello.first"].detail == "the rover sent nothing within 3 s"
    assert {f.result for f in findings if f.rule != "hello.first"} == {SKIP}
    assert by["ack.prompt"].detail == "not reached: the rover never spoke"


@pytest.mark.parametrize("kind", ["tcpin", "udp"])
def test_a_busy_listening_port_is_one_line_and_status_2(kind) -> None:
    """``tcpin:``/``udp:`` on a port in use: one line naming it, status 2, nothing printed."""
    with socket.socket(type=socket.SOCK_STREAM if kind == "tcpin" else socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        if kind == "tcpin":
            s.listen()
        port = s.getsockname()[1]
        done = subprocess.run([sys.executable, "-m", "tui.cli", "check-rover",
                               f"{kind}:127.0.0.1:{port}"], cwd=ROOT, capture_output=True,
                              text=True, timeout=60)
    assert (done.returncode, done.stdout) == (2, "")
    assert done.stderr == (f"hideseek check-rover: cannot open {kind}:127.0.0.1:{port}: "
                           "Address already in use\n")
