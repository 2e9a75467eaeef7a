"""The feedback law: what a person relies on when the laser closes the loop.

Plants here are small linear ones written in the tests (a gain, a lag, a dead time), so each
behaviour is checked against a known answer; the foreign plants and ours are the benchmark's
(bench/bench_closed_loop.py) and the node's integration test.
"""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.feedback import ClosedLoop, FeedbackGains, PIDFeedback
from catheter_models.feedback.tune import LoopModel, design
from catheter_models.limits import limit_window

RATE_HZ = 250.0
DT_S = 1.0 / RATE_HZ
GAIN_RAD_PER_PA = math.radians(12.0) / 1e5  # 12 deg/bar, about the rig's mid-range gain


class LagPlant:
    """Bend = gain * pressure through a first-order lag and a dead time, from rest."""

    def __init__(self, gain: float = GAIN_RAD_PER_PA, tau_s: float = 0.03, delay: int = 2):
        self.gain = gain
        self.alpha = 1.0 - math.exp(-DT_S / tau_s)
        self.queue = [0.0] * delay
        self.y = 0.0

    def step(self, pressure_pa: float) -> float:
        self.queue.append(pressure_pa)
        u = self.queue.pop(0)
        self.y += self.alpha * (self.gain * u - self.y)
        return self.y


class GainFeedforward:
    """A static-inverse feedforward with a wrong gain (the model is never exact)."""

    preview_s = 0.0
    sample_period_s: float | None = None

    def __init__(self, gain_error: float) -> None:
        self.scale = 1.0 / (GAIN_RAD_PER_PA * gain_error)

    def reset(self) -> None:
        pass

    def step(self, angle_desired_rad: float) -> float:
        return angle_desired_rad * self.scale


GAINS = FeedbackGains(kp_pa_per_rad=1.0e5, ki_pa_per_rad_s=5.0e6)


def _loop(gains: FeedbackGains | None, ff: object | None = None, slew: float = 20e5) -> ClosedLoop:
    return ClosedLoop(
        ff,
        gains,
        rate_hz=RATE_HZ,
        min_pressure_pa=0.0,
        max_pressure_pa=3.0e5,
        max_slew_pa_per_s=slew,
    )


def _run(loop: ClosedLoop, plant: LagPlant, desired: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    loop.reset()
    y = 0.0
    out, cmd = np.zeros(desired.size), np.zeros(desired.size)
    for k, d in enumerate(desired):
        u = loop.step(float(d), y)
        y = plant.step(u)
        out[k], cmd[k] = y, u
    return out, cmd


def test_feedback_removes_what_a_wrong_feedforward_leaves() -> None:
    t = np.arange(round(20 * RATE_HZ)) * DT_S
    desired = np.radians(10.0 + 8.0 * np.sin(2 * np.pi * 0.3 * t))
    ff = GainFeedforward(gain_error=1.3)  # the model thinks the catheter 30 % stiffer
    open_loop, _ = _run(_loop(None, ff), LagPlant(), desired)
    closed, cmd = _run(_loop(GAINS, ff), LagPlant(), desired)
    settled = t > 2.0
    rmse_open = np.sqrt(np.mean((open_loop - desired)[settled] ** 2))
    rmse_closed = np.sqrt(np.mean((closed - desired)[settled] ** 2))
    assert rmse_closed < 0.15 * rmse_open, (np.degrees(rmse_open), np.degrees(rmse_closed))
    assert cmd.min() >= 0.0 and cmd.max() <= 3.0e5


def test_a_hold_settles_on_the_set_point_without_feedforward() -> None:
    # Feedback alone must be given the authority to reach 1.25 bar from zero.
    gains = FeedbackGains(1.0e5, 5.0e6, max_correction_pa=3.0e5)
    desired = np.full(round(4 * RATE_HZ), math.radians(15.0))
    out, _ = _run(_loop(gains), LagPlant(), desired)
    assert abs(math.degrees(out[-1]) - 15.0) < 0.01


def test_feedback_alone_stops_at_its_authority() -> None:
    desired = np.full(round(4 * RATE_HZ), math.radians(15.0))
    loop = _loop(GAINS)
    _out, cmd = _run(loop, LagPlant(), desired)
    assert cmd.max() <= GAINS.max_correction_pa + 1.0
    assert "authority" in loop.fault_reason


def test_anti_windup_comes_off_the_clamp_as_soon_as_the_error_turns() -> None:
    """Ask for a bend the clamp cannot reach for 3 s, then for one it can.

    With the integral corrected toward the applied command, the command leaves 3 bar within
    a few ticks of the new set-point; a loop without that correction stays pinned while its
    wound-up integral unwinds (seconds)."""
    unreachable = math.radians(60.0)  # 3 bar gives 36 deg here
    desired = np.concatenate(
        [np.full(round(3 * RATE_HZ), unreachable), np.full(round(2 * RATE_HZ), math.radians(10))]
    )
    switch = round(3 * RATE_HZ)

    def ticks_pinned(gains: FeedbackGains) -> int:
        _, cmd = _run(_loop(gains), LagPlant(), desired)
        pinned = np.flatnonzero(cmd[switch:] < 3.0e5 - 1.0)
        return int(pinned[0]) if pinned.size else desired.size

    # The authority band is opened wide so that only the clamp binds here.
    wide = FeedbackGains(1.0e5, 5.0e6, max_correction_pa=10e5, authority_timeout_s=100.0)
    assert ticks_pinned(wide) <= 3
    # The same gains without back-calculation (an endless tracking time) stay pinned.
    no_aw = FeedbackGains(
        1.0e5, 5.0e6, tracking_time_s=1e9, max_correction_pa=10e5, authority_timeout_s=100.0
    )
    assert ticks_pinned(no_aw) > 50


def test_below_the_opening_pressure_the_integral_is_not_wound_down() -> None:
    """Friction holds the bend at 0.6 deg over a zero set-point; the feedforward sits at the
    edge of motion (0.4 bar, under the 0.5 bar opening). Pressure there moves nothing, so the
    integral must not wind the command down to zero, from where the next rise would have to
    climb back through the whole dead band."""
    gains = FeedbackGains(0.0, 5.0e6, opening_pressure_pa=0.5e5)
    fb = PIDFeedback(gains, RATE_HZ)
    for _ in range(500):
        u = fb.command(
            0.0,
            math.radians(0.6),
            0.4e5,
            dt_s=DT_S,
            low_pa=0.0,
            high_pa=3e5,
            floor_pa=0.0,
            ceiling_pa=3e5,
        )
    assert fb.integral_pa == 0.0
    assert u == 0.4e5
    # Without the dead band the same loop winds the command down to zero.
    plain = PIDFeedback(FeedbackGains(0.0, 5.0e6), RATE_HZ)
    for _ in range(500):
        u = plain.command(
            0.0,
            math.radians(0.6),
            0.4e5,
            dt_s=DT_S,
            low_pa=0.0,
            high_pa=3e5,
            floor_pa=0.0,
            ceiling_pa=3e5,
        )
    assert u == 0.0
    assert plain.integral_pa < -0.39e5


def test_in_the_dead_band_the_integral_does_not_charge_and_a_rise_jumps_it() -> None:
    """The feedforward (a model that underestimates the dead band) sits at 0.3 bar under the
    0.5 bar opening. A small error there (within the laser's noise band) charges nothing: a
    charge would fire as a spike once the muscle opens. A set-point 3 deg above the bend
    takes the command to the opening pressure on the first tick."""
    gains = FeedbackGains(1.0e4, 5.0e6, opening_pressure_pa=0.5e5)
    limits = {"dt_s": DT_S, "low_pa": 0.0, "high_pa": 3e5, "floor_pa": 0.0, "ceiling_pa": 3e5}
    fb = PIDFeedback(gains, RATE_HZ)
    for _ in range(500):
        u = fb.command(math.radians(0.1), 0.0, 0.3e5, **limits)
    assert fb.integral_pa == 0.0
    assert u < 0.35e5
    # Without the dead band the same error charges the integral over those 2 s.
    plain = PIDFeedback(FeedbackGains(1.0e4, 5.0e6), RATE_HZ)
    for _ in range(500):
        plain.command(math.radians(0.1), 0.0, 0.3e5, **limits)
    assert plain.integral_pa > 1.5e4
    assert fb.command(math.radians(3.0), 0.0, 0.3e5, **limits) == 0.5e5


def test_an_opening_beyond_the_authority_is_not_wound_into_the_integral() -> None:
    """A vented feedforward (0 bar: a chain's inverse in its deadband) and a set-point 0.5 deg
    above the bend: the feedback jumps to the opening (0.77 bar), which its 0.5 bar authority
    cuts to 0.5 bar. That cut is the jump's, not the PI's: back-calculated, it wound the
    integral to -1 bar in 0.1 s, and the rise that followed came 4 deg late."""
    gains = FeedbackGains(5.5e4, 2.5e6, opening_pressure_pa=0.77e5)
    limits = {"dt_s": DT_S, "low_pa": 0.0, "high_pa": 3e5, "floor_pa": 0.0, "ceiling_pa": 3e5}
    fb = PIDFeedback(gains, RATE_HZ)
    for _ in range(25):
        u = fb.command(math.radians(0.5), 0.0, 0.0, **limits)
    assert u == pytest.approx(gains.max_correction_pa)  # as far as the authority lets it
    assert fb.integral_pa >= 0.0
    assert fb.at_authority_s == 0.0  # the jump is not the PI pressing on its bound
    # Then the feedforward rises past the opening: the command follows it, not 1 bar below.
    assert fb.command(math.radians(0.5), 0.0, 1.2e5, **limits) >= 1.2e5


def test_an_untrusted_sample_holds_the_feedback_and_is_counted() -> None:
    fb = PIDFeedback(GAINS, RATE_HZ)
    for _ in range(50):
        fb.command(
            0.2, 0.1, 1.0e5, dt_s=DT_S, low_pa=0.0, high_pa=3e5, floor_pa=0.0, ceiling_pa=3e5
        )
    held = fb.integral_pa
    for bad in (math.nan, math.inf, None):
        u = fb.command(
            0.2, bad, 1.0e5, dt_s=DT_S, low_pa=0.0, high_pa=3e5, floor_pa=0.0, ceiling_pa=3e5
        )
        assert u == pytest.approx(1.0e5 + held)
    assert fb.integral_pa == held
    assert fb.untrusted_samples == 3


def test_a_frozen_laser_cannot_drive_the_catheter_to_the_clamp() -> None:
    """The laser reads 5 deg forever; the set-point rises to 20 deg."""
    loop = _loop(GAINS, GainFeedforward(1.0))
    loop.reset()
    commands = []
    for k in range(round(3 * RATE_HZ)):
        desired = math.radians(min(20.0, 5.0 + 15.0 * k * DT_S))
        commands.append(loop.step(desired, math.radians(5.0)))
    ff_max = math.radians(20.0) / GAIN_RAD_PER_PA
    # Never past the feedforward's own command plus the authority band ...
    assert max(commands) <= ff_max + GAINS.max_correction_pa + 1.0
    # ... and the loop gives up, ramps down and says why.
    assert "authority" in loop.fault_reason
    assert commands[-1] == 0.0


def test_the_notch_blocks_its_frequency_and_passes_a_hold() -> None:
    gains = FeedbackGains(1.0, 0.0, notch_frequency_hz=4.0, notch_damping=0.5)
    fb = PIDFeedback(gains, RATE_HZ)
    t = np.arange(round(5 * RATE_HZ)) * DT_S
    ringing = 0.01 * np.sin(2 * np.pi * 4.0 * t)
    seen = [
        -fb.command(
            0.0, float(x), 0.0, dt_s=DT_S, low_pa=-1e9, high_pa=1e9, floor_pa=-1e9, ceiling_pa=1e9
        )
        for x in ringing
    ]
    tail = np.asarray(seen[-round(RATE_HZ) :])
    assert np.max(np.abs(tail)) < 0.01 * 0.1  # -20 dB at the tip's frequency
    fb.reset()
    for _ in range(round(2 * RATE_HZ)):
        held = -fb.command(
            0.0, 0.02, 0.0, dt_s=DT_S, low_pa=-1e9, high_pa=1e9, floor_pa=-1e9, ceiling_pa=1e9
        )
    assert held == pytest.approx(0.02, rel=1e-6)


@pytest.mark.parametrize(
    ("last", "floor", "ceiling", "step", "expected"),
    [
        (1.0e5, 0.0, 3.0e5, 0.1e5, (0.9e5, 1.1e5)),
        (2.95e5, 0.0, 3.0e5, 0.1e5, (2.85e5, 3.0e5)),
        (0.05e5, 0.0, 3.0e5, 0.1e5, (0.0, 0.15e5)),
        (3.5e5, 0.0, 3.0e5, 0.1e5, (3.4e5, 3.4e5)),  # above a lowered ceiling: walk back
    ],
)
def test_the_limit_window_is_the_clamp_and_the_slew(
    last: float, floor: float, ceiling: float, step: float, expected: tuple[float, float]
) -> None:
    assert limit_window(last, floor, ceiling, step) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("field", "value", "says"),
    [
        ("kp_pa_per_rad", -1.0e5, "sign error"),
        ("ki_pa_per_rad_s", -5.0, "sign error"),
        ("kp_pa_per_rad", math.nan, "finite"),
        ("max_correction_pa", 0.0, "> 0"),
    ],
)
def test_bad_gains_are_refused_by_name(field: str, value: float, says: str) -> None:
    raw = {"kp_pa_per_rad": 1e5, "ki_pa_per_rad_s": 1e6, field: value}
    with pytest.raises(ParameterError, match=field) as info:
        FeedbackGains(**raw)
    assert says in str(info.value)


def test_gains_files_round_trip_and_refuse_misspelt_keys(tmp_path: Path) -> None:
    # Only tuned gains load (tests/catheter_models/feedback/test_feedback_seal.py): a design
    # on a known loop, as catheter-lab tune makes it.
    loop = LoopModel(
        math.radians(15.0) / 1e5, math.radians(12.0) / 1e5, 0.02, 0.01, 4.0, 0.1, 0.05, 5, RATE_HZ
    )
    gains = design(loop)[0]
    path = gains.save(tmp_path)
    assert FeedbackGains.load(tmp_path) == gains
    assert FeedbackGains.load(path).tuning == gains.tuning
    raw = json.loads(path.read_text())
    raw["kp_pa_per_radian"] = raw.pop("kp_pa_per_rad")
    path.write_text(json.dumps(raw))
    with pytest.raises(ParameterError, match="kp_pa_per_radian"):
        FeedbackGains.load(path)
    with pytest.raises(ParameterError, match="no feedback gains"):
        FeedbackGains.load(tmp_path / "elsewhere")


def test_a_feedforward_at_another_rate_is_refused() -> None:
    class Sampled(GainFeedforward):
        sample_period_s = 0.01

    with pytest.raises(ParameterError, match="100 Hz"):
        _loop(GAINS, Sampled(1.0))


@pytest.mark.parametrize(
    "filters",
    [
        {"notch_frequency_hz": 4.9, "notch_damping": 0.5},  # a ringing tip's notch
        {"measurement_filter_s": 0.02},  # a noisy laser's low-pass
    ],
)
def test_a_bend_that_follows_the_plan_asks_the_feedback_for_nothing(filters: dict) -> None:
    # The set-point passes the measurement's filters too: filtering the bend alone delays
    # it (the notch: ~30 ms at 1 Hz), and the feedback then pushed a bend the feedforward had
    # right ahead of the plan (0.10 -> 0.48 deg on the Bouc-Wen tip plant's down-chirp).
    gains = FeedbackGains(4.0e4, 2.0e6, **filters)
    fb = PIDFeedback(gains, RATE_HZ)
    t = np.arange(int(5 * RATE_HZ)) / RATE_HZ
    plan = np.radians(15.0 + 8.0 * np.sin(2 * np.pi * 1.0 * t))
    corrections = [
        fb.command(
            float(a),
            float(a),
            1.5e5,
            dt_s=1 / RATE_HZ,
            low_pa=0.0,
            high_pa=3e5,
            floor_pa=0.0,
            ceiling_pa=3e5,
        )
        - 1.5e5
        for a in plan
    ]
    assert max(abs(c) for c in corrections) < 1.0  # Pa: nothing (rounding)
    assert abs(fb.integral_pa) < 1.0
