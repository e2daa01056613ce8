"""IR thread: debounced, hysteretic in-range decision from ADC samples."""

from __future__ import annotations

import pytest
import trio

from actors import Message, open_actor_system
from actors.firmware.commands import Cmd
from actors.firmware.drivers.ir import IrSensor
from actors.firmware.hardware import Interrupt
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


@pytest.mark.parametrize("rail", [4095, 0])
def test_samples_on_an_adc_rail_pin_the_sensor_until_one_comes_off_it(rail: int) -> None:
    """A stuck-high sensor is not "in range", nor a stuck-low one "out of range": three
    samples in a row on a rail pin it (no decision) until a sample off the rails."""
    ir = IrSensor(FakeHardware(), high=2200, low=1800, consecutive=3)
    changes = [ir.update(rail) for _ in range(5)]
    assert changes == [False, False, True, False, False]
    assert ir.pinned and not ir.in_range
    assert ir.update(3800) and not ir.pinned and not ir.in_range  # a real reading again
    assert [ir.update(3800) for _ in range(3)][-1] and ir.in_range


def test_a_reading_near_a_rail_is_a_reading() -> None:
    """Near the rails (contact, nothing in range) the noisy reading is a decision."""
    ir = IrSensor(FakeHardware(), high=2200, low=1800, consecutive=3)
    assert [ir.update(s) for s in (4094, 4095, 4093)][-1] and ir.in_range and not ir.pinned
    assert [ir.update(s) for s in (1, 0, 2)][-1] and not ir.in_range and not ir.pinned


def test_bad_thresholds_are_refused() -> None:
    with pytest.raises(ValueError, match="need 0 <= low < high <= 4095, got low=3000 high=2000"):
        IrSensor(FakeHardware(), low=3000, high=2000)


def ir_tree(hw, log: list, **kw) -> SupervisorSpec:
    """A seeker tree with a recording navigation and the IR actor (rate 40 Hz)."""
    hw.rate = None
    hw.set_ir_timer = lambda r: setattr(hw, "rate", r)
    return SupervisorSpec([ChildSpec("nav", lambda: Recorder(log)),
                           ChildSpec("ir", lambda: IrSensor(hw, rate_hz=40.0, **kw))])


def nav_ir(log: list) -> list[int]:
    return [int(m.value) for _, m in log if m.command == Cmd.NAV_IR]


@pytest.mark.trio
async def test_adc_interrupts_reach_navigation_as_nav_ir(autojump_clock) -> None:
    """Always on: the actor sets the timer, its Int C ISR posts samples, navigation gets
    the decision."""
    hw = FakeHardware()
    log: list = []
    async with open_actor_system(1) as system:
        await system.start_supervisor(ir_tree(hw, log, always_on=True), "seeker")
        assert hw.rate == 40.0
        adc = hw.handlers[Interrupt.INT_C]
        for s in (3000, 3000, 3000):
            adc(s)
        await trio.sleep(0.01)
        assert nav_ir(log)[-1] == 1
        await system.send("seeker/ir", Message.int(Cmd.IR_SAMPLE, 0))
        await trio.sleep(0.01)
        assert [m.value for _, m in log][-1] == 1  # one low sample is not enough
        await system.send("seeker/ir", Message.float(Cmd.IR_LEASE, 0.0))  # no effect: always on
        await trio.sleep(0.01)
        assert hw.rate == 40.0


@pytest.mark.trio
async def test_sampling_runs_only_under_a_lease(autojump_clock) -> None:
    """On demand (the default): stopped at start, started by a lease, samples while
    stopped are ignored, and the decision falls back to "not in range" when it stops."""
    hw = FakeHardware()
    log: list = []
    async with open_actor_system(1) as system:
        await system.start_supervisor(ir_tree(hw, log), "seeker")
        assert hw.rate == 0.0
        adc = hw.handlers[Interrupt.INT_C]
        for s in (3000, 3000, 3000):
            adc(s)
        await trio.sleep(0.01)
        assert nav_ir(log) == []  # a stopped sensor decides nothing
        await system.send("seeker/ir", Message.float(Cmd.IR_LEASE, 1.0))
        await trio.sleep(0.01)
        assert hw.rate == 40.0
        for s in (3000, 3000, 3000):
            adc(s)
        await trio.sleep(0.01)
        assert nav_ir(log)[-1] == 1
        await system.send("seeker/ir", Message.float(Cmd.IR_LEASE, 0.0))
        await trio.sleep(0.01)
        assert hw.rate == 0.0 and nav_ir(log)[-1] == 0


@pytest.mark.trio
async def test_a_lease_nobody_renews_runs_out(autojump_clock) -> None:
    """The end of a lease is noticed at the next sample; renewals keep it running."""
    hw = FakeHardware()
    log: list = []
    async with open_actor_system(1) as system:
        await system.start_supervisor(ir_tree(hw, log), "seeker")
        adc = hw.handlers[Interrupt.INT_C]
        await system.send("seeker/ir", Message.float(Cmd.IR_LEASE, 0.5))
        await trio.sleep(0.4)
        await system.send("seeker/ir", Message.float(Cmd.IR_LEASE, 0.5))  # renewed until 0.9
        await trio.sleep(0.3)
        adc(100)
        await trio.sleep(0.01)
        assert hw.rate == 40.0
        await trio.sleep(0.3)
        adc(100)
        await trio.sleep(0.01)
        assert hw.rate == 0.0


@pytest.mark.trio
async def test_a_restarted_ir_starts_stopped_and_noop_is_ignored(autojump_clock) -> None:
    """A crash while sampling: the new incarnation stops the timer until the next lease;
    a NOOP flood does not crash the actor."""
    hw = FakeHardware()
    log: list = []
    async with open_actor_system(1) as system:
        await system.start_supervisor(ir_tree(hw, log), "seeker")
        await system.send("seeker/ir", Message.float(Cmd.IR_LEASE, 5.0))
        await trio.sleep(0.01)
        assert hw.rate == 40.0
        mon = system.monitor("seeker/ir")
        system.inject_crash("seeker/ir")
        await mon.receive()
        await trio.sleep(0.01)
        assert hw.rate == 0.0
        system.flood("seeker/ir", 10, Message.uint(Cmd.NOOP, 0))
        await system.send("seeker/ir", Message.float(Cmd.IR_LEASE, 1.0))
        await trio.sleep(0.01)
        assert hw.rate == 40.0
        assert system.whereis("seeker/ir").last_exit.kind.name == "CRASH"  # only the injected one
