"""Campaign options and game references: what names a campaign game.

Game ``i`` of campaign ``S`` is a pure function of ``(S, i)`` and the
campaign's options (`CampaignConfig`), so every game is reproducible from a
short reference, ``S:i[,key=value...]`` (`CampaignConfig.game_ref`), which
`parse_game_ref` reads back and ``hideseek run --campaign REF`` plays with
the same trace hash.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

from supervisors.harness.headless import Budget
from world.faults import ACTOR_FAULTS, DEVICE_FAULTS
from world.scenario import ROOM_FAMILIES, ScenarioError, builtin_scenarios

MODES = ("single", "overlapping", "none")
#: every fault kind a campaign draws from: ``device:kind`` or ``actor:kind``
FAULT_LABELS: tuple[str, ...] = tuple(
    [f"{dev}:{kind}" for dev, kinds in DEVICE_FAULTS.items()
     if not dev.endswith(("_left", "_right")) for kind in kinds]
    + [f"actor:{kind}" for kind in ACTOR_FAULTS])

MAX_GAMES = 1_000_000       # games per campaign at most


class CampaignError(ScenarioError):
    """Bad campaign options or game reference; the message is fit to show a user.

    A `ScenarioError` (so a `ValueError`): a game reference names a scenario.
    """


def select_kinds(text: str | None) -> tuple[str, ...]:
    """Fault labels chosen by a comma list (None or ``all``: every label).

    An item is a label (``wifly:loss``), a device or ``actor`` (every kind on
    it: ``wifly``), or a kind (``crash``, ``stuck``: on every device that has it).

    Raises:
        CampaignError: an item matches no label.
    """
    if text is None or text.strip() in ("", "all"):
        return FAULT_LABELS
    chosen: list[str] = []
    for item in (p.strip() for p in text.replace("+", ",").split(",")):
        if not item:
            continue
        hits = [lab for lab in FAULT_LABELS
                if item in (lab, lab.split(":")[0], lab.split(":")[1])]
        if not hits:
            raise CampaignError(f"unknown fault kind {item!r}; kinds are "
                                f"{', '.join(FAULT_LABELS)} (or a device, or 'actor')")
        chosen += [h for h in hits if h not in chosen]
    if not chosen:
        raise CampaignError(f"no fault kind chosen in {text!r}")
    return tuple(lab for lab in FAULT_LABELS if lab in chosen)


@dataclass(frozen=True, slots=True)
class CampaignConfig:
    """What determines a campaign's games, besides the game index."""

    seed: int
    mode: str = "single"
    """``single`` (one fault per game), ``overlapping`` (0..3) or ``none``."""
    kinds: tuple[str, ...] = FAULT_LABELS
    """Fault labels to draw from (`select_kinds`)."""
    rooms: tuple[str, ...] = ()
    """Built-in scenario names, round-robin (empty: every built-in)."""
    generated: bool = False
    """Procedural rooms (`generate_scenario(seed, i, family)`) instead of built-ins."""
    family: str = ROOM_FAMILIES[0]
    """The procedural rooms' family (`world.scenario.ROOM_FAMILIES`); another than the
    default makes the rooms procedural."""
    window_s: tuple[float, float] = (5.0, 240.0)
    """Simulated time range in which faults start [s]."""
    mapping_budget_s: float = 1200.0
    """Simulated time allowed for mapping [s] (as ``hideseek run --budget``)."""
    swarm: bool = False
    """Swarm testing: each game draws its own subset of ``kinds`` and its own device
    parameters (link speed, sensor noise) from its seed (`supervisors.harness.campaign.plan`)."""
    _builtins: tuple[str, ...] = field(default=(), init=False, repr=False, compare=False)
    """Every built-in room, read once here (reading them parses each file)."""

    def __post_init__(self) -> None:
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise CampaignError(f"seed must be an integer >= 0, got {self.seed!r}")
        if self.mode not in MODES:
            raise CampaignError(f"mode must be {', '.join(MODES)}, got {self.mode!r}")
        bad = [k for k in self.kinds if k not in FAULT_LABELS]
        if bad or not self.kinds:
            raise CampaignError(f"fault kinds must be among {', '.join(FAULT_LABELS)}, "
                                f"got {', '.join(bad) or 'none'}")
        known = tuple(builtin_scenarios())
        object.__setattr__(self, "_builtins", known)  # frozen: set once, at construction
        for name in self.rooms:
            if name not in known:
                raise CampaignError(f"unknown built-in room {name!r}; rooms are "
                                    f"{', '.join(known)}")
        lo, hi = self.window_s
        if not 0 <= lo <= hi or not math.isfinite(hi):
            raise CampaignError(f"fault window must be 0 <= start <= end, got {lo}-{hi}")
        if self.family not in ROOM_FAMILIES:
            raise CampaignError(f"room family must be one of {', '.join(ROOM_FAMILIES)}, "
                                f"got {self.family!r}")
        if self.family != ROOM_FAMILIES[0]:
            if self.rooms:
                raise CampaignError("a room family is for generated rooms, not built-in ones")
            object.__setattr__(self, "generated", True)  # frozen: set once, at construction
        if not isinstance(self.swarm, bool):
            raise CampaignError(f"swarm must be True or False, got {self.swarm!r}")
        if not 0 < self.mapping_budget_s <= 1e6:
            raise CampaignError(f"mapping budget must be within (0, 1e6] s, "
                                f"got {self.mapping_budget_s!r}")

    def room_names(self) -> tuple[str, ...]:
        """The built-in rooms used, in round-robin order."""
        return self.rooms or self._builtins

    def budget(self) -> Budget:
        """Simulated-time budget of each game."""
        return Budget(mapping=self.mapping_budget_s)

    def game_ref(self, index: int) -> str:
        """``S:i`` plus every option that differs from the default: what reproduces game i."""
        parts = [f"{self.seed}:{index}"]
        default = CampaignConfig(0)
        if self.mode != default.mode:
            parts.append(f"mode={self.mode}")
        if self.generated:
            parts.append("rooms=generated")
            if self.family != default.family:
                parts.append(f"family={self.family}")
        elif self.rooms:
            parts.append("rooms=" + "+".join(self.rooms))
        if self.kinds != default.kinds:
            parts.append("faults=" + "+".join(self.kinds))
        if self.window_s != default.window_s:
            parts.append(f"window={self.window_s[0]:g}-{self.window_s[1]:g}")
        if self.mapping_budget_s != default.mapping_budget_s:
            parts.append(f"budget={self.mapping_budget_s:g}")
        if self.swarm:
            parts.append("swarm=on")
        return ",".join(parts)


def parse_game_ref(text: str) -> tuple[CampaignConfig, int]:
    """Read a game reference ``S:i[,mode=..][,rooms=..][,faults=..][,window=A-B][,budget=..]...``.

    Options: ``mode``, ``rooms``, ``family``, ``faults``, ``window``, ``budget``, ``swarm``
    (``on``).

    Raises:
        CampaignError: malformed reference or bad option.
    """
    if not isinstance(text, str) or not text.strip():
        raise CampaignError("game reference must be S:i[,key=value...], got nothing")
    head, *options = text.strip().split(",")
    try:
        seed_s, index_s = head.split(":")
        seed, index = int(seed_s), int(index_s)
    except ValueError:
        raise CampaignError(f"game reference must start with SEED:INDEX, got {head!r}") from None
    if not 0 <= index < MAX_GAMES:
        raise CampaignError(f"game index must be within 0..{MAX_GAMES - 1}, got {index}")
    kw: dict[str, Any] = {}
    for opt in options:
        key, sep, value = opt.partition("=")
        if not sep:
            raise CampaignError(f"game reference option must be key=value, got {opt!r}")
        try:
            if key == "mode":
                kw["mode"] = value
            elif key == "rooms" and value == "generated":
                kw["generated"] = True
            elif key == "rooms":
                kw["rooms"] = tuple(v for v in value.split("+") if v)
            elif key == "family":
                kw["family"] = value
            elif key == "faults":
                kw["kinds"] = select_kinds(value)
            elif key == "window":
                lo, hi = value.split("-")
                kw["window_s"] = (float(lo), float(hi))
            elif key == "budget":
                kw["mapping_budget_s"] = float(value)
            elif key == "swarm" and value in ("on", "off"):
                kw["swarm"] = value == "on"
            elif key == "swarm":
                raise CampaignError(f"game reference option swarm must be on or off, "
                                    f"got {value!r}")
            else:
                raise CampaignError(f"unknown game reference option {key!r} (options: mode, "
                                    "rooms, family, faults, window, budget, swarm)")
        except ValueError as exc:
            if isinstance(exc, CampaignError):
                raise
            raise CampaignError(f"bad game reference option {opt!r}: {exc}") from None
    return CampaignConfig(seed, **kw), index
