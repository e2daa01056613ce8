"""The simulated world: room, rovers, devices and faults, stepped on a fixed tick.

`World` is a plain object: `World.step` advances one tick (default 50 ms, with
10 ms physics substeps) and calls the rovers' interrupt handlers synchronously
with that tick's device events, in a fixed order (per role mapper, hider,
seeker: Int E, Int A, Int D/Int C, Int B; then bytes reaching the server).
`run_world` paces it on Trio's clock, so under a virtual clock a whole game
runs far faster than real time.

Determinism: one seeded ``numpy.random.Generator`` feeds every noise source, in
a fixed order per tick; the same scenario, seed and device commands give the
same device events.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from typing import Any

import numpy as np
import trio

from actors.clock import sleep_until
from actors.firmware.hardware import Interrupt
from world.drive import Tread, lag_alpha, slipped_travel
from world.faults import Fault, FaultBook, check_fault, is_actor_fault
from world.geometry import Pose, boundary_segments, room_segments
from world.hardware import SimRoverHardware
from world.ir import IrSensor, to_adc
from world.lidar import Lidar
from world.params import ROLES, rover_spec
from world.physics import DEFAULT_SUBSTEP_S, Physics
from world.raycast import FanCaster, fan_may_hit_disc
from world.scenario import Scenario, ScheduledFault
from world.wifly import WiflyLink

DEFAULT_TICK_S = 0.05
"""World tick [s]: device events are batched per tick (50 ms: see docs/scenarios.md)."""

EventCallback = Callable[[str, str, dict], None]


class World:
    """The room, three rovers and their devices.

    Args:
        scenario: a validated scenario.
        rng: the run's generator; every noise source draws from it.
        tick_s: tick [s] (0.001..0.1).
        substep_s: physics substep [s] (at most ``tick_s``).
        on_event: called as ``on_event(kind, target, detail)`` for fault injection and
            clearance (``fault_injected``, ``fault_cleared``) and ``actor_fault_due``.
    """

    def __init__(self, scenario: Scenario, rng: np.random.Generator, *,
                 tick_s: float = DEFAULT_TICK_S, substep_s: float = DEFAULT_SUBSTEP_S,
                 on_event: EventCallback | None = None) -> None:
        if not isinstance(rng, np.random.Generator):
            raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
        if not 0.001 <= tick_s <= 0.1:
            raise ValueError(f"tick_s must be within 0.001..0.1 s, got {tick_s!r}")
        if not 0 < substep_s <= tick_s:
            raise ValueError(f"substep_s must be within 0..tick_s, got {substep_s!r}")
        self.scenario = scenario
        self.params = p = scenario.params()
        self.rng = rng
        self.tick_s = tick_s
        self.on_event = on_event
        self.ticks = 0
        self.physics = Physics(scenario.room_size, scenario.obstacles, scenario.starts, p,
                               substep_s)
        self._static = np.vstack([room_segments(*scenario.room_size),
                                  boundary_segments(list(scenario.obstacles))])
        self._alpha = lag_alpha(tick_s, p.motor_tau_s)
        self._faults = FaultBook()
        self._schedule = [f for f in scenario.faults if not f.is_actor_fault]
        self._actor_schedule = list(scenario.actor_faults)
        self.treads = {r: (Tread(0), Tread(1)) for r in ROLES}
        self.links = {r: WiflyLink(r, p.wifly_buffer_bytes) for r in ROLES}
        self.lidar = Lidar(p)
        self.ir = IrSensor(p)
        self._hw = {
            r: SimRoverHardware(r, rover_spec(r, p), self.treads[r], self.links[r],
                                self.lidar if r == "mapper" else None,
                                self.ir if r == "seeker" else None)
            for r in ROLES
        }
        self._prev = {r: self.physics.state(r) for r in ROLES}
        self._now = dict(self._prev)
        # everything a LIDAR ray can hit: static walls then the hider's and seeker's bodies
        self._caster = FanCaster(self._static, boxes=2)
        self._boxes_at: list[tuple[float, float, float] | None] = [None, None]
        """The hider's and seeker's states the caster's boxes were placed at (None: parked)."""
        self._body_radius = math.hypot(p.length_cm, p.width_cm) / 2
        self._step_observers: list[Callable[[], None]] = []

    # ------------------------------------------------------------------ public API

    @property
    def time(self) -> float:
        """Simulated time since the start [s]."""
        return self.ticks * self.tick_s

    def hardware(self, role: str) -> SimRoverHardware:
        """The hardware a rover's firmware drives (implements ``RoverHardware``)."""
        return self._hw[self._role(role)]

    def wifly_link(self, role: str) -> WiflyLink:
        """The server's end of a rover's WiFly link."""
        return self.links[self._role(role)]

    def true_pose(self, role: str) -> Pose:
        """Ground-truth pose (for metrics and the console only, never for firmware)."""
        return self.physics.pose(self._role(role))

    def hider_in_ir_view(self) -> bool:
        """Ground truth: a healthy IR sensor on the seeker would see the hider now (within
        its range and field of view; for campaign invariants only, never for firmware)."""
        seeker, hider = self.physics.state("seeker"), self.physics.state("hider")
        return self.ir.reading(seeker, hider, 0.0) > self.params.ir_low

    def observe_steps(self, observer: Callable[[], None]) -> None:
        """Call ``observer()`` after every tick (metrics probes reading ground truth: it
        must neither draw from the run's generator nor change the world)."""
        self._step_observers.append(observer)

    def inject_fault(self, target: str, kind: str, duration_s: float = 0.0, **params: float) -> int:
        """Start a device fault now; returns its id.

        Raises:
            ValueError: unknown target/kind, a kind not applicable to the device, a bad
                parameter, or an actor fault (those are the runtime's).
        """
        if is_actor_fault(kind):
            raise ValueError(f"{kind!r} is an actor fault: the actor runtime performs it, "
                             "not the world")
        full = check_fault(target, kind, duration_s, params)
        fault = self._faults.add(target, kind, self.time, duration_s, full)
        self._apply_link_faults()
        self._emit("fault_injected", target, {"id": fault.id, "kind": kind,
                                              "duration_s": float(duration_s), "params": full})
        return fault.id

    def clear_fault(self, key: int | str) -> int:
        """Clear a fault by id, or every fault on a target; returns how many were cleared."""
        gone = self._faults.remove(key)
        self._cleared(gone, "cleared")
        return len(gone)

    def active_faults(self) -> list[Fault]:
        """Active device faults, oldest first."""
        return self._faults.active()

    def actor_faults_due(self) -> list[ScheduledFault]:
        """Scheduled actor faults (crash/hang/flood) whose time has come, each returned once.

        The system polls this and hands them to the actor runtime.
        """
        due = [f for f in self._actor_schedule if f.at_s <= self.time + 1e-9]
        for f in due:
            self._actor_schedule.remove(f)
            self._emit("actor_fault_due", f.target, {"kind": f.kind, "duration_s": f.duration_s,
                                                     "params": f.params})
        return due

    def next_actor_fault_s(self) -> float | None:
        """World time [s] of the next scheduled actor fault not yet returned by
        `actor_faults_due`, or None when none is left: a poller can sleep until then
        instead of waking every tick."""
        return min((f.at_s for f in self._actor_schedule), default=None)

    def statistics(self) -> dict[str, Any]:
        """Counters for the console: time, drops, link stats."""
        return {
            "time_s": self.time,
            "lidar_samples": self.lidar.samples,
            "lidar_dropped_bytes": self.lidar.dropped_bytes,
            "ir_adc_overruns": self.ir.adc_overruns,
            "wifly": {r: link.statistics() for r, link in self.links.items()},
            "faults": len(self._faults.active()),
        }

    # ------------------------------------------------------------------ stepping

    def step(self) -> None:
        """Advance one tick and deliver its device events."""
        now = self.ticks * self.tick_s  # `time`
        faulty = bool(self._faults)
        if faulty or self._schedule:  # (with neither, nothing can fire or expire)
            self._fire_schedule(now)
            faulty = bool(self._faults)
        dt = self.tick_s
        physics = self.physics
        vmax, alpha = self.params.max_speed_cm_s, self._alpha
        for role in ROLES:
            left, right = self.treads[role]
            strength_l, strength_r = self._strengths(role) if faulty else (1.0, 1.0)
            vl = left.motor_step(vmax, strength_l, alpha)
            vr = right.motor_step(vmax, strength_r, alpha)
            physics.set_tread_speeds(role, vl, vr)
        physics.step(dt)
        self.ticks += 1
        slip = self.rng.standard_normal(2 * len(ROLES)).tolist()  # per tread, every tick
        state = physics.state
        self._prev, self._now = self._now, {r: state(r) for r in ROLES}
        for i, role in enumerate(ROLES):
            self._encoders(role, slip[2 * i], slip[2 * i + 1])
            if role == "mapper":
                self._lidar_tick(dt)
            elif role == "seeker":
                self._ir_tick(dt)
            self._wifly_tick(role, now, dt)
        for observer in self._step_observers:
            observer()

    def _encoders(self, role: str, z_left: float, z_right: float) -> None:
        """Count this tick's tread travel with slip (`slipped_travel`: the error grows
        with the distance, not the tick) and deliver the Int E it raises; ``z_left``,
        ``z_right`` are the tick's standard normal draws."""
        if self._prev[role] == self._now[role]:
            return  # no travel, no ticks (the slip draws were taken all the same)
        x0, y0, a0 = self._prev[role]
        x1, y1, a1 = self._now[role]
        da = a1 - a0
        mid = a0 + da / 2
        ds = (x1 - x0) * math.cos(mid) + (y1 - y0) * math.sin(mid)
        half = da * self.params.track_width_cm / 2
        handler = self._hw[role].handlers.get(Interrupt.INT_E)
        p = self.params
        left, right = self.treads[role]
        travel_l = slipped_travel(ds - half, z_left, p.slip_sigma)
        travel_r = slipped_travel(ds + half, z_right, p.slip_sigma)
        if self._faults:
            travel_l = self._encoder_fault(role, "encoder_left", travel_l)
            travel_r = self._encoder_fault(role, "encoder_right", travel_r)
        events = (left.encode(travel_l, p.ticks_per_cm, p.ticks_per_interrupt)
                  + right.encode(travel_r, p.ticks_per_cm, p.ticks_per_interrupt))
        if handler:
            for e in events:
                handler(e)

    def _encoder_fault(self, role: str, device: str, travel: float) -> float:
        if self._faults.find(role, device, "stuck"):
            return 0.0
        f = self._faults.find(role, device, "slipping")
        return travel * f.params["ratio"] if f else travel

    def _lidar_tick(self, dt: float) -> None:
        lidar = self.lidar
        if lidar.idle():
            return  # a still rotor (the LIDAR is off but while the mapper maps)
        faults = self._faults
        stuck = bool(faults) and faults.find("mapper", "lidar", "stuck") is not None
        first, n = lidar.due(dt, stuck)
        if n == 0 or (faults and faults.find("mapper", "lidar", "dead")):
            return
        sigma = self.params.lidar_noise_cm
        f = faults.find("mapper", "lidar", "noisy") if faults else None
        if f:
            sigma = math.hypot(sigma, f.params["sigma_cm"])
        noise = self.rng.standard_normal(n) * sigma
        self._place_bodies(first, n, stuck)
        dist = lidar.measure(first, n, stuck, self._now["mapper"], self._caster, noise)
        frames = lidar.frames(first, dist, stuck)
        if faults and faults.find("mapper", "lidar", "garbage"):
            frames = self.rng.integers(0, 256, len(frames), dtype=np.uint8).tobytes()
        frames = lidar.uart(frames, dt)
        handler = self._hw["mapper"].handlers.get(Interrupt.INT_A)
        if frames and handler:
            handler(frames)

    def _place_bodies(self, first: int, n: int, stuck: bool) -> None:
        """Put the hider's and seeker's bodies in the caster where this tick's fan may see
        them, and park them where it cannot (placing a body costs more than the check)."""
        p = self.params
        x, y, heading = self._now["mapper"]
        step = 2.0 * math.pi / p.lidar_samples_per_rev
        span = 0.0 if stuck else (n - 1) * step
        for i, role in enumerate(("hider", "seeker")):
            state = self._now[role]
            if not fan_may_hit_disc((x, y), heading + first * step, span, state[:2],
                                    self._body_radius):
                state = None
            if state != self._boxes_at[i]:
                self._caster.set_box(i, state, p.length_cm, p.width_cm)
                self._boxes_at[i] = state

    def _ir_tick(self, dt: float) -> None:
        if self.ir.idle():
            return  # the IR timer runs only while the seeker looks
        hw = self._hw["seeker"]
        self._adc_complete(hw)
        for _ in range(self.ir.timer_events(dt)):
            h = hw.handlers.get(Interrupt.INT_D)
            if h:
                h(None)
            self._adc_complete(hw)

    def _adc_complete(self, hw: SimRoverHardware) -> None:
        ir = self.ir
        if not ir.adc_pending:
            return
        ir.adc_pending = False
        noise = self.rng.standard_normal() * self.params.ir_noise
        value = ir.reading(self._now["seeker"], self._now["hider"], noise)
        if self._faults:
            if self._faults.find("seeker", "ir", "stuck_high"):
                value = 4095
            elif self._faults.find("seeker", "ir", "stuck_low"):
                value = 0
        h = hw.handlers.get(Interrupt.INT_C)
        if h:
            h(to_adc(value))

    def _wifly_tick(self, role: str, now: float, dt: float) -> None:
        p = self.params
        link = self.links[role]
        if not (link.up.buffer or link.up.in_flight or link.down.buffer or link.down.in_flight):
            return  # idle: nothing to send or deliver (the byte budget is capped anyway)
        loss, corrupt, latency = p.wifly_loss, p.wifly_corrupt, p.wifly_latency_s
        f = self._faults.find(role, "wifly", "loss")
        if f:
            loss = 1.0 - (1.0 - loss) * (1.0 - min(f.params["percent"], 100.0) / 100.0)
        f = self._faults.find(role, "wifly", "corrupt")
        if f:
            corrupt = 1.0 - (1.0 - corrupt) * (1.0 - min(f.params["per_byte"], 1.0))
        f = self._faults.find(role, "wifly", "latency")
        if f:
            latency += f.params["added_s"]
        rate = p.wifly_bytes_s
        down = link.down.tick(now, dt, rate, latency, loss, corrupt, self.rng)
        up = link.up.tick(now, dt, rate, latency, loss, corrupt, self.rng)
        h = self._hw[role].handlers.get(Interrupt.INT_B)
        if h:
            for chunk in down:
                h(chunk)
        if link.on_server_receive is not None:
            for chunk in up:
                link.on_server_receive(chunk)

    # ------------------------------------------------------------------ faults

    def _fire_schedule(self, now: float) -> None:
        while self._schedule and self._schedule[0].at_s <= now + 1e-9:
            f = self._schedule.pop(0)
            target = f.world_target  # a rover's link is its WiFly here
            fault = self._faults.add(target, f.kind, now, f.duration_s, dict(f.params))
            self._emit("fault_injected", target, {"id": fault.id, "kind": f.kind,
                                                  "duration_s": f.duration_s,
                                                  "params": dict(f.params),
                                                  "scheduled": True})
            self._apply_link_faults()
        gone = self._faults.expired(now)
        if gone:
            self._cleared(gone, "expired")

    def _cleared(self, gone: list[Fault], reason: str) -> None:
        if gone:
            self._apply_link_faults()
        for f in gone:
            self._emit("fault_cleared", f.target, {"id": f.id, "kind": f.kind, "reason": reason})

    def _apply_link_faults(self) -> None:
        for role, link in self.links.items():
            link.set_fault_down(self._faults.find(role, "wifly", "down") is not None)

    def _strengths(self, role: str) -> tuple[float, float]:
        """The share of its speed each tread (left, right) of ``role`` reaches while some
        fault is active (`step` takes 1 without asking otherwise): 0 stalled, a weak
        motor's ``strength``, else 1."""
        return self._strength(role, "motor_left"), self._strength(role, "motor_right")

    def _strength(self, role: str, device: str) -> float:
        if self._faults.find(role, device, "stalled"):
            return 0.0
        f = self._faults.find(role, device, "weak")
        return f.params["strength"] if f else 1.0

    def _emit(self, kind: str, target: str, detail: dict) -> None:
        if self.on_event is not None:
            self.on_event(kind, target, {"time_s": self.time, **detail})

    @staticmethod
    def _role(role: str) -> str:
        if role not in ROLES:
            raise ValueError(f"role must be one of {', '.join(ROLES)}, got {role!r}")
        return role


async def run_world(world: World, stop_at: float | None = None) -> None:
    """Step ``world`` on Trio's clock, one tick per ``world.tick_s`` of Trio time.

    World time 0 is aligned with the Trio time at the call (less the world's own
    time so far), so the loop may be restarted. Returns when ``world.time``
    reaches ``stop_at`` [s]; runs until cancelled when it is None.
    """
    origin = trio.current_time() - world.time
    while stop_at is None or world.time < stop_at - 1e-9:
        await sleep_until(origin + world.time + world.tick_s)  # Trio's, cheaper
        world.step()
