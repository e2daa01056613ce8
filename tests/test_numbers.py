"""Every number of the firmware counted: each classified, the policy numbers bounded,
and docs/tunables.md the one the code generates (`benchmarks.tunables`)."""

from __future__ import annotations

from benchmarks import tunables

MAX_POLICY = 40
"""Policy numbers (thresholds of hand-tuned rules) in the firmware, at most: a new one
replaces one, or is shown to be physical, structural or derived."""


def test_every_firmware_number_is_classified() -> None:
    """Each module-level, class-level and option-field number of ``actors/firmware`` has a
    kind (derived, physical, structural, policy), and `tunables.KINDS` names no number
    the code no longer has."""
    found = tunables.numbers()
    assert len(found) > 200  # the scan reached every module
    assert [f"{n.owner}.{n.name}" for n in found if tunables.classify(n) is None] == []
    typed = {(n.owner, n.name) for n in found if not n.computed}
    stale = [f"{owner}.{name}" for owner, names in tunables.KINDS.items() for name in names
             if (owner, name) not in typed]
    assert stale == []


def test_the_policy_numbers_are_bounded() -> None:
    """At most ``MAX_POLICY`` policy numbers."""
    kinds = [tunables.classify(n) for n in tunables.numbers()]
    assert kinds.count("policy") <= MAX_POLICY


def test_a_computed_number_is_derived_and_a_typed_one_is_not() -> None:
    """``derived`` is read from the code (an expression, not a literal): a number computed
    from others is derived whatever the table says; the table's kinds are the other three."""
    found = {(n.owner, n.name): n for n in tunables.numbers()}
    assert tunables.classify(found[("nav.sensor_watch", "ODO_HOLD_MAX_S")]) == "derived"
    assert tunables.classify(found[("nav.recovery", "REPLAN_LIMIT")]) == "structural"
    assert {k for names in tunables.KINDS.values() for k in names.values()} <= {
        "physical", "structural", "policy"}


def test_docs_tunables_is_generated_from_the_code() -> None:
    """docs/tunables.md is what ``python -m benchmarks.tunables`` writes now."""
    assert tunables.DOC.read_text(encoding="utf-8") == tunables.render()
    assert tunables.main(["--check"]) == 0
