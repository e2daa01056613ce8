"""IR thread (seeker): ADC samples to a debounced "hider in range" decision.

The seed's IR thread. On start it attaches the IR timer ISR (Int D, which
starts an ADC conversion) and the ADC ISR (Int C, which posts ``IR_SAMPLE``
0..4095) and sets the IR timer rate. Samples become a decision with
hysteresis (in range above ``high``, out of range below ``low``) and
debouncing (the new state must hold for ``consecutive`` samples in a row),
so sensor noise near the threshold does not make the decision flicker.

``NAV_IR`` (int32: 1 in range, 0 not) goes to navigation on every change and
once per burst of samples (so navigation always has a recent decision). The
decision of a restarted incarnation starts at "not in range" and is rebuilt
from the next ``consecutive`` samples: nothing to ask anyone.
"""

from __future__ import annotations

from actors import Actor, ExitKind, ExitReason, Message

from .commands import Cmd
from .devices import Interrupt, RoverHardware
from .isr import IrAdcIsr, IrTimerIsr

__all__ = ["IrSensor"]


class IrSensor(Actor):
    """The ``seeker/ir`` actor (see the module docstring).

    Args:
        hardware: the rover's devices (IR timer, ADC, Int C/D).
        rate_hz: IR timer rate [Hz].
        high: ADC level above which a sample says "in range" [0..4095].
        low: ADC level below which a sample says "out of range" (< high).
        consecutive: samples in a row needed to change the decision.
        adc_isr: the ADC ISR (its counters survive restarts); made here when None.

    Raises:
        ValueError: thresholds or counts out of range.
    """

    def __init__(self, hardware: RoverHardware, *, rate_hz: float = 50.0, high: int = 2200,
                 low: int = 1800, consecutive: int = 3, adc_isr: IrAdcIsr | None = None) -> None:
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

    async def on_start(self) -> None:
        prefix = self.ctx.name.rpartition("/")[0]
        self._nav = f"{prefix}/nav" if prefix else "nav"
        if self._adc_isr is None:
            self._adc_isr = IrAdcIsr(self._post)
        self.hw.attach(Interrupt.INT_D, IrTimerIsr(self.hw))
        self.hw.attach(Interrupt.INT_C, self._adc_isr)
        self.hw.set_ir_timer(self.rate_hz)

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
            if m.command != Cmd.IR_SAMPLE:
                raise ValueError(f"ir got an unknown command 0x{m.command:04x}")
            samples += 1
            if self.update(int(m.value)):
                self._report()
                samples = 0
        if samples:
            self._report()

    def update(self, sample: int) -> bool:
        """Feed one sample; True when the decision changed."""
        self.last_sample = sample
        disagrees = sample < self.low if self.in_range else sample > self.high
        self._streak = self._streak + 1 if disagrees else 0
        if self._streak >= self.consecutive:
            self.in_range = not self.in_range
            self._streak = 0
            return True
        return False

    def _report(self) -> None:
        self._send(self._nav, Message.int(Cmd.NAV_IR, int(self.in_range)))
