"""A check's findings as people and programs read them: a table, or JSON."""

from __future__ import annotations

import json

from .rules import FAIL, PASS, RULES, SKIP, Finding

__all__ = ["summary", "as_json", "as_table"]


def summary(findings: list[Finding]) -> dict[str, int]:
    """How many rules passed, failed, were skipped."""
    return {"passed": sum(f.result == PASS for f in findings),
            "failed": sum(f.result == FAIL for f in findings),
            "skipped": sum(f.result == SKIP for f in findings)}


def as_json(findings: list[Finding]) -> str:
    """``{"rules": [{"rule", "result", "detail", "frames"}...], "passed", "failed",
    "skipped"}`` on one line."""
    return json.dumps({"rules": [f.as_json() for f in findings], **summary(findings)})


def as_table(findings: list[Finding], *, frames: bool = True) -> str:
    """One row per rule (result, rule, detail); under a failed rule the frames that show
    it (``frames``)."""
    width = max(len(r.id) for r in RULES)
    rows = []
    for f in findings:
        rows.append(f"{f.result.upper():4}  {f.rule:{width}}  {f.detail}")
        if frames and f.result == FAIL:
            rows += [f"      {'':{width}}  | {line}" for line in f.frames]
    s = summary(findings)
    rows.append(f"{s['passed']} passed, {s['failed']} failed, {s['skipped']} skipped")
    return "\n".join(rows)
