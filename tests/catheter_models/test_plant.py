"""Tests of the simulated rig (catheter_models.plant) against docs/simulated_rig.md.

Each effect is checked against the plant's *own* physics as config.py documents it (Dahl
friction scaled by wire tension, orifice flow, Zener creep, ...), usually with every other
effect off (``PlantConfig.ideal()``) and the sensor noise at zero, so a number can be
predicted from the equations rather than from the lab's block forms. The defaults are then
checked against what the thesis saw (ch. 4, figs. 4.3/4.4).
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import fields

import numpy as np
import numpy.typing as npt
import pytest

from catheter_models.errors import ParameterError
from catheter_models.geometry import LaserGeometry
from catheter_models.plant import EFFECTS, RIG_PARAMS, Plant, PlantConfig, PlantOutput
from catheter_models.plant.config import EffectSetting
from catheter_models.signals import get_preset
from catheter_models.units import AMBIENT_PRESSURE_PA, bar_to_pa, deg_to_rad, rad_to_deg

FloatArray = npt.NDArray[np.float64]

RATE_HZ = 250.0
QUIET = {"laser_noise_m": 0.0, "pressure_noise_pa": 0.0}
# Bend per bar of the default rig, the small-bend spring every ideal-plant prediction uses.
GAIN_DEG_PER_BAR = rad_to_deg(
    next(p.default for p in RIG_PARAMS if p.name == "bend_gain_rad_per_pa") * 1e5
)


# --- helpers ---------------------------------------------------------------------------------


def _quiet_ideal() -> PlantConfig:
    """Every effect off and no sensor noise: outputs are the bare physics."""
    return PlantConfig.ideal().with_rig(**QUIET)


def _samples(duration_s: float) -> int:
    return round(duration_s * RATE_HZ)


def _raised_sine_pa(freq_hz: float, amplitude_pa: float, cycles: int) -> FloatArray:
    """``a (1 - cos(2 pi f t))``: starts at rest, swings 0..2a, ``cycles`` whole periods."""
    t_s = np.arange(_samples(cycles / freq_hz)) / RATE_HZ
    out: FloatArray = amplitude_pa * (1.0 - np.cos(2.0 * math.pi * freq_hz * t_s))
    return out


def _hold_then_step_pa(
    before_pa: float, after_pa: float, hold_s: float, after_s: float
) -> FloatArray:
    return np.concatenate(
        [np.full(_samples(hold_s), before_pa), np.full(_samples(after_s), after_pa)]
    )


def _crossings(x: FloatArray, level: float) -> tuple[FloatArray, FloatArray]:
    """Fractional sample indices where ``x`` crosses ``level`` upward and downward."""
    d = x - level
    i = np.flatnonzero((d[:-1] < 0.0) & (d[1:] >= 0.0))
    j = np.flatnonzero((d[:-1] >= 0.0) & (d[1:] < 0.0))
    return i + (-d[i]) / (d[i + 1] - d[i]), j + d[j] / (d[j] - d[j + 1])


def _at(y: FloatArray, index: float) -> float:
    """``y`` linearly interpolated at a fractional sample index."""
    i = math.floor(index)
    w = index - i
    return float(y[i] * (1.0 - w) + y[i + 1] * w)


def _loop_width_deg(out: PlantOutput, pressure_pa: float, cycle: int = -1) -> float:
    """Unloading minus loading bend [deg] at ``pressure_pa`` of muscle pressure.

    The abscissa is the muscle pressure, not the command, so valve and line lags do not count
    as hysteresis: only what the bend does at a given pull.
    """
    up, down = _crossings(out.muscle_pressure_pa, pressure_pa)
    angle_deg = rad_to_deg(out.true_angle_rad)
    return _at(angle_deg, down[cycle]) - _at(angle_deg, up[cycle])


def _sine_amplitude_pa(out: PlantOutput, freq_hz: float) -> float:
    """Half the peak-to-peak muscle pressure over the last period [Pa]."""
    last = out.muscle_pressure_pa[-_samples(1.0 / freq_hz) :]
    return 0.5 * float(last.max() - last.min())


def _rise_time_s(t_s: FloatArray, y: FloatArray, start: int, fraction: float) -> float:
    """Time from sample ``start`` until ``y`` has covered ``fraction`` of its final change."""
    progress = (y[start:] - y[start]) / (y[-1] - y[start])
    i = int(np.argmax(progress >= fraction))
    w = (fraction - progress[i - 1]) / (progress[i] - progress[i - 1])
    t_cross = t_s[start + i - 1] + w * (t_s[start + i] - t_s[start + i - 1])
    return float(t_cross - t_s[start])


def _all_effects_on(seed: int = 0) -> PlantConfig:
    config = PlantConfig.thesis_rig(seed=seed)
    for name in EFFECTS:
        config = config.with_effect(name)
    return config


# --- the defaults reproduce the thesis ------------------------------------------------------


def test_default_deadband_no_bend_below_opening_pressure() -> None:
    """Thesis sec. 4.2: no motion from rest up to roughly 0.85-1 bar, then motion."""
    config = PlantConfig.thesis_rig().with_rig(**QUIET)
    out = Plant(config).simulate(np.linspace(0.0, bar_to_pa(2.0), _samples(20.0)))
    opening_pa = config.effect_param("deadband", "opening_pressure_pa")
    assert 0.5e5 <= opening_pa <= 1.0e5
    below = out.muscle_pressure_pa < opening_pa
    assert below.sum() > 100
    np.testing.assert_array_equal(out.true_angle_rad[below], 0.0)
    above = out.muscle_pressure_pa > bar_to_pa(1.2)
    assert rad_to_deg(out.true_angle_rad[above]).min() > 0.5


def test_default_bend_at_3_bar_is_about_30_deg() -> None:
    """Thesis: about 30 deg at 3 bar, read through the noisy laser on a slow ramp."""
    ramp = np.linspace(0.0, bar_to_pa(3.0), _samples(30.0))
    hold = np.full(_samples(2.0), bar_to_pa(3.0))
    out = Plant(PlantConfig.thesis_rig()).simulate(np.concatenate([ramp, hold]))
    measured_deg = rad_to_deg(out.angle_rad[-_samples(1.0) :]).mean()
    assert 27.0 <= measured_deg <= 32.0


def test_default_loop_width_grows_from_0p2_to_0p8_hz() -> None:
    """Fig. 4.3: the major loop widens with frequency, by +1 to 3 deg (effects.md)."""
    config = PlantConfig.thesis_rig().with_rig(**QUIET)
    widths = []
    for freq in ("0.2", "0.4", "0.6", "0.8"):
        signal = get_preset(f"train_zero_f{freq}").generate(RATE_HZ)
        out = Plant(config).simulate(signal.values_si)
        widths.append(_loop_width_deg(out, bar_to_pa(1.5), cycle=0))
    assert np.all(np.diff(widths) > 0.0), widths
    assert 1.0 <= widths[-1] - widths[0] <= 3.0, widths


def test_default_laser_noise_at_250_hz() -> None:
    """Laser distance noise, seen through eq. 3.3's slope 2L/H^2 near a straight tip."""
    config = PlantConfig.thesis_rig()
    plant = Plant(config)
    assert plant.sample_period_s == pytest.approx(1.0 / RATE_HZ)
    out = plant.simulate(np.zeros(_samples(10.0)))
    error_deg = rad_to_deg(out.angle_rad - out.true_angle_rad)
    std_deg = float(np.std(error_deg))
    assert 0.01 <= std_deg <= 0.1
    geom = LaserGeometry()
    slope_rad_per_m = 2.0 * geom.length_m / geom.height_m**2
    expected_deg = rad_to_deg(slope_rad_per_m * config.rig["laser_noise_m"])
    assert std_deg == pytest.approx(expected_deg, rel=0.1)
    # White: neighbouring samples are independent.
    assert abs(np.corrcoef(error_deg[:-1], error_deg[1:])[0, 1]) < 0.1


# --- every effect switch --------------------------------------------------------------------


@pytest.mark.parametrize("friction_deg", [1.0, 2.0, 4.0])
def test_play_loop_width_scales_with_friction_and_wire_tension(friction_deg: float) -> None:
    """Coulomb level = friction_rad x (pull / pull at 1 bar): width 2 x level at the pull."""
    freq_hz = 0.05  # slow, so the structural lag adds only a few hundredths of a degree
    command = _raised_sine_pa(freq_hz, 1.0e5, cycles=2)
    base = _quiet_ideal()
    off = Plant(base).simulate(command)
    on = Plant(base.with_effect("play", friction_rad=deg_to_rad(friction_deg))).simulate(command)
    # Only where the unloading branch slides: after the reversal at p_max the tip sticks
    # until G p + F p = (G - F) p_max, i.e. down to 1.27 bar for 4 deg of friction.
    for pressure_bar in (0.5, 1.0):
        width_off = _loop_width_deg(off, bar_to_pa(pressure_bar))
        width_on = _loop_width_deg(on, bar_to_pa(pressure_bar))
        assert abs(width_off) < 0.1
        expected = 2.0 * friction_deg * pressure_bar
        assert width_on - width_off == pytest.approx(expected, rel=0.05)


def test_play_tip_returns_home_after_venting() -> None:
    """With the muscle vented the wire is slack, so friction cannot hold the tip bent."""
    config = _quiet_ideal().with_effect("play", friction_rad=deg_to_rad(4.0))
    command = np.concatenate([_raised_sine_pa(0.2, 1.0e5, cycles=2), np.zeros(_samples(1.0))])
    out = Plant(config).simulate(command)
    # Peak (G - F) x 2 bar = 28 deg: friction held back 8 deg of it on the way up.
    assert rad_to_deg(out.true_angle_rad).max() > 25.0
    assert abs(rad_to_deg(out.true_angle_rad[-1])) < 1e-3


@pytest.mark.parametrize("viscous_s", [0.005, 0.02])
def test_rate_dependence_widens_loops_with_frequency(viscous_s: float) -> None:
    """Viscous torque c x bend rate: extra width 2 G a omega c at mid pressure (omega c << 1)."""
    base = _quiet_ideal()
    config = base.with_effect("rate_dependence", viscous_s=viscous_s)
    growth = {}
    for label, cfg in (("off", base), ("on", config)):
        widths = {}
        for freq_hz in (0.2, 0.8):
            command = _raised_sine_pa(freq_hz, 1.0e5, cycles=3)
            off = Plant(base).simulate(command)
            out = Plant(cfg).simulate(command)
            widths[freq_hz] = _loop_width_deg(out, 1.0e5)
            if label == "on":
                omega = 2.0 * math.pi * freq_hz
                amp_bar = _sine_amplitude_pa(out, freq_hz) / 1e5
                expected = 2.0 * GAIN_DEG_PER_BAR * amp_bar * omega * viscous_s
                extra = widths[freq_hz] - _loop_width_deg(off, 1.0e5)
                assert extra == pytest.approx(expected, rel=0.05)
        growth[label] = widths[0.8] - widths[0.2]
    # The unit amplitude is nominal here; the valve's 5 ms lag trims it by well under 1 %.
    expected_extra = 2.0 * GAIN_DEG_PER_BAR * 2.0 * math.pi * (0.8 - 0.2) * viscous_s
    assert growth["on"] - growth["off"] == pytest.approx(expected_extra, rel=0.05)
    assert growth["on"] > growth["off"] > 0.0


@pytest.mark.parametrize("opening_bar", [0.5, 1.2])
def test_deadband_no_bend_below_opening_pressure(opening_bar: float) -> None:
    """Zero pull below opening_pressure_pa; above the knee the bend is G (p - open - knee/2)."""
    base = _quiet_ideal()
    config = base.with_effect("deadband", opening_pressure_pa=bar_to_pa(opening_bar))
    ramp = np.linspace(0.0, bar_to_pa(2.0), _samples(20.0))
    off = Plant(base).simulate(ramp)
    on = Plant(config).simulate(ramp)
    low = on.muscle_pressure_pa <= bar_to_pa(opening_bar)
    np.testing.assert_array_equal(on.true_angle_rad[low], 0.0)
    # Off, the bend follows from the first pascal.
    early = off.muscle_pressure_pa > bar_to_pa(0.1)
    assert rad_to_deg(off.true_angle_rad[early]).min() > 1.0
    knee_bar = config.effect_param("deadband", "knee_pa") / 1e5
    expected_deg = GAIN_DEG_PER_BAR * (2.0 - opening_bar - 0.5 * knee_bar)
    assert rad_to_deg(on.true_angle_rad[-1]) == pytest.approx(expected_deg, abs=0.05)


def test_asymmetry_unloading_above_loading_and_grows_with_ratio() -> None:
    """Braid friction: gain 1-r while inflating, 1+r while deflating, gap 2 r G p."""
    command = _raised_sine_pa(0.05, 1.0e5, cycles=2)
    base = _quiet_ideal()
    width_off = _loop_width_deg(Plant(base).simulate(command), 1.0e5)
    assert abs(width_off) < 0.1
    gaps = []
    for ratio in (0.04, 0.08, 0.16):
        out = Plant(base.with_effect("asymmetry", ratio=ratio)).simulate(command)
        for pressure_bar in (1.0, 1.5):
            gap = _loop_width_deg(out, bar_to_pa(pressure_bar)) - width_off * pressure_bar
            assert gap == pytest.approx(2.0 * ratio * GAIN_DEG_PER_BAR * pressure_bar, rel=0.05)
        gaps.append(_loop_width_deg(out, 1.0e5))
    assert gaps[0] > 0.0
    assert np.all(np.diff(gaps) > 0.0)


@pytest.mark.parametrize("limit_deg", [30.0, 55.0])
def test_saturation_follows_artanh_spring_and_never_exceeds_limit(limit_deg: float) -> None:
    """Spring L artanh(theta/L) against pull G p: quasi-static bend L tanh(G p / L)."""
    gain_deg_per_bar = 20.0  # reaches 60 deg linear at 3 bar: far into saturation
    base = _quiet_ideal().with_rig(bend_gain_rad_per_pa=deg_to_rad(gain_deg_per_bar) / 1e5)
    config = base.with_effect("saturation", limit_rad=deg_to_rad(limit_deg))
    ramp = np.linspace(0.0, bar_to_pa(3.0), _samples(30.0))
    lin = Plant(base).simulate(ramp)
    sat = Plant(config).simulate(ramp)
    p_bar = sat.muscle_pressure_pa / 1e5
    bend_deg = rad_to_deg(sat.true_angle_rad)
    expected = limit_deg * np.tanh(gain_deg_per_bar * p_bar / limit_deg)
    np.testing.assert_allclose(bend_deg, expected, atol=0.05)
    assert bend_deg.max() < limit_deg

    def slope(out: PlantOutput, lo_bar: float, hi_bar: float) -> float:
        p = out.muscle_pressure_pa / 1e5
        sel = (p > lo_bar) & (p < hi_bar)
        return float(np.polyfit(p[sel], rad_to_deg(out.true_angle_rad[sel]), 1)[0])

    assert slope(lin, 2.5, 3.0) == pytest.approx(slope(lin, 0.2, 0.6), rel=1e-3)
    assert slope(sat, 2.5, 3.0) < 0.5 * slope(sat, 0.2, 0.6)


def test_saturation_limit_holds_against_overshoot() -> None:
    """Even a ringing tip driven far past the limit stays below it."""
    limit_deg = 20.0
    config = (
        _quiet_ideal()
        .with_rig(bend_gain_rad_per_pa=deg_to_rad(60.0) / 1e5)
        .with_effect("saturation", limit_rad=deg_to_rad(limit_deg))
        .with_effect("tip_dynamics", damping_ratio=0.02)
    )
    out = Plant(config).simulate(_hold_then_step_pa(0.0, bar_to_pa(3.0), 0.1, 1.0))
    assert rad_to_deg(out.true_angle_rad).max() <= limit_deg


def test_pneumatic_lag_time_constant_and_pressure_dependence() -> None:
    """dP/dt = G (Pv^2 - Pm^2): small-signal tau at 1.5 bar as set, tau ~ 1/P_abs elsewhere."""
    tau_s = 0.06
    # A fast valve, so the line is what the step response shows.
    base = _quiet_ideal().with_rig(valve_time_constant_s=0.001)
    config = base.with_effect("pneumatic_lag", time_constant_s=tau_s)
    step_pa = 0.02e5
    hold_s = 3.0
    start = _samples(hold_s) - 1

    def tau_at(cfg: PlantConfig, gauge_pa: float) -> float:
        out = Plant(cfg).simulate(_hold_then_step_pa(gauge_pa, gauge_pa + step_pa, hold_s, 1.0))
        return _rise_time_s(out.t_s, out.muscle_pressure_pa, start, 1.0 - math.exp(-1.0))

    tau_mid = tau_at(config, 1.5e5)
    tau_high = tau_at(config, 2.5e5)
    assert tau_mid == pytest.approx(tau_s, rel=0.15)
    assert tau_high < tau_mid
    expected_ratio = (AMBIENT_PRESSURE_PA + 1.5e5) / (AMBIENT_PRESSURE_PA + 2.5e5)
    assert tau_high / tau_mid == pytest.approx(expected_ratio, rel=0.15)
    # Off: the muscle sees the valve pressure as it is.
    assert tau_at(base, 1.5e5) < 0.2 * tau_s
    off = Plant(base).simulate(_raised_sine_pa(1.0, 1.0e5, cycles=2))
    np.testing.assert_array_equal(off.muscle_pressure_pa, off.pressure_measured_pa)


def _smooth_random_command_pa(seed: int, n: int) -> FloatArray:
    rng = np.random.default_rng(seed)
    out: FloatArray = np.convolve(rng.uniform(0.0, 2.0e5, n), np.ones(25) / 25.0, mode="same")
    return out


@pytest.mark.parametrize("delay_s", [0.004, 0.02, 0.1])
def test_transport_delay_shifts_the_bend_by_whole_samples(delay_s: float) -> None:
    """Dead time: the response is the undelayed one, shifted by delay_s."""
    command = _smooth_random_command_pa(0, _samples(10.0))
    base = _quiet_ideal()
    off = Plant(base).simulate(command)
    on = Plant(base.with_effect("transport_delay", delay_s=delay_s)).simulate(command)
    k = round(delay_s * RATE_HZ)
    np.testing.assert_array_equal(on.true_angle_rad[k:], off.true_angle_rad[:-k])
    np.testing.assert_array_equal(on.true_angle_rad[:k], 0.0)


def test_transport_delay_cross_correlation_peaks_at_the_delay() -> None:
    """A delay between samples (12.5 samples) shows within one sample of where it should."""
    delay_s = 0.05
    command = _smooth_random_command_pa(1, _samples(20.0))
    base = _quiet_ideal()
    ref = np.diff(Plant(base).simulate(command).true_angle_rad)
    on = np.diff(
        Plant(base.with_effect("transport_delay", delay_s=delay_s)).simulate(command).true_angle_rad
    )
    lags = np.arange(40)
    xcorr = [float(np.dot(ref[: ref.size - lag], on[lag:])) for lag in lags]
    assert abs(int(lags[int(np.argmax(xcorr))]) - delay_s * RATE_HZ) <= 1.0


@pytest.mark.parametrize(("fraction", "tau_s"), [(0.1, 2.0), (0.3, 0.5)])
def test_creep_bend_keeps_rising_under_held_pressure(fraction: float, tau_s: float) -> None:
    """Zener solid: two Maxwell branches (tau/2, 2 tau) that carry `fraction` once relaxed."""
    base = _quiet_ideal()
    config = base.with_effect("creep", fraction=fraction, time_constant_s=tau_s)
    hold_s = 0.2
    command = _hold_then_step_pa(0.0, 1.0e5, hold_s, 12.0 * tau_s)
    out = Plant(config).simulate(command)
    start = _samples(hold_s) - 1
    t_s = out.t_s[start:] - out.t_s[start]
    bend_deg = rad_to_deg(out.true_angle_rad[start:])
    final_deg = GAIN_DEG_PER_BAR

    # The linear model of the two branches, solved exactly: with the spring massless
    # (mech tau 3 ms << tau) the bend is (pull + k c1 + k c2) / (1 + 2k) and each branch
    # relaxes dc_i/dt = (theta - c_i) / tau_i.
    k = fraction / (2.0 * (1.0 - fraction))
    s = k / (1.0 + 2.0 * k)
    taus = np.array([tau_s / 2.0, 2.0 * tau_s])
    a = np.array([[s - 1.0, s], [s, s - 1.0]]) / taus[:, None]
    b = final_deg / (1.0 + 2.0 * k) / taus
    x_final = -np.linalg.solve(a, b)
    eigval, eigvec = np.linalg.eig(a)
    coef = np.linalg.solve(eigvec, -x_final)
    branches = x_final[:, None] + eigvec @ (coef[:, None] * np.exp(eigval[:, None] * t_s))
    expected_deg = (final_deg + k * branches.sum(axis=0)) / (1.0 + 2.0 * k)

    instant_deg = final_deg * (1.0 - fraction)
    settled = t_s > 0.2
    np.testing.assert_allclose(
        bend_deg[settled], expected_deg[settled], atol=0.02 * fraction * final_deg
    )
    # Right after the step the bend has only the short-term share; it creeps the rest.
    assert expected_deg[0] == pytest.approx(instant_deg, rel=1e-9)
    assert bend_deg[_samples(0.05)] == pytest.approx(
        expected_deg[_samples(0.05)], abs=0.05 * fraction * final_deg
    )
    assert bend_deg[-1] == pytest.approx(final_deg, abs=0.02 * fraction * final_deg)
    creep_progress = (bend_deg - instant_deg) / (fraction * final_deg)
    t63 = float(t_s[int(np.argmax(creep_progress >= 1.0 - math.exp(-1.0)))])
    assert 0.5 * tau_s <= t63 <= 2.0 * tau_s

    off = Plant(base).simulate(command)
    off_deg = rad_to_deg(off.true_angle_rad[start:])
    assert abs(off_deg[-1] - off_deg[_samples(0.2)]) < 1e-6


@pytest.mark.parametrize(("natural_hz", "zeta"), [(8.0, 0.15), (5.0, 0.05), (12.0, 0.3)])
def test_tip_dynamics_rings_at_damped_natural_frequency(natural_hz: float, zeta: float) -> None:
    """Tip inertia on the bending spring: a step rings at f_n sqrt(1 - zeta^2), decay zeta."""
    base = _quiet_ideal()
    config = base.with_effect("tip_dynamics", natural_frequency_hz=natural_hz, damping_ratio=zeta)
    command = _hold_then_step_pa(0.0, 1.0e5, 0.2, 3.0)
    start = _samples(0.2)
    residual_deg = rad_to_deg(Plant(config).simulate(command).true_angle_rad[start:])
    residual_deg = residual_deg - GAIN_DEG_PER_BAR
    up, down = _crossings(residual_deg, 0.0)
    zero_crossings = np.sort(np.concatenate([up, down]))[:9]
    assert zero_crossings.size == 9
    ringing_hz = RATE_HZ / (2.0 * float(np.mean(np.diff(zero_crossings))))
    assert ringing_hz == pytest.approx(natural_hz * math.sqrt(1.0 - zeta**2), rel=0.03)
    # Logarithmic decrement over one period gives the damping ratio back.
    peaks = [
        np.abs(residual_deg[int(zero_crossings[i]) : int(zero_crossings[i + 1]) + 2]).max()
        for i in range(3)
    ]
    decrement = math.log(peaks[0] / peaks[2])
    assert decrement / math.sqrt(4.0 * math.pi**2 + decrement**2) == pytest.approx(zeta, rel=0.1)

    off_deg = rad_to_deg(Plant(base).simulate(command).true_angle_rad[start:])
    assert off_deg.max() - GAIN_DEG_PER_BAR < 1e-6  # overdamped: no overshoot at all


@pytest.mark.parametrize("rate_deg_per_min", [1.0, -2.0, 5.0])
def test_drift_moves_the_measured_angle_only(rate_deg_per_min: float) -> None:
    """Laser mount drift: measured angle starts drifting at rate, true angle stays zero."""
    base = _quiet_ideal()
    config = base.with_effect("drift", rate_rad_per_s=deg_to_rad(rate_deg_per_min) / 60.0)
    out = Plant(config).simulate(np.zeros(_samples(60.0)))
    np.testing.assert_array_equal(out.true_angle_rad, 0.0)
    measured_deg = rad_to_deg(out.angle_rad)
    first = out.t_s <= 10.0
    slope_deg_per_min = 60.0 * float(np.polyfit(out.t_s[first], measured_deg[first], 1)[0])
    assert slope_deg_per_min == pytest.approx(rate_deg_per_min, rel=0.03)
    # Exponential approach (10 min): after a minute the offset is rate x tau x (1 - e^-0.1).
    expected_deg = rate_deg_per_min / 60.0 * 600.0 * (1.0 - math.exp(-0.1))
    assert measured_deg[-1] == pytest.approx(expected_deg, rel=0.02)

    off = Plant(base).simulate(np.zeros(_samples(60.0)))
    np.testing.assert_array_equal(off.angle_rad, 0.0)


def test_tip_beyond_laser_branch_is_measured_not_refused() -> None:
    """A valid rig (saturation off) can bend past eq. 3.3's 67.9 deg; the laser must still read.

    The rig's laser would clip, not stop the experiment; the simulator must not raise from
    its own sensor model for an in-range configuration and an in-range command.
    """
    config = _quiet_ideal().with_effect("tip_dynamics")
    out = Plant(config).simulate(_hold_then_step_pa(0.0, bar_to_pa(3.0), 0.1, 1.0))
    assert rad_to_deg(out.true_angle_rad).max() > rad_to_deg(LaserGeometry().max_angle_rad)
    assert np.all(np.isfinite(out.angle_rad))


# --- batch and streaming --------------------------------------------------------------------


_OUTPUT_FIELDS = [f.name for f in fields(PlantOutput)]


@pytest.mark.parametrize("field", _OUTPUT_FIELDS)
@pytest.mark.parametrize("config_name", ["thesis_rig", "all_effects"])
def test_batch_and_streaming_are_bit_identical(config_name: str, field: str) -> None:
    config = PlantConfig.thesis_rig(seed=7) if config_name == "thesis_rig" else _all_effects_on(7)
    rng = np.random.default_rng(3)
    # Random walk over the whole range, beyond it at both ends so clipping is exercised too.
    command = np.clip(np.cumsum(rng.normal(0.0, 3e3, 1500)) + 1.5e5, -0.5e5, 4.0e5)
    batch = Plant(config).simulate(command)
    plant = Plant(config)
    streamed = np.array([getattr(plant.step(float(c)), field) for c in command])
    np.testing.assert_array_equal(streamed, getattr(batch, field))


def test_batch_can_continue_as_stream() -> None:
    """A batch warm-up then streaming equals one batch over the whole signal (kernel state)."""
    config = _all_effects_on(5)
    command = _smooth_random_command_pa(2, 600)
    whole = Plant(config).simulate(command)
    plant = Plant(config)
    first = plant.simulate(command[:400])
    rest = np.array([plant.step(float(c)).true_angle_rad for c in command[400:]])
    np.testing.assert_array_equal(first.true_angle_rad, whole.true_angle_rad[:400])
    np.testing.assert_array_equal(rest, whole.true_angle_rad[400:])


# --- refusals and limits --------------------------------------------------------------------


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf])
def test_batch_refuses_non_finite_command_naming_the_sample(bad: float) -> None:
    plant = Plant(PlantConfig.thesis_rig())
    command = np.full(20, 1.0e5)
    command[7] = bad
    with pytest.raises(ParameterError, match=r"sample 7\b"):
        plant.simulate(command)
    assert plant.t_s == 0.0
    # Nothing was simulated: the same plant now gives what a fresh one gives.
    np.testing.assert_array_equal(
        plant.simulate(np.full(20, 1.0e5)).angle_rad,
        Plant(PlantConfig.thesis_rig()).simulate(np.full(20, 1.0e5)).angle_rad,
    )


@pytest.mark.parametrize("bad", [math.nan, math.inf])
def test_streaming_refuses_non_finite_command_without_advancing(bad: float) -> None:
    config = _all_effects_on(2)
    plant, reference = Plant(config), Plant(config)
    for c in (0.5e5, 1.0e5, 1.5e5):
        plant.step(c)
        reference.step(c)
    t_before = plant.t_s
    with pytest.raises(ParameterError, match="not finite"):
        plant.step(bad)
    assert plant.t_s == t_before
    # State and noise stream untouched: the next samples match a plant that never saw it.
    for c in (2.0e5, 2.5e5):
        assert plant.step(c) == reference.step(c)


@pytest.mark.parametrize(
    ("make", "expected"),
    [
        (
            lambda c: c.with_effect("play", friction_rad=1.0),
            r"play\.friction_rad.*\[0, 0\.174533\]",
        ),
        (lambda c: c.with_effect("creep", fraction=-0.1), r"creep\.fraction.*\[0, 0\.3\]"),
        (lambda c: c.with_effect("tip_dynamics", natural_frequency_hz=math.nan), r"\[2, 30\]"),
        (lambda c: c.with_rig(laser_noise_m=-1.0), r"rig\.laser_noise_m.*\[0, 0\.001\]"),
        (lambda c: c.with_rig(sample_rate_hz=1e6), r"rig\.sample_rate_hz.*\[10, 5000\]"),
        (
            lambda c: PlantConfig(rig={"valve_max_pressure_pa": 20e5}),
            r"valve_max_pressure_pa.*\[50000, 1e\+06\]",
        ),
        (
            lambda c: PlantConfig(
                effects={"deadband": EffectSetting(True, {"opening_pressure_pa": 3e5})}
            ),
            r"deadband\.opening_pressure_pa.*\[0, 200000\]",
        ),
    ],
)
def test_out_of_range_parameter_is_refused_with_its_range(
    make: Callable[[PlantConfig], PlantConfig], expected: str
) -> None:
    with pytest.raises(ParameterError, match=expected):
        make(PlantConfig.thesis_rig())


def test_unknown_names_are_refused_listing_the_valid_ones() -> None:
    config = PlantConfig.thesis_rig()
    with pytest.raises(ParameterError, match="hysteresis") as err:
        config.with_effect("hysteresis")
    assert all(name in str(err.value) for name in EFFECTS)
    with pytest.raises(ParameterError, match="'friction'") as err:
        config.with_effect("play", friction=1.0)
    assert "friction_rad" in str(err.value) and "presliding_rad" in str(err.value)
    with pytest.raises(ParameterError, match="'gain'") as err:
        config.with_rig(gain=1.0)
    assert all(p.name in str(err.value) for p in RIG_PARAMS)
    with pytest.raises(ParameterError, match="'foo'"):
        PlantConfig(rig={"foo": 1.0})
    with pytest.raises(ParameterError, match="'foo'"):
        PlantConfig(effects={"foo": EffectSetting(True, {})})


@pytest.mark.parametrize("max_bar", [3.0, 2.0])
def test_commands_beyond_the_valve_range_clip(max_bar: float) -> None:
    config = _quiet_ideal().with_rig(valve_max_pressure_pa=bar_to_pa(max_bar))
    high = Plant(config).simulate(np.full(_samples(0.5), bar_to_pa(5.0)))
    assert high.pressure_measured_pa.max() <= bar_to_pa(max_bar)
    assert high.pressure_measured_pa[-1] == pytest.approx(bar_to_pa(max_bar), rel=1e-9)
    assert rad_to_deg(high.true_angle_rad[-1]) == pytest.approx(
        GAIN_DEG_PER_BAR * max_bar, rel=1e-6
    )
    low = Plant(config).simulate(np.full(_samples(0.5), -bar_to_pa(1.0)))
    np.testing.assert_array_equal(low.pressure_measured_pa, 0.0)
    np.testing.assert_array_equal(low.true_angle_rad, 0.0)
