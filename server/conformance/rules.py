"""The rules `check_rover` checks: a registry, and the findings of one check.

Each rule is one sentence of docs/protocol.md (or of the telemetry and fault
sections) that a rover's behaviour on the link can show or refute. A check
ends with one `Finding` per rule: ``pass``, ``fail`` or ``skip`` (the rover
does not advertise what the rule needs, or an earlier failure left nothing to
check), a detail line, and the frames that show it.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from .peer import Seen

__all__ = ["Rule", "RULES", "RULE_IDS", "PASS", "FAIL", "SKIP", "Finding", "Findings"]

PASS, FAIL, SKIP = "pass", "fail", "skip"


@dataclass(frozen=True, slots=True)
class Rule:
    """One checked rule."""

    id: str
    """Its name in reports, ``group.name``."""
    text: str
    """What a rover must do, in one sentence."""
    roles: tuple[str, ...] = ("mapper", "hider", "seeker")
    """The roles it applies to (skipped for the others)."""


RULES: tuple[Rule, ...] = (
    Rule("hello.first", "the first frame is a well-formed hello (id, role, seq_base), and "
         "nothing but hello leaves before the welcome"),
    Rule("hello.repeat", "an unanswered hello is said again, at most 8 s later"),
    Rule("hello.welcome", "after the welcome the rover stops saying hello and starts its "
         "session"),
    Rule("seq.numbering", "reliable frames carry seq, counted up by one from hello's "
         "seq_base without a gap; unreliable frames never carry seq"),
    Rule("ack.prompt", "every reliable frame of the server is acknowledged within 0.5 s, "
         "a bare ack always carries its ack field, and no ack names a seq never sent"),
    Rule("resend.same", "an unacknowledged reliable frame is resent with the same seq, cmd, "
         "type and data"),
    Rule("resend.timeout", "resends wait at least 0.3 s, double on every try, at most 8 s"),
    Rule("duplicate.suppressed", "a reliable frame received again (seq already acknowledged) "
         "is acknowledged again and not acted on twice"),
    Rule("heartbeat.interval", "after the welcome the rover is never silent for more than "
         "1 s; heartbeats are heartbeat/beat/null without seq"),
    Rule("mapping.start_stop", "a mapper told start and then stop uploads the map it has",
         ("mapper",)),
    Rule("map.upload", "an uploaded map is one map_id, the same header on every chunk, "
         "base64 pieces of at most 640 characters, count pieces, its CRC and runs right",
         ("mapper",)),
    Rule("map.download", "a hider or seeker asks for the map on start (map_request) and "
         "acknowledges every chunk of it", ("hider", "seeker")),
    Rule("report.hide", "a hider answers a destination with arrived or invalid_spot, "
         "reliably and well-formed", ("hider",)),
    Rule("report.seek", "a seeker answers a destination with found or not_found, reliably "
         "and well-formed", ("seeker",)),
    Rule("reconnect.resume", "after the link drops the rover says hello again with its "
         "oldest unacknowledged seq as seq_base (and its first hello's session, if it said "
         "one) and resends that frame"),
    Rule("resync.hello_first", "'send hello first' is answered with hello (seq_base right, "
         "session unchanged); the rover then follows welcome.seq_base of a new server "
         "session and resends what was unacknowledged"),
    Rule("malformed.answered", "a line that is not a frame, too long, of an unknown cmd or "
         "a wrong type is answered with an error frame naming the fault"),
    Rule("malformed.reliable", "a reliable frame whose data does not fit is answered "
         "bad_data and not acknowledged; the same seq sent right is"),
    Rule("malformed.survives", "after malformed lines the rover keeps the link: it goes on "
         "sending and acknowledging"),
    Rule("telemetry.asked", "telemetry only after the welcome, only of the streams it "
         "asked for, and only of streams hello listed"),
    Rule("telemetry.frames", "telemetry frames never carry seq, fit 1024 bytes, and have "
         "the cmd, type and data of their stream"),
    Rule("telemetry.rate", "each stream at most as often as asked, all of it within the "
         "welcome's telemetry_share of the link"),
    Rule("fault.reply", "every fault command gets exactly one fault_reply with its "
         "fault_id, sent reliably"),
    Rule("fault.opt_in", "faults hello lists are accepted, unknown ones unsupported; a "
         "rover that lists none refuses every fault"),
)
"""Every rule, in report order."""

RULE_IDS = tuple(r.id for r in RULES)


@dataclass(frozen=True, slots=True)
class Finding:
    """The outcome of one rule."""

    rule: str
    result: str
    """``pass``, ``fail`` or ``skip``."""
    detail: str
    frames: tuple[str, ...] = ()
    """The lines that show it (`Seen.show`), at most a few."""

    def as_json(self) -> dict:
        return {"rule": self.rule, "result": self.result, "detail": self.detail,
                "frames": list(self.frames)}


@dataclass
class Findings:
    """The findings of one check, by rule; the first word on a rule stands, except that
    a failure overrides a pass (a rule checked in two places)."""

    by_rule: dict[str, Finding] = field(default_factory=dict)

    def put(self, rule: str, result: str, detail: str, frames: list[Seen] | tuple = ()) -> None:
        """Record ``result`` for ``rule`` with the lines that show it (at most 6)."""
        if rule not in RULE_IDS:
            raise ValueError(f"rule must be one of the registry, got {rule!r}")
        old = self.by_rule.get(rule)
        if old is not None and not (old.result == PASS and result == FAIL):
            return
        shown = tuple(s.show() if isinstance(s, Seen) else str(s) for s in list(frames)[:6])
        self.by_rule[rule] = Finding(rule, result, detail, shown)

    def ok(self, rule: str, detail: str, frames: list[Seen] | tuple = ()) -> None:
        self.put(rule, PASS, detail, frames)

    def fail(self, rule: str, detail: str, frames: list[Seen] | tuple = ()) -> None:
        self.put(rule, FAIL, detail, frames)

    def skip(self, rule: str, detail: str) -> None:
        self.put(rule, SKIP, detail)

    def has(self, rule: str) -> bool:
        """Whether ``rule`` has a finding yet."""
        return rule in self.by_rule

    def final(self, why_missing: str) -> list[Finding]:
        """Every rule in registry order; a rule with no finding is skipped with
        ``why_missing``."""
        return [self.by_rule.get(r.id) or Finding(r.id, SKIP, why_missing) for r in RULES]
