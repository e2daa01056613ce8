"""IR thread (seeker): ADC samples to a debounced "hider in range" decision.

The seed's IR thread. On start it attaches the IR timer ISR (Int D, which
starts an ADC conversion) and the ADC ISR (Int C, which posts ``IR_SAMPLE``
0..4095) and sets the IR timer rate. Samples become a decision with
hysteresis (in range above ``high``, out of range below ``low``) and
debouncing (the new state must hold for ``consecutive`` samples in a row),
so sensor noise near the threshold does not make the decision flicker.

``NAV_IR`` (int32: `IR_IN` 1 in range, `IR_OUT` 0 not, `IR_PINNED` 2 no
decision) goes to navigation on every change and once per burst of samples
(so navigation always has a recent decision). The
decision of a restarted incarnation starts at "not in range" and is rebuilt
from the next ``consecutive`` samples: nothing to ask anyone.

Sampling on demand (the seed's IR timer is a device command): by default the
IR timer runs only while navigation holds a lease, an `Cmd.IR_LEASE` message
(float32 [s]: keep sampling that long from now; 0 stops at once). Why: at
50 Hz the samples and decisions were a quarter of all messages of a game,
while navigation looks only during a few seconds of each guess. A lease, not
on/off: navigation renews it while it looks, so a restart of either actor
heals by itself (a new IR incarnation starts stopped and the next renewal
starts it; a lease nobody renews runs out). The lease's end is noticed when
samples arrive, so a running timer stops at most one sample late. When the
timer stops the decision falls back to "not in range" (sent to navigation),
so a later look never starts from a stale "in range". ``always_on=True``
keeps the timer running from the start.

A pinned sensor: a healthy sensor reads about 200 counts with nothing in
range and about 3800 at contact, with noise, so ``consecutive`` samples in a
row at exactly an ADC rail (0 or 4095) are not a reading but a stuck sensor
or a shorted line. The sensor is then `pinned`: the decision is "not in
range" and navigation is told `IR_PINNED` instead of a decision, until a
sample off the rails comes.
"""

from __future__ import annotations

import math

import trio

from actors import Actor, ExitKind, ExitReason, Message
from actors.firmware.addresses import Addresses
from actors.firmware.commands import Cmd
from actors.firmware.drivers.isr import IrAdcIsr, IrTimerIsr
from actors.firmware.hardware import Interrupt, RoverHardware

__all__ = ["IrSensor", "IR_OUT", "IR_IN", "IR_PINNED", "ADC_RAILS"]

IR_OUT, IR_IN, IR_PINNED = 0, 1, 2
"""``NAV_IR`` values: not in range, in range, no decision (the sensor is pinned)."""
ADC_RAILS = (0, 4095)
"""The 12-bit ADC's rails [counts]: a healthy sensor's noisy reading never sits on one."""

#: the longest lease accepted [s]: a renewal is expected every navigation tick
MAX_LEASE_S = 60.0


class IrSensor(Actor):
    """The ``seeker/ir`` actor (see the module docstring).

    Args:
        hardware: the rover's devices (IR timer, ADC, Int C/D).
        rate_hz: IR timer rate [Hz].
        high: ADC level above which a sample says "in range" [0..4095].
        low: ADC level below which a sample says "out of range" (< high).
        consecutive: samples in a row needed to change the decision.
        adc_isr: the ADC ISR (its counters survive restarts); made here when None.
        always_on: run the IR timer from the start, without leases (see the module).

    Raises:
        ValueError: thresholds or counts out of range.
    """

    def __init__(self, hardware: RoverHardware, *, rate_hz: float = 50.0, high: int = 2200,
                 low: int = 1800, consecutive: int = 3, adc_isr: IrAdcIsr | None = None,
                 always_on: bool = False, addresses: Addresses | None = None) -> None:
        self._addresses = addresses
        if not 0 <= low < high <= 4095:
            raise ValueError(f"need 0 <= low < high <= 4095, got low={low!r} high={high!r}")
        if consecutive < 1:
            raise ValueError(f"consecutive must be >= 1, got {consecutive!r}")
        if not rate_hz > 0:
            raise ValueError(f"rate_hz must be > 0 [Hz], got {rate_hz!r}")
        self.hw = hardware
        self.rate_hz = rate_hz
        self.high, self.low, self.consecutive = high, low, consecutive
        self._adc_isr = adc_isr
        self.in_range = False
        """The debounced decision."""
        self.last_sample = 0
        """The latest ADC reading [0..4095]."""
        self._streak = 0  # samples in a row that disagree with the decision
        self._rail_run = 0  # samples in a row at an ADC rail
        self.pinned = False
        """``consecutive`` samples in a row at an ADC rail, none off them since."""
        self.always_on = always_on
        self.sampling = False
        """Whether the IR timer runs (set by this incarnation)."""
        self._until = -math.inf  # the lease's end [s]

    async def on_start(self) -> None:
        self._nav = (self._addresses or Addresses.beside(self.ctx.name)).nav
        if self._adc_isr is None:
            self._adc_isr = IrAdcIsr(self._post)
        self.hw.attach(Interrupt.INT_D, IrTimerIsr(self.hw))
        self.hw.attach(Interrupt.INT_C, self._adc_isr)
        # a restarted incarnation starts stopped (the old one may have left the timer on)
        self._set_sampling(self.always_on, report=False)

    def _post(self, message: Message) -> bool:
        return self.ctx.system.send_nowait(self.ctx.name, message)

    async def on_stop(self, reason: ExitReason) -> None:
        if reason.kind is ExitKind.SHUTDOWN:
            self.hw.set_ir_timer(0.0)

    def _send(self, name: str, message: Message) -> bool:
        """``send_nowait`` to a neighbour; False when full or not registered (yet)."""
        system = self.ctx.system
        return system.whereis(name) is not None and system.send_nowait(name, message)

    async def handle(self, message: Message) -> None:
        await self.handle_burst([message])

    async def handle_burst(self, messages: list[Message]) -> None:
        samples = 0
        for m in messages:
            cmd = m.command
            if cmd == Cmd.IR_SAMPLE:
                if not self.sampling:
                    continue  # posted before the timer stopped: a stopped sensor decides nothing
                samples += 1
                if self.update(int(m.value)):
                    self._report()
                    samples = 0
            elif cmd == Cmd.IR_LEASE:
                self.lease(float(m.value))
            elif cmd != Cmd.NOOP:
                raise ValueError(f"ir got an unknown command 0x{cmd:04x}")
        if samples:
            self._report()
        if self.sampling and not self.always_on and trio.current_time() >= self._until:
            self._set_sampling(False)

    def lease(self, seconds: float) -> None:
        """Keep sampling for ``seconds`` [s] from now (at most `MAX_LEASE_S`); 0 or less
        stops at once. A no-op when ``always_on``."""
        if self.always_on:
            return
        if not seconds > 0:  # nan included
            self._until = -math.inf
            self._set_sampling(False)
            return
        self._until = trio.current_time() + min(seconds, MAX_LEASE_S)
        if not self.sampling:
            self._set_sampling(True)

    def _set_sampling(self, on: bool, *, report: bool = True) -> None:
        """Start or stop the IR timer; stopping resets the decision to "not in range"."""
        self.hw.set_ir_timer(self.rate_hz if on else 0.0)
        self.sampling = on
        if not on:
            changed = self.in_range
            self.in_range = False
            self._streak = self._rail_run = 0
            if report and changed:
                self._report()

    def update(self, sample: int) -> bool:
        """Feed one sample; True when the decision (or `pinned`) changed."""
        self.last_sample = sample
        self._rail_run = self._rail_run + 1 if sample in ADC_RAILS else 0
        pinned = self._rail_run >= self.consecutive or (self.pinned and self._rail_run > 0)
        if pinned != self.pinned:
            self.pinned = pinned
            self.in_range = False
            self._streak = 0
            return True
        if pinned:
            return False
        disagrees = sample < self.low if self.in_range else sample > self.high
        self._streak = self._streak + 1 if disagrees else 0
        if self._streak >= self.consecutive:
            self.in_range = not self.in_range
            self._streak = 0
            return True
        return False

    def _report(self) -> None:
        value = IR_PINNED if self.pinned else IR_IN if self.in_range else IR_OUT
        self._send(self._nav, Message.int(Cmd.NAV_IR, value))
