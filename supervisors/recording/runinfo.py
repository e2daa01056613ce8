"""What a recording says about its run: enough to play the same game again.

A `RunInfo` names how the scenario was made (``builtin:NAME``, ``file:PATH``
with the file's TOML text kept, ``generated:[FAMILY:]SEED:INDEX`` or
``campaign:REF``), the seed, the mapping budget and the code version, plus the
changes a fork made (extra faults, another hide spot or other guesses). It is
written as the recording's ``hideseek.run`` metadata record and read back by
`RunInfo.from_metadata`; `RunInfo.scenario` rebuilds the scenario the game was
played on, changes included.
"""

from __future__ import annotations

import dataclasses
import json
import pathlib
import subprocess
from dataclasses import dataclass, field
from typing import Any

from world.scenario import (
    Pose,
    Scenario,
    ScenarioError,
    ScheduledFault,
    generate_scenario,
    load_scenario,
    parse_generated,
    parse_scenario,
)

__all__ = ["RunInfo", "code_version", "scenario_text"]

_ROOT = pathlib.Path(__file__).resolve().parent.parent.parent


def code_version() -> str:
    """``git describe --always --dirty`` of the source tree, or ``unknown`` outside git."""
    try:
        out = subprocess.run(["git", "-C", str(_ROOT), "describe", "--always", "--dirty"],
                             capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return "unknown"
    return out.stdout.strip() if out.returncode == 0 and out.stdout.strip() else "unknown"


def scenario_text(scenario: Scenario) -> str:
    """The TOML text a scenario was read from ("" when it was not read from a file)."""
    source = scenario.source
    if source.startswith("builtin:"):
        from importlib import resources  # noqa: PLC0415

        res = resources.files("world.scenarios").joinpath(f"{source[8:]}.toml")
        return res.read_text(encoding="utf-8") if res.is_file() else ""
    path = pathlib.Path(source)
    if source and path.suffix == ".toml" and path.is_file():
        return path.read_text(encoding="utf-8")
    return ""


@dataclass(frozen=True, slots=True)
class RunInfo:
    """How one headless game was made (see the module docstring)."""

    scenario_ref: str
    """``builtin:NAME``, ``file:PATH``, ``generated:[FAMILY:]SEED:INDEX`` or ``campaign:REF``."""
    seed: int
    """The run's seed (the world's noise, the actors' generators, Trio's task order)."""
    budget_s: float = 1200.0
    """Simulated seconds allowed for mapping."""
    toml: str = ""
    """The scenario file's text (``builtin:`` and ``file:`` refs)."""
    operator: str = "headless"
    """``headless`` (the scenario's choices) or ``console`` (a person's: not re-playable)."""
    code: str = field(default_factory=code_version)
    """The code version that played it."""
    extra_faults: tuple[ScheduledFault, ...] = ()
    """Faults a fork added to the schedule."""
    hide_at: tuple[float, float, float] | None = None
    """A fork's hide spot instead of the scenario's (room frame [cm, deg])."""
    seek_at: tuple[tuple[float, float], ...] | None = None
    """A fork's guesses instead of the scenario's (room frame [cm])."""

    @classmethod
    def for_scenario(cls, scenario: Scenario, seed: int, *, budget_s: float = 1200.0,
                     campaign: str | None = None, operator: str = "headless") -> RunInfo:
        """The info of a run of ``scenario`` (``campaign``: the game's campaign reference)."""
        if campaign:
            return cls(f"campaign:{campaign}", seed, budget_s, operator=operator)
        source = scenario.source
        if source.startswith("generated:"):
            s, _, i = source[10:].replace("/", ":").partition(":")
            return cls(f"generated:{s}:{i}", seed, budget_s, operator=operator)
        ref = source if source.startswith("builtin:") else f"file:{source}"
        return cls(ref, seed, budget_s, toml=scenario_text(scenario), operator=operator)

    def scenario(self) -> Scenario:
        """The scenario the game was played on, a fork's changes applied.

        Raises:
            ScenarioError: the reference cannot be rebuilt (a built-in scenario whose
                text changed since, a malformed reference).
        """
        kind, _, rest = self.scenario_ref.partition(":")
        if kind == "campaign":
            from supervisors.harness.campaign import game_from_ref  # noqa: PLC0415

            base = game_from_ref(rest)[0]
        elif kind == "generated":
            try:
                base = generate_scenario(*parse_generated(rest))
            except ScenarioError:
                raise ScenarioError(f"recording: bad scenario reference {self.scenario_ref!r}"
                                    ) from None
        elif kind == "builtin":
            base = load_scenario(rest)
            if self.toml and scenario_text(base) != self.toml:
                raise ScenarioError(f"recording: the built-in scenario {rest!r} changed since "
                                    "the recording was made")
        elif kind == "file" and self.toml:
            base = parse_scenario(self.toml, rest)
        else:
            raise ScenarioError(f"recording: cannot rebuild scenario {self.scenario_ref!r}")
        changes: dict[str, Any] = {}
        if self.extra_faults:
            changes["faults"] = tuple(sorted(base.faults + self.extra_faults,
                                             key=lambda f: f.at_s))
        if self.hide_at is not None:
            changes["hide_at"] = Pose(*self.hide_at)
        if self.seek_at is not None:
            changes["seek_at"] = tuple(self.seek_at)
        return dataclasses.replace(base, **changes) if changes else base

    # ---------------------------------------------------------------- metadata
    def to_metadata(self) -> dict[str, str]:
        """The ``hideseek.run`` metadata record (MCAP metadata values are strings)."""
        return {
            "scenario_ref": self.scenario_ref, "seed": str(self.seed),
            "budget_s": repr(self.budget_s), "operator": self.operator, "code": self.code,
            "extra_faults": json.dumps([dataclasses.asdict(f) for f in self.extra_faults]),
            "hide_at": json.dumps(self.hide_at), "seek_at": json.dumps(self.seek_at),
        }

    @classmethod
    def from_metadata(cls, run: dict[str, str], toml: str = "") -> RunInfo:
        """Read back `to_metadata` (``toml``: the ``hideseek.scenario`` record's text).

        Raises:
            ValueError: a field is missing or malformed.
        """
        try:
            faults = tuple(ScheduledFault(**f) for f in json.loads(run.get("extra_faults", "[]")))
            hide = json.loads(run.get("hide_at", "null"))
            seek = json.loads(run.get("seek_at", "null"))
            return cls(run["scenario_ref"], int(run["seed"]), float(run["budget_s"]), toml,
                       run.get("operator", "headless"), run.get("code", "unknown"), faults,
                       None if hide is None else tuple(hide),
                       None if seek is None else tuple(tuple(g) for g in seek))
        except (KeyError, TypeError, ValueError) as exc:
            raise ValueError(f"recording: bad hideseek.run metadata: {exc}") from None
