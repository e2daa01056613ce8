"""IR thread: debounced, hysteretic in-range decision from ADC samples."""

from __future__ import annotations

import pytest
import trio

from actors import Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.devices import Interrupt
from actors.firmware.ir import IrSensor
from supervisors import ChildSpec, SupervisorSpec

from .test_fw_motor import FakeHardware, Recorder


def test_decision_needs_consecutive_samples_past_the_thresholds() -> None:
    """Noise around one threshold never flips it; three in a row past it does."""
    ir = IrSensor(FakeHardware(), high=2200, low=1800, consecutive=3)
    changes = [ir.update(s) for s in (2300, 2300, 1000, 2300, 2300, 2300)]
    assert changes == [False, False, False, False, False, True] and ir.in_range
    assert not any(ir.update(s) for s in (1900, 2000, 1700, 1700, 2100))  # hysteresis band
    assert [ir.update(s) for s in (100, 100, 100)] == [False, False, True]
    assert not ir.in_range


def test_bad_thresholds_are_refused() -> None:
    with pytest.raises(ValueError, match="need 0 <= low < high <= 4095, got low=3000 high=2000"):
        IrSensor(FakeHardware(), low=3000, high=2000)


@pytest.mark.trio
async def test_adc_interrupts_reach_navigation_as_nav_ir(autojump_clock) -> None:
    """The actor sets the timer, its Int C ISR posts samples, navigation gets the decision."""
    hw = FakeHardware()
    hw.rate = None
    hw.set_ir_timer = lambda r: setattr(hw, "rate", r)
    log: list = []
    spec = SupervisorSpec([ChildSpec("nav", lambda: Recorder(log)),
                           ChildSpec("ir", lambda: IrSensor(hw, rate_hz=40.0))])
    async with open_actor_system(1) as system:
        await system.start_supervisor(spec, "seeker")
        assert hw.rate == 40.0
        adc = hw.handlers[Interrupt.INT_C]
        for s in (3000, 3000, 3000):
            adc(s)
        await trio.sleep(0.01)
        assert [m.value for _, m in log if m.command == Cmd.NAV_IR][-1] == 1
        await system.send("seeker/ir", Message.int(Cmd.IR_SAMPLE, 0))
        await trio.sleep(0.01)
        assert [m.value for _, m in log][-1] == 1  # one low sample is not enough
