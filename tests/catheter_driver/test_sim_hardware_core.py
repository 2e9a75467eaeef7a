"""The simulated driver's safety duties without ROS: refusal, clamping, watchdog."""

import math

import pytest

from catheter_driver.sim_hardware import SimHardware
from catheter_models.plant import PlantConfig

CFG = PlantConfig.thesis_rig().with_rig(laser_noise_m=0.0, pressure_noise_pa=0.0)


def test_nan_and_inf_commands_are_refused_and_counted() -> None:
    hw = SimHardware(CFG)
    assert hw.command(1.5e5, now_s=0.0)
    for bad in (math.nan, math.inf, -math.inf):
        assert not hw.command(bad, now_s=0.01)
    c = hw.counters()
    assert (c.received, c.refused_nonfinite) == (4, 3)
    assert hw.command_pa == 1.5e5, "a refused command leaves the last good one in force"
    assert "non-finite" in hw.last_refusal


def test_commands_are_clamped_to_the_safety_range() -> None:
    hw = SimHardware(CFG, max_pressure_pa=2e5)
    hw.command(5e5, 0.0)
    assert hw.command_pa == 2e5
    hw.command(-1e5, 0.0)
    assert hw.command_pa == 0.0
    assert hw.counters().clamped == 2


def test_watchdog_vents_when_commands_stop() -> None:
    hw = SimHardware(CFG, command_timeout_s=0.1)
    assert hw.venting, "at rest until the first command"
    hw.command(2.5e5, now_s=0.0)
    t = 0.0
    for _ in range(20):  # 80 ms of fresh command: pressure builds
        t += 0.004
        sample = hw.step(t)
    assert sample.pressure_measured_pa > 2e5 and not hw.venting
    for _ in range(100):  # no more commands: the watchdog must vent
        t += 0.004
        sample = hw.step(t)
    assert hw.venting and hw.counters().watchdog_vents == 1
    assert sample.pressure_measured_pa < 0.05e5


def test_step_is_the_plant_step() -> None:
    hw = SimHardware(CFG)
    hw.command(2e5, 0.0)
    s = hw.step(0.001)
    assert s.t_s == pytest.approx(1.0 / hw.rate_hz)


def test_a_command_stamped_before_the_last_one_applied_is_refused() -> None:
    hw = SimHardware(CFG, command_timeout_s=0.1)
    assert hw.command(1.0e5, now_s=0.0, stamp_ns=1_000_000_000)
    assert not hw.command(2.0e5, now_s=0.001, stamp_ns=999_000_000), "reordered: older intent"
    assert hw.command_pa == 1.0e5
    assert hw.counters().refused_out_of_order == 1
    assert "out-of-order" in hw.last_refusal and "1.0 ms" in hw.last_refusal
    assert hw.command(2.0e5, now_s=0.002, stamp_ns=1_004_000_000)
    assert hw.command_pa == 2.0e5


def test_the_watchdog_vent_forgets_the_last_stamp() -> None:
    # A new publisher (or a clock stepped back) is refused at most until the watchdog vents.
    hw = SimHardware(CFG, command_timeout_s=0.1)
    hw.command(1.0e5, now_s=0.0, stamp_ns=5_000_000_000)
    assert not hw.command(1.0e5, now_s=0.05, stamp_ns=1_000_000_000)
    hw.step(0.2)
    assert hw.venting
    assert hw.command(1.0e5, now_s=0.21, stamp_ns=1_000_000_000)
