"""Planning: the game a campaign reference names, drawn from the campaign's seed.

`plan_game` is ``numpy.random.default_rng([S, i])`` drawing, in this order,
the game's run seed, then its fault schedule from the catalogue of
`FAULT_LABELS` (device faults of world/faults.py on a rover that has the
device, link faults, and crash/hang/flood on a firmware actor such as
``seeker/wifly``): exactly one fault per game in ``single`` mode, 0 to 3 in
``overlapping`` mode, none in ``none`` mode. Each fault has a start drawn in
the fault window and a duration (transient faults: permanent ones are what
docs/faults.md explains the system cannot survive). The room is a built-in
scenario chosen round-robin (its hide spot and guesses with it), or
``generate_scenario(S, i, family)``.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from supervisors.harness.campaign.refs import (
    MAX_GAMES,
    CampaignConfig,
    CampaignError,
    parse_game_ref,
)
from world.faults import ROLE_DEVICES
from world.params import ROLES
from world.scenario import Scenario, ScheduledFault, generate_scenario, load_scenario

#: firmware actors per role (supervisors/rover.py registers them as ``role/name``)
ACTORS_BY_ROLE: dict[str, tuple[str, ...]] = {
    "mapper": ("nav", "motor", "wifly", "lidar", "map"),
    "hider": ("nav", "motor", "wifly"),
    "seeker": ("nav", "motor", "wifly", "ir"),
}
#: devices named without a side in the labels; the side is drawn ("" = both treads)
_SIDED = ("encoder", "motor")
#: label -> (duration range [s], {parameter: (low, high)} drawn uniformly)
_DRAW: dict[str, tuple[tuple[float, float], dict[str, tuple[float, float]]]] = {
    "lidar:noisy": ((5.0, 30.0), {"sigma_cm": (5.0, 20.0)}),
    "encoder:slipping": ((2.0, 20.0), {"ratio": (0.3, 0.8)}),
    "motor:weak": ((2.0, 20.0), {"strength": (0.3, 0.8)}),
    "wifly:loss": ((5.0, 30.0), {"percent": (10.0, 50.0)}),
    "wifly:corrupt": ((5.0, 30.0), {"per_byte": (0.001, 0.02)}),
    "wifly:latency": ((5.0, 30.0), {"added_s": (0.1, 1.0)}),
    "actor:flood": ((0.0, 0.0), {"messages": (50.0, 500.0)}),
    "actor:crash": ((0.0, 0.0), {}),
    "actor:hang": ((2.0, 20.0), {}),
}
_DEFAULT_DRAW = ((2.0, 20.0), {})
_MAX_OVERLAP = 3            # faults at most per game in overlapping mode
#: swarm mode: device parameters each game draws, name -> (low, high) drawn uniformly, in the
#: field's units (world/params.py: noise [cm], odometry slip, IR noise [ADC counts], link
#: speed [bytes/s] and latency [s]); the defaults lie inside each range
SWARM_DEVICES: dict[str, tuple[float, float]] = {
    "lidar_noise_cm": (0.2, 2.0),
    "slip_sigma": (0.01, 0.05),
    "ir_noise": (10.0, 60.0),
    "wifly_bytes_s": (2880.0, 11520.0),
    "wifly_latency_s": (0.002, 0.05),
}


@dataclass(frozen=True, slots=True)
class GameSpec:
    """Everything that determines one campaign game (made by `plan_game`)."""

    config: CampaignConfig
    index: int
    run_seed: int
    """The seed the game runs with (world noise, actors, Trio's scheduling)."""
    room: str
    """A built-in scenario name, or ``generated``."""
    faults: tuple[ScheduledFault, ...]
    labels: tuple[str, ...]
    """The fault label of each fault, same order."""
    devices: tuple[tuple[str, float], ...] = ()
    """Device parameters this game overrides (swarm mode), as (name, value) pairs."""
    kinds: tuple[str, ...] = ()
    """The fault labels this game drew from (swarm mode: its own subset; else the campaign's)."""

    @property
    def ref(self) -> str:
        """The game reference (`CampaignConfig.game_ref`)."""
        return self.config.game_ref(self.index)

    @property
    def reproduce(self) -> str:
        """The command line that plays this game alone, with the same trace hash."""
        return f"hideseek run --campaign {self.ref}"

    def scenario(self) -> Scenario:
        """The room with this game's fault schedule."""
        base = (generate_scenario(self.config.seed, self.index, self.config.family)
                if self.room == "generated" else load_scenario(self.room))
        if self.devices:
            base = dataclasses.replace(base, devices={**base.devices, **dict(self.devices)})
        return dataclasses.replace(base, faults=tuple(sorted(
            base.faults + self.faults, key=lambda f: f.at_s)))


def _draw_fault(rng: np.random.Generator, label: str, window: tuple[float, float]
                ) -> ScheduledFault:
    device, kind = label.split(":")
    (d_lo, d_hi), ranges = _DRAW.get(label, _DEFAULT_DRAW)
    if device == "actor":
        role = ROLES[int(rng.integers(len(ROLES)))]
        names = ACTORS_BY_ROLE[role]
        target = f"{role}/{names[int(rng.integers(len(names)))]}"
    else:
        roles = ROLE_DEVICES.get(device, ROLES)
        role = roles[int(rng.integers(len(roles)))]
        side = ("", "_left", "_right")[int(rng.integers(3))] if device in _SIDED else ""
        target = f"{role}/{device}{side}"
    at = float(rng.uniform(*window))
    duration = float(rng.uniform(d_lo, d_hi)) if d_hi > 0 else 0.0
    params = {name: float(rng.uniform(lo, hi)) for name, (lo, hi) in ranges.items()}
    if "messages" in params:
        params["messages"] = float(round(params["messages"]))
    return ScheduledFault(round(at, 3), target, kind, round(duration, 3),
                          {k: round(v, 4) for k, v in params.items()})


def plan_game(config: CampaignConfig, index: int) -> GameSpec:
    """Game ``index`` of the campaign: a pure function of (config, index).

    Raises:
        CampaignError: the index is out of range.
    """
    if isinstance(index, bool) or not isinstance(index, int) or not 0 <= index < MAX_GAMES:
        raise CampaignError(f"game index must be within 0..{MAX_GAMES - 1}, got {index!r}")
    rng = np.random.default_rng([config.seed, index])
    run_seed = int(rng.integers(1, 2**31 - 1))
    kinds, devices = _swarm(rng, config.kinds) if config.swarm else (config.kinds, ())
    if config.mode == "single":
        n = 1
    elif config.mode == "overlapping":
        n = int(rng.integers(0, _MAX_OVERLAP + 1))
    else:
        n = 0
    labels = tuple(kinds[int(rng.integers(len(kinds)))] for _ in range(n))
    faults = tuple(_draw_fault(rng, lab, config.window_s) for lab in labels)
    if config.generated:
        room = "generated"
    else:
        names = config.room_names()
        room = names[index % len(names)]
    return GameSpec(config, index, run_seed, room, faults, labels, devices, kinds)


def _swarm(rng: np.random.Generator, kinds: tuple[str, ...]
           ) -> tuple[tuple[str, ...], tuple[tuple[str, float], ...]]:
    """A swarm game's own fault kinds (each kept with probability 1/2, at least one) and
    device parameters (`SWARM_DEVICES`).

    Swarm testing (Groce et al., ISSTA 2012): a fixed mix of every kind lets
    the kinds mask each other, while games that each leave some out reach
    more distinct failures. Drawn only in swarm mode, after the run seed,
    so other campaigns' games stay as they were.
    """
    kept = tuple(k for k, keep in zip(kinds, rng.random(len(kinds)) < 0.5, strict=True)
                 if keep)
    chosen = kept or (kinds[int(rng.integers(len(kinds)))],)
    devices = tuple((name, round(float(rng.uniform(lo, hi)), 4))
                    for name, (lo, hi) in SWARM_DEVICES.items())
    return chosen, devices


def game_from_ref(ref: str) -> tuple[Scenario, int, float]:
    """What ``hideseek run --campaign REF`` plays: (scenario with faults, run seed, budget [s]).

    Raises:
        CampaignError: a bad reference (a `ScenarioError`, so ``hideseek run``
            reports it like any bad scenario).
    """
    config, index = parse_game_ref(ref)
    spec = plan_game(config, index)
    return spec.scenario(), spec.run_seed, config.mapping_budget_s
