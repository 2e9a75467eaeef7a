"""The compensator's tick: plan following, clamping, slew limit, ramp-down, pre-emption."""

import math

import numpy as np
import pytest

from catheter_control.control_core import ControlCore, StaticInverseCompensator
from catheter_control.trajectory import TrajectoryLimits, TrajectoryPlan
from catheter_models.static_map import StaticMap

RATE_HZ = 250.0
DT = 1.0 / RATE_HZ


class LinearCompensator:
    """1 bar per 10 deg, remembers resets; stands in for any streaming compensator."""

    def __init__(
        self, scale_pa_per_rad: float = 1e5 / math.radians(10), preview_s: float = 0.0
    ) -> None:
        self.scale = scale_pa_per_rad
        self.resets = 0
        self.preview_s = preview_s

    def reset(self) -> None:
        self.resets += 1

    def step(self, angle_desired_rad: float) -> float:
        return self.scale * angle_desired_rad


def ramp_plan(peak_deg: float = 20.0, duration_s: float = 2.0) -> TrajectoryPlan:
    t = np.array([0.0, duration_s / 2, duration_s])
    a = np.radians([0.0, peak_deg, 0.0])
    return TrajectoryPlan.from_knots(t, a, TrajectoryLimits(), RATE_HZ)


def run(core: ControlCore, start_s: float, n: int) -> list:
    return [core.tick(start_s + k * DT, DT) for k in range(n)]


def test_follows_plan_then_ramps_down_and_idles() -> None:
    core = ControlCore(LinearCompensator(), 0.0, 3e5, max_slew_pa_per_s=1e7)
    core.start(ramp_plan(), now_s=0.0)
    outs = run(core, 0.0, int(2.0 * RATE_HZ) + 50)
    mid = outs[int(RATE_HZ)]
    assert mid is not None
    assert mid.angle_desired_rad == pytest.approx(math.radians(20.0), abs=1e-3)
    assert mid.pressure_pa == pytest.approx(2e5, rel=1e-2)
    assert outs[-1] is None, "after the plan and the ramp the core goes idle"
    assert core.state == ControlCore.IDLE


def test_never_leaves_the_pressure_range() -> None:
    # A compensator asking for 4 bar at 20 deg: the core must clamp at 3 bar.
    core = ControlCore(LinearCompensator(2e5 / math.radians(10)), 0.2e5, 3e5, 1e8)
    core.start(ramp_plan(), 0.0)
    pressures = [o.pressure_pa for o in run(core, 0.0, 400) if o is not None]
    assert max(pressures) == pytest.approx(3e5)
    assert min(pressures[: int(RATE_HZ)]) >= 0.2e5 - 1e-9


def test_slew_limit_holds_every_tick() -> None:
    slew = 1e5  # 1 bar/s
    core = ControlCore(LinearCompensator(), 0.0, 3e5, slew)
    core.start(ramp_plan(duration_s=2.0), 0.0)
    pressures = np.array([o.pressure_pa for o in run(core, 0.0, 2000) if o is not None])
    assert np.max(np.abs(np.diff(pressures))) <= slew * DT + 1e-6


def test_stop_ramps_to_zero_at_slew_limit() -> None:
    core = ControlCore(LinearCompensator(), 0.0, 3e5, max_slew_pa_per_s=2e5)
    core.start(ramp_plan(duration_s=4.0), 0.0)
    run(core, 0.0, int(2.0 * RATE_HZ))  # up near the peak
    core.stop()
    outs = [o for o in run(core, 2.0, int(3 * RATE_HZ)) if o is not None]
    p = np.array([o.pressure_pa for o in outs])
    assert np.all(np.diff(p) <= 1e-9), "a stop only ever lowers the pressure"
    assert p[-1] == 0.0 and core.state == ControlCore.IDLE


def test_nonfinite_compensator_output_ramps_down_and_is_counted() -> None:
    class Broken(LinearCompensator):
        def step(self, angle_desired_rad: float) -> float:
            return (
                math.nan if angle_desired_rad > math.radians(5) else super().step(angle_desired_rad)
            )

    core = ControlCore(Broken(), 0.0, 3e5, 5e5)
    core.start(ramp_plan(), 0.0)
    outs = [o for o in run(core, 0.0, 600) if o is not None]
    assert all(math.isfinite(o.pressure_pa) for o in outs)
    assert core.nonfinite_from_compensator >= 1
    assert core.state == ControlCore.IDLE


def test_preemption_keeps_compensator_memory_but_fresh_start_resets() -> None:
    comp = LinearCompensator()
    core = ControlCore(comp, 0.0, 3e5, 1e7)
    core.start(ramp_plan(), 0.0)
    run(core, 0.0, 100)
    core.start(ramp_plan(peak_deg=10.0), 0.4)  # pre-empt mid-motion
    assert comp.resets == 1, "pre-emption must not wipe the hysteresis state"
    run(core, 0.4, 1000)
    assert core.state == ControlCore.IDLE
    core.start(ramp_plan(), 10.0)
    assert comp.resets == 2


def test_static_inverse_compensator_inverts_the_curve() -> None:
    m = StaticMap(np.array([0.0, 1e5, 2e5, 3e5]), np.radians([0.0, 0.0, 10.0, 25.0]))
    comp = StaticInverseCompensator(m)
    assert comp.step(math.radians(10.0)) == pytest.approx(2e5)
    assert comp.step(math.radians(17.5)) == pytest.approx(2.5e5)
    # Zero bend sits at the edge of motion, not at zero pressure.
    assert comp.step(0.0) == pytest.approx(1e5)


def test_a_previewing_compensator_reads_the_plan_ahead() -> None:
    """The model sees the set-point preview_s early; the published set-point is today's."""
    plain, ahead = LinearCompensator(), LinearCompensator(preview_s=0.1)
    outs = {}
    for name, comp in (("plain", plain), ("ahead", ahead)):
        core = ControlCore(comp, 0.0, 3e5, 1e9)
        core.start(ramp_plan(peak_deg=20.0, duration_s=2.0), 0.0)
        outs[name] = [o for o in run(core, 0.0, 200) if o is not None]
    k = 100  # t = 0.4 s on the rising ramp (20 deg/s before smoothing)
    assert outs["ahead"][k].angle_desired_rad == outs["plain"][k].angle_desired_rad
    assert outs["ahead"][k].pressure_pa == pytest.approx(outs["plain"][k + 25].pressure_pa)
    assert outs["ahead"][k].pressure_pa > outs["plain"][k].pressure_pa


def test_a_compensator_that_raises_ramps_down_and_says_why() -> None:
    class Raising(LinearCompensator):
        def step(self, angle_desired_rad: float) -> float:
            if angle_desired_rad > math.radians(5.0):
                raise RuntimeError("onnxruntime: session lost")
            return super().step(angle_desired_rad)

    core = ControlCore(Raising(), 0.0, 3e5, 5e5)
    core.start(ramp_plan(), 0.0)
    outs = [o for o in run(core, 0.0, 600) if o is not None]
    assert all(math.isfinite(o.pressure_pa) and o.pressure_pa >= 0.0 for o in outs)
    assert outs[-1].pressure_pa == 0.0
    assert core.state == ControlCore.IDLE
    assert core.nonfinite_from_compensator >= 1
    assert core.compensator_error == "RuntimeError: onnxruntime: session lost"
