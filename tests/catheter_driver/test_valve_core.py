"""The valve driver's safety logic against fake devices: every path that moves the catheter."""

import math

import pytest

from catheter_driver.devices.base import PressureTransmitter, ValveSetpoint
from catheter_driver.errors import DeviceError, DeviceTimeout
from catheter_driver.valve_core import MAX_CONSECUTIVE_TIMEOUTS, ValveDriverCore

DT = 0.004


class FakeValve(ValveSetpoint):
    def __init__(self) -> None:
        super().__init__()
        self.written: list[float] = []
        self._is_open = False
        self.fail_open = False
        self.fail_write = False

    def _open(self) -> None:
        if self.fail_open:
            raise DeviceError("port /dev/ttyX: no such device")
        self._is_open = True

    def close(self) -> None:
        self._is_open = False

    @property
    def is_open(self) -> bool:
        return self._is_open

    def write_setpoint_pa(self, gauge_pa: float) -> None:
        if self.fail_write:
            raise DeviceError("port closed")
        self.written.append(gauge_pa)


class FakeTransmitter(PressureTransmitter):
    def __init__(self) -> None:
        super().__init__()
        self.value = 1.0e5
        self.timeouts_left = 0
        self._is_open = False

    def _open(self) -> None:
        self._is_open = True

    def close(self) -> None:
        self._is_open = False

    @property
    def is_open(self) -> bool:
        return self._is_open

    def read_gauge_pa(self) -> float:
        if self.timeouts_left:
            self.timeouts_left -= 1
            raise DeviceTimeout("no reply in 5 ms")
        return self.value


def make(**kw: float) -> tuple[ValveDriverCore, FakeValve, FakeTransmitter]:
    valve, tx = FakeValve(), FakeTransmitter()
    args = dict(min_pressure_pa=0.0, max_pressure_pa=3e5, max_slew_pa_per_s=1e8, watchdog_s=0.1)
    args.update(kw)
    return ValveDriverCore(valve, tx, **args), valve, tx


def test_vented_until_the_first_command() -> None:
    core, valve, _ = make()
    tick = core.tick_setpoint(0.0, DT)
    assert tick.setpoint_pa == 0.0 and tick.state == "watchdog"
    assert "no pressure command yet" in tick.reason
    assert valve.written == [0.0]


def test_follows_clamps_and_refuses_nan() -> None:
    core, valve, _ = make()
    assert core.command(2e5, 0.0)
    assert core.tick_setpoint(0.004, DT).setpoint_pa == 2e5
    assert core.command(9e5, 0.008)
    assert core.tick_setpoint(0.012, DT).setpoint_pa == 3e5
    assert not core.command(math.nan, 0.016)
    assert core.tick_setpoint(0.02, DT).setpoint_pa == 3e5, "NaN leaves the last good command"
    assert (core.commands_refused, core.commands_clamped) == (1, 1)
    assert max(valve.written) <= 3e5


def test_out_of_order_commands_are_refused_until_a_vent() -> None:
    core, _, _ = make()
    assert core.command(1e5, 0.0, stamp_ns=2_000_000)
    assert not core.command(2e5, 0.001, stamp_ns=1_000_000)
    assert core.tick_setpoint(0.004, DT).setpoint_pa == 1e5, "the newer intent stays"
    assert core.commands_out_of_order == 1 and "out-of-order" in core.last_refusal
    core.vent()  # forgets the stamp: a restarted publisher with an earlier clock gets through
    assert core.command(2e5, 0.008, stamp_ns=1_000_000)


def test_watchdog_vents_within_its_timeout_and_says_why() -> None:
    core, valve, _ = make(watchdog_s=0.1, max_slew_pa_per_s=1e5)
    core.command(2e5, 0.0)
    t = 0.0
    while t < 0.09:
        t += DT
        core.tick_setpoint(t, DT)
    assert valve.written[-1] > 0.0
    t += 0.02  # 110 ms since the last command
    tick = core.tick_setpoint(t, DT)
    assert tick.setpoint_pa == 0.0, "venting is immediate, not slew-limited"
    assert tick.state == "watchdog" and "100 ms" in tick.reason
    assert core.watchdog_trips == 1


def test_slew_limit_while_following() -> None:
    core, valve, _ = make(max_slew_pa_per_s=1e5)
    for k in range(50):
        core.command(3e5, k * DT)
        core.tick_setpoint(k * DT, DT)
    steps = [b - a for a, b in zip(valve.written, valve.written[1:], strict=False)]
    assert max(steps) <= 1e5 * DT + 1e-9


def test_vent_and_disable_override_commands() -> None:
    core, _, _ = make()
    core.command(2e5, 0.0)
    core.vent()
    assert core.tick_setpoint(0.004, DT).state == "vented"
    core.command(2e5, 0.008)
    assert core.tick_setpoint(0.012, DT).setpoint_pa == 2e5, "a new command resumes"
    core.set_enabled(False)
    core.command(2e5, 0.016)
    tick = core.tick_setpoint(0.02, DT)
    assert (tick.state, tick.setpoint_pa) == ("disabled", 0.0)


def test_lost_valve_reports_and_reconnects() -> None:
    core, valve, _ = make()
    core.command(2e5, 0.0)
    valve.fail_write = True
    tick = core.tick_setpoint(0.004, DT)
    assert tick.state == "link_down" and "port closed" in tick.reason
    valve.fail_write = False
    valve.fail_open = True
    assert core.tick_setpoint(1.5, DT).state == "link_down"
    valve.fail_open = False
    core.command(2e5, 2.95)
    assert core.tick_setpoint(3.0, DT).state == "ok"
    assert valve.counters.reconnects == 1


def test_transmitter_tolerates_a_lone_timeout_but_not_a_run() -> None:
    core, _, tx = make()
    tx.timeouts_left = 1
    assert core.poll_pressure(0.0) is None
    assert core.poll_pressure(0.01) == 1e5, "one timeout does not drop the link"
    tx.timeouts_left = MAX_CONSECUTIVE_TIMEOUTS
    for k in range(MAX_CONSECUTIVE_TIMEOUTS):
        assert core.poll_pressure(0.02 + k * 0.01) is None
    assert not core.transmitter.up
    assert core.poll_pressure(0.1) is None, "waits for the reconnect period"
    assert core.poll_pressure(1.2) == 1e5


def test_close_vents_first() -> None:
    core, valve, _ = make()
    core.command(2e5, 0.0)
    core.tick_setpoint(0.004, DT)
    core.close()
    assert valve.written[-1] == 0.0 and not valve.is_open


def test_bad_range_is_refused() -> None:
    with pytest.raises(ValueError, match="min_pressure_pa"):
        make(min_pressure_pa=2e5, max_pressure_pa=1e5)
