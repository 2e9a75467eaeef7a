"""The compensator's tick: following a plan, holding its end, clamping, slew, ramp-down."""

import math

import numpy as np
import pytest

from catheter_control.control_core import ControlCore, SensorWatch, StaticInverseCompensator
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
        self.sample_period_s: float | None = None

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


def test_ended_says_which_plan_stopped_and_why_but_not_a_preempted_one() -> None:
    core = ControlCore(LinearCompensator(), 0.0, 3e5, max_slew_pa_per_s=1e7)
    first, second, third = ramp_plan(), ramp_plan(10.0), ramp_plan(5.0)
    core.start(first, 0.0)
    run(core, 0.0, 10)
    core.start(second, 10 * DT)  # pre-empts the first: it did not end, it was replaced
    assert core.ended is None
    run(core, 10 * DT, int(2.0 * RATE_HZ) + 50)
    assert core.ended == (second, "")  # ran to its end
    core.start(third, 10.0)
    core.fault("tip/angle stale")
    assert core.ended == (third, "tip/angle stale")


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


class SampledCompensator(LinearCompensator):
    """A model fitted at 250 Hz: records every input it is stepped with."""

    def __init__(self, preview_s: float = 0.0) -> None:
        super().__init__(preview_s=preview_s)
        self.sample_period_s = DT
        self.inputs: list[float] = []

    def step(self, angle_desired_rad: float) -> float:
        self.inputs.append(angle_desired_rad)
        return super().step(angle_desired_rad)


def run_at(core: ControlCore, rate_hz: float, n: int, start_s: float = 0.0) -> list:
    dt = 1.0 / rate_hz
    return [core.tick(start_s + k * dt, dt) for k in range(n)]


def test_a_250_hz_model_in_a_1_khz_loop_sees_its_own_rate_and_is_interpolated() -> None:
    slow, fast = SampledCompensator(preview_s=0.02), SampledCompensator(preview_s=0.02)
    outs = {}
    for comp, rate in ((slow, 250.0), (fast, 1000.0)):
        core = ControlCore(comp, 0.0, 3e5, 1e12)
        core.start(ramp_plan(peak_deg=20.0, duration_s=2.0), 0.0)
        outs[rate] = [o.pressure_pa for o in run_at(core, rate, round(1.0 * rate))]
    # The model was stepped on the same plan instants in both loops (plus the one sample it
    # reads ahead), not four times as often.
    assert fast.inputs[: len(slow.inputs)] == slow.inputs
    assert len(fast.inputs) == len(slow.inputs)
    # At the model's instants the 1 kHz loop commands what the 250 Hz loop commands...
    np.testing.assert_array_equal(outs[1000.0][::4], outs[250.0])
    # ...and in between, the straight line to the next model output (no hold, no lag).
    for k in range(1, 3):
        expected = np.array(outs[250.0][:-1]) + k / 4 * np.diff(outs[250.0])
        np.testing.assert_allclose(outs[1000.0][k:-4:4], expected, rtol=1e-12, atol=1e-6)


def test_missed_deadlines_still_step_the_model_through_every_sample() -> None:
    comp = SampledCompensator()
    core = ControlCore(comp, 0.0, 3e5, 1e12)
    plan = ramp_plan()
    core.start(plan, 0.0)
    ticks = [k for k in range(200) if not 50 <= k < 57]  # a 28 ms stall: 7 ticks skipped
    for k in ticks:
        core.tick(k * DT, DT)
    expected = [plan.desired_at(k * DT) for k in range(200)]
    assert comp.inputs[:200] == pytest.approx(expected, abs=0.0)


def test_preempting_a_sampled_model_starts_from_the_command_in_force() -> None:
    comp = SampledCompensator()
    core = ControlCore(comp, 0.0, 3e5, 1e12)
    core.start(ramp_plan(peak_deg=20.0), 0.0)
    before = [o.pressure_pa for o in run_at(core, 1000.0, 402)]  # t = 0.401 s, mid-ramp
    core.start(ramp_plan(peak_deg=10.0), 0.402)
    after = [o.pressure_pa for o in run_at(core, 1000.0, 8, start_s=0.402)]
    step = 1e5 / math.radians(10) * math.radians(20.0) / 1.0 * 0.001  # ramp slope per ms
    assert abs(after[0] - before[-1]) < 2 * step, (before[-1], after[0])
    assert comp.resets == 1


def test_sensor_watch_names_the_stale_stream() -> None:
    watch = SensorWatch(("pressure/measured", "tip/angle"), timeout_s=0.1)
    assert watch.stale(0.0) == "pressure/measured required but none received"
    watch.seen("pressure/measured", 1.0)
    watch.seen("tip/angle", 1.0)
    watch.seen("tip/distance", 5.0)  # not required: ignored
    assert watch.stale(1.05) == ""
    watch.seen("pressure/measured", 1.1)
    assert watch.stale(1.15) == "tip/angle stale: no sample for 150 ms (limit 100 ms)"
    assert watch.age_s("pressure/measured", 1.15) == pytest.approx(0.05)
    # The longest wait between samples since the last look, then forgotten.
    watch.seen("tip/angle", 1.16)
    assert watch.take_longest_silence_s("tip/angle") == pytest.approx(0.16)
    assert watch.take_longest_silence_s("tip/angle") == 0.0
    assert watch.take_longest_silence_s("pressure/measured") == pytest.approx(0.1)
    with pytest.raises(ValueError, match="timeout"):
        SensorWatch(("tip/angle",), 0.0)


def test_a_fault_ramps_down_says_why_and_the_next_run_starts_clean() -> None:
    comp = LinearCompensator()
    core = ControlCore(comp, 0.0, 3e5, 5e5)
    core.start(ramp_plan(), 0.0)
    run(core, 0.0, 250)  # 1 s in: at the 20 deg peak
    core.fault("tip/angle stale: no sample for 120 ms (limit 100 ms)")
    outs = [o for o in run(core, 1.0, 250) if o is not None]
    assert core.state == ControlCore.IDLE and outs[-1].pressure_pa == 0.0
    diffs = np.diff([o.pressure_pa for o in outs])
    assert np.all(diffs <= 0.0) and np.all(diffs >= -5e5 * DT - 1e-6)
    assert core.fault_reason.startswith("tip/angle stale")
    core.start(ramp_plan(), 3.0)
    assert core.fault_reason == "" and comp.resets == 2
    assert core.tick(3.0, DT) is not None and core.state == ControlCore.FOLLOWING


def test_a_fault_while_idle_changes_nothing() -> None:
    core = ControlCore(LinearCompensator(), 0.0, 3e5, 5e5)
    core.fault("pressure/measured required but none received")
    assert core.state == ControlCore.IDLE and core.fault_reason == ""
    assert core.tick(0.0, DT) is None


@pytest.mark.parametrize("loop_hz", [250.0, 1000.0])
def test_feedback_in_the_core_tracks_the_rig_at_250_hz_and_1_khz(loop_hz: float) -> None:
    """The node's core with the shipped static inverse and gains, on the simulated rig: the
    laser samples at 250 Hz whatever the loop's rate (each sample is used until the next)."""
    from catheter_control.models import load_compensator, load_feedback
    from catheter_models.plant import Plant, PlantConfig
    from catheter_models.signals import get_preset

    desired = np.asarray(get_preset("traj_up_chirp").generate(RATE_HZ).values_si)
    t_knots = np.arange(desired.size) / RATE_HZ
    plan = TrajectoryPlan.from_knots(t_knots, desired, TrajectoryLimits(), loop_hz)
    per_sample = round(loop_hz / RATE_HZ)

    def rmse_deg(with_feedback: bool) -> float:
        core = ControlCore(
            load_compensator("none", ""),
            0.0,
            3.0e5,
            20.0e5,
            load_feedback("pi" if with_feedback else "none", "", "", loop_hz),
        )
        plant = Plant(PlantConfig.thesis_rig())
        core.start(plan, 0.0)
        angle, errors = 0.0, []
        for k in range(desired.size):
            command = 0.0
            for j in range(per_sample):
                out = core.tick((k * per_sample + j) / loop_hz, 1.0 / loop_hz, angle)
                command = 0.0 if out is None else out.pressure_pa
            sample = plant.step(command)
            angle = sample.angle_rad
            errors.append(angle - desired[k])
        return math.degrees(float(np.sqrt(np.mean(np.square(errors)))))

    open_loop, closed = rmse_deg(False), rmse_deg(True)
    assert closed < 0.35 * open_loop, (open_loop, closed)


def hold_plan(end_deg: float = 15.0, duration_s: float = 1.0) -> TrajectoryPlan:
    """A rise from rest that ends at ``end_deg``: its last point is the one held."""
    t = np.array([0.0, duration_s])
    return TrajectoryPlan.from_knots(t, np.radians([0.0, end_deg]), TrajectoryLimits(), RATE_HZ)


def test_after_its_end_the_plan_s_last_point_is_held_until_the_timeout() -> None:
    core = ControlCore(LinearCompensator(), 0.0, 3e5, 2e5, hold_timeout_s=2.0)
    plan = hold_plan(15.0)
    core.start(plan, 0.0)
    outs = run(core, 0.0, int(2.9 * RATE_HZ))  # the plan, then 1.9 s of the hold
    assert core.state == ControlCore.HOLDING
    assert core.ended == (plan, ""), "a plan that ran to its end ended well"
    assert core.hold_angle_rad == pytest.approx(math.radians(15.0))
    assert core.held_s(2.9) == pytest.approx(1.9)
    held = [o for o in outs[int(1.1 * RATE_HZ) :] if o is not None]
    assert all(o.state == ControlCore.HOLDING for o in held)
    assert all(o.pressure_pa == pytest.approx(1.5e5) for o in held), "the hold lets go"
    assert all(o.angle_desired_rad == pytest.approx(math.radians(15.0)) for o in held)
    # Past hold_timeout_s it ramps down at the slew limit and says why.
    after = [o for o in run(core, 2.9 + DT, int(1.0 * RATE_HZ)) if o is not None]
    assert core.state == ControlCore.IDLE and after[-1].pressure_pa == 0.0
    assert np.all(np.diff([o.pressure_pa for o in after]) >= -2e5 * DT - 1e-6)
    assert core.ended is not None and "hold_timeout_s (2 s)" in core.ended[1]
    # No set-point is in force on the way down: a score of the run must not count the ramp
    # as the loop missing the plan's last point.
    down = [o for o in after if o.state != ControlCore.HOLDING]
    assert len(down) > 1 and all(o.angle_desired_rad is None for o in down)
    assert all(o.angle_desired_rad is not None for o in after if o.state == ControlCore.HOLDING)


def test_no_hold_with_a_zero_timeout_ramps_down_at_the_end() -> None:
    core = ControlCore(LinearCompensator(), 0.0, 3e5, 1e7, hold_timeout_s=0.0)
    plan = hold_plan(15.0)
    core.start(plan, 0.0)
    run(core, 0.0, int(1.2 * RATE_HZ))
    assert core.state == ControlCore.IDLE and core.ended == (plan, "")


@pytest.mark.parametrize("bad_s", [-1.0, math.inf, math.nan])
def test_a_hold_timeout_must_be_finite(bad_s: float) -> None:
    with pytest.raises(ValueError, match="hold_timeout_s"):
        ControlCore(LinearCompensator(), 0.0, 3e5, 1e7, hold_timeout_s=bad_s)


def test_the_hold_never_leaves_the_pressure_range() -> None:
    # The compensator asks 4.5 bar for the held 15 deg: the hold clamps at 3 bar, and a
    # floor of 0.2 bar holds too.
    core = ControlCore(
        LinearCompensator(3e5 / math.radians(10)), 0.2e5, 3e5, 1e8, hold_timeout_s=5.0
    )
    core.start(hold_plan(15.0), 0.0)
    outs = [o for o in run(core, 0.0, int(3.0 * RATE_HZ)) if o is not None]
    held = [o.pressure_pa for o in outs if o.state == ControlCore.HOLDING]
    assert len(held) > RATE_HZ and max(held) == pytest.approx(3e5) and min(held) >= 0.2e5


@pytest.mark.parametrize("how", ["stop", "fault"])
def test_a_stop_or_a_stale_sensor_during_the_hold_ramps_down_and_says_why(how: str) -> None:
    core = ControlCore(LinearCompensator(), 0.0, 3e5, 2e5, hold_timeout_s=60.0)
    plan = hold_plan(15.0)
    core.start(plan, 0.0)
    run(core, 0.0, int(1.5 * RATE_HZ))
    assert core.state == ControlCore.HOLDING
    why = "tip/angle stale: no sample for 120 ms (limit 100 ms)"
    if how == "stop":
        core.stop()
    else:
        core.fault(why)
    outs = [o for o in run(core, 1.5, int(1.5 * RATE_HZ)) if o is not None]
    p = np.array([o.pressure_pa for o in outs])
    assert np.all(np.diff(p) <= 0.0) and np.all(np.diff(p) >= -2e5 * DT - 1e-6)
    assert p[-1] == 0.0 and core.state == ControlCore.IDLE
    expected = "stopped on request" if how == "stop" else why
    assert core.ended is not None and core.ended[0] is plan and expected in core.ended[1]
    assert core.fault_reason == ("" if how == "stop" else why)


def test_a_plan_started_from_the_hold_goes_on_with_the_compensator_s_memory() -> None:
    comp = SampledCompensator()
    core = ControlCore(comp, 0.0, 3e5, 1e12, hold_timeout_s=60.0)
    first = hold_plan(15.0)
    core.start(first, 0.0)
    before = [o.pressure_pa for o in run(core, 0.0, int(1.5 * RATE_HZ))]
    t = np.array([0.0, 1.0])
    second = TrajectoryPlan.from_knots(t, np.radians([15.0, 10.0]), TrajectoryLimits(), RATE_HZ)
    core.start(second, 1.5)
    assert comp.resets == 1, "going on from a hold must not wipe the hysteresis state"
    assert core.ended is not None and core.ended[0] is first
    assert "pre-empted" in core.ended[1]
    after = [o.pressure_pa for o in run(core, 1.5, 3)]
    assert after[0] == pytest.approx(before[-1]), "no jump from the hold to the new plan"
    assert core.state == ControlCore.FOLLOWING


def test_feedback_holds_the_rig_at_the_last_point() -> None:
    """The shipped static inverse with feedback on the simulated rig: through a 3 s hold the
    bend stays at the plan's last point (without the hold it would fall back to rest)."""
    from catheter_control.models import load_compensator, load_feedback
    from catheter_models.plant import Plant, PlantConfig

    core = ControlCore(
        load_compensator("none", ""),
        0.0,
        3.0e5,
        20.0e5,
        load_feedback("pi", "", "", RATE_HZ),
        hold_timeout_s=10.0,
    )
    plant = Plant(PlantConfig.thesis_rig())
    core.start(hold_plan(15.0, duration_s=2.0), 0.0)
    angles, angle = [], 0.0
    for k in range(int(5.0 * RATE_HZ)):
        out = core.tick(k * DT, DT, angle)
        angle = plant.step(0.0 if out is None else out.pressure_pa).angle_rad
        angles.append(angle)
    assert core.state == ControlCore.HOLDING
    hold = np.degrees(angles[int(3.0 * RATE_HZ) :])  # 1 s into the hold, to its end
    assert np.all(np.abs(hold - 15.0) < 0.5), (hold.min(), hold.max())


@pytest.mark.parametrize(("end_deg", "held"), [(0.0, False), (0.5, False), (1.0, True)])
def test_a_plan_that_ends_at_rest_is_not_held_but_ramped_down(end_deg: float, held: bool) -> None:
    # Straight is zero pressure: a last point within the rest band (0.8 deg here, one tick
    # at 200 deg/s) ends with the ramp-down, so nothing stays pressurised or watched.
    core = ControlCore(
        LinearCompensator(),
        0.0,
        3e5,
        1e7,
        hold_timeout_s=60.0,
        rest_angle_rad=0.0,
        rest_band_rad=math.radians(200.0) / RATE_HZ,
    )
    t = np.array([0.0, 1.0, 2.0])
    plan = TrajectoryPlan.from_knots(
        t, np.radians([0.0, 15.0, end_deg]), TrajectoryLimits(), RATE_HZ
    )
    core.start(plan, 0.0)
    run(core, 0.0, int(2.5 * RATE_HZ))
    assert core.state == (ControlCore.HOLDING if held else ControlCore.IDLE)
    assert core.ended == (plan, "")
