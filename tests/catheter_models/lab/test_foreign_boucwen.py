"""Tests of the Bouc-Wen foreign plant: its scale, its loops and each effect it can hide.

Effects are measured the way a person at a rig would: a step or a hold with the effect and
without it (same catheter, same noise seed), and the difference read against the effect's
parameter. Noise-free runs (``bend_without_noise``) keep the read-outs exact where the
noise would only blur them; the noise itself is tested on ``simulate``.
"""

from __future__ import annotations

import ast
import itertools
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from foreign_plants.base import RANGES, Effect
from foreign_plants.boucwen import BoucWenPlant, drift_offset_rad
from plant_probes import (
    BAR,
    DT_S,
    RATE_HZ,
    hold,
    loop_width_deg,
    mean_time_s,
    ramp,
    sine_command,
    step_command,
)
from scipy.signal import bilinear, butter, lfilter


@pytest.fixture(scope="module")
def plant() -> BoucWenPlant:
    return BoucWenPlant(0)


# --- contract basics -------------------------------------------------------------------------


def test_deterministic_for_a_seed_and_different_for_another(plant: BoucWenPlant) -> None:
    _, cmd = sine_command(0.3, 3)
    effects = (Effect("creep", {"fraction": 0.2, "time_constant_s": 2.0}),)
    a = plant.simulate(cmd, RATE_HZ, effects, seed=3)
    b = plant.simulate(cmd, RATE_HZ, effects, seed=3)
    c = plant.simulate(cmd, RATE_HZ, effects, seed=4)
    assert a.shape == cmd.shape
    np.testing.assert_array_equal(a, b)
    assert np.std(a - c) > 0.5 * plant.noise_std_rad
    # Another variant is another catheter.
    assert np.max(np.abs(BoucWenPlant(7).simulate(cmd, RATE_HZ, seed=3) - a)) > math.radians(1)


@pytest.mark.parametrize("variant", [0, 5, 11])
def test_noise_std_matches_noise_std_rad(variant: int) -> None:
    p = BoucWenPlant(variant)
    cmd = np.concatenate([ramp(0.0, 2.0 * BAR, 2.0), hold(2.0 * BAR, 30.0)])
    hold_part = slice(round(4.0 * RATE_HZ), None)
    a = p.simulate(cmd, RATE_HZ, seed=1)[hold_part]
    b = p.simulate(cmd, RATE_HZ, seed=2)[hold_part]
    # The residual of a repeated run is the difference of two independent noises.
    assert np.std(a - b) / math.sqrt(2.0) == pytest.approx(p.noise_std_rad, rel=0.1)
    # A constant-pressure hold: the bend itself is constant, so its spread is the noise.
    assert np.std(a) == pytest.approx(p.noise_std_rad, rel=0.2)
    assert math.radians(0.03) <= p.noise_std_rad <= math.radians(0.081)


@pytest.mark.parametrize("variant", [0, 1, 2, 3, 4, 5, 6, 7])
def test_opening_knee_bend_at_3_bar_and_saturation(variant: int) -> None:
    p = BoucWenPlant(variant)
    cmd = np.concatenate([ramp(0.0, 3.0 * BAR, 30.0), hold(3.0 * BAR, 1.0)])
    bend = np.degrees(p.bend_without_noise(cmd, RATE_HZ))
    rising = slice(0, round(30.0 * RATE_HZ))
    c, y = cmd[rising], bend[rising]
    opening = p.params.opening_pa
    assert 0.5 * BAR <= opening <= 1.2 * BAR
    assert np.max(np.abs(y[c < 0.85 * opening])) < 0.25  # no bend below the opening
    assert np.interp(opening + 0.4 * BAR, c, y) > 2.0  # it does bend above it...
    slope = np.gradient(y, c)
    knee = (c > opening - 0.2 * BAR) & (c < opening + 0.4 * BAR)
    assert np.max(np.abs(np.diff(slope[knee]))) < 0.05 * np.max(slope)  # ...through a smooth knee
    assert 25.0 <= bend[-1] <= 50.0
    # Saturation: the top of the range is much stiffer than mid range.
    mid_slope = np.mean(slope[(c > 1.4 * BAR) & (c < 1.9 * BAR)])
    top_slope = np.mean(slope[c > 2.8 * BAR])
    assert top_slope < 0.5 * mid_slope


@pytest.mark.parametrize("variant", [0, 1, 2, 3])
def test_slow_loop_width_and_widening_with_frequency(variant: int) -> None:
    p = BoucWenPlant(variant)
    slow = loop_width_deg(p, 0.1)
    assert 2.0 <= slow <= 6.0
    widening = loop_width_deg(p, 0.8) - loop_width_deg(p, 0.2)
    assert 1.0 <= widening <= 3.0


def test_loading_and_unloading_differ(plant: BoucWenPlant) -> None:
    """After a reversal the bend sticks; the stick lasts longer on unloading (stronger
    friction there) than on loading."""
    cmd = np.concatenate([ramp(0.0, 2.2 * BAR, 4.0), ramp(2.2 * BAR, 1.2 * BAR, 10.0)])
    cmd = np.concatenate([cmd, ramp(1.2 * BAR, 2.2 * BAR, 10.0)])
    bend = np.degrees(plant.bend_without_noise(cmd, RATE_HZ))

    def stick_pa(k: int) -> float:
        # Pressure travelled after the reversal at sample k until the bend moved 1.5 deg.
        moved = np.abs(bend[k:] - bend[k]) > 1.5
        return abs(cmd[k + int(np.argmax(moved))] - cmd[k])

    top = round(4.0 * RATE_HZ)
    bottom = round(14.0 * RATE_HZ)
    assert stick_pa(top) > 1.1 * stick_pa(bottom)


def test_no_effect_means_no_lag_creep_drift_or_ringing(plant: BoucWenPlant) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR, after_s=20.0)
    bend = np.degrees(plant.bend_without_noise(cmd, RATE_HZ))
    settled = bend[k + round(0.1 * RATE_HZ)]
    assert abs(bend[-1] - settled) < 0.02  # nothing slow after 0.1 s
    assert np.max(bend[k:]) - bend[-1] < 0.02  # no overshoot
    assert mean_time_s(np.radians(bend), k, 1.0) < 0.02  # fast valve and stiff structure


@pytest.mark.parametrize("rate_hz", [100.0, 250.0, 1000.0])
@pytest.mark.parametrize("end", [0, 1])
def test_finite_for_any_command_and_effects(rate_hz: float, end: int) -> None:
    rng = np.random.default_rng(int(rate_hz) + end)
    n = round(40.0 * rate_hz)
    cmd = np.repeat(rng.uniform(-0.5 * BAR, 4.0 * BAR, n // 50 + 1), 50)[:n]  # steps, clipped
    cmd[: n // 4] = rng.uniform(0.0, 3.0 * BAR, n // 4)  # white noise: sub-sample chatter
    effects = tuple(Effect(name, {k: v[end] for k, v in r.items()}) for name, r in RANGES.items())
    for subset in (effects, effects[::2], ()):
        bend = BoucWenPlant(end * 17).simulate(cmd, rate_hz, subset, seed=1)
        assert bend.shape == cmd.shape
        assert np.all(np.isfinite(bend))
        # A lightly damped tip may overshoot a full-range step by most of the step.
        assert np.max(np.abs(bend)) < math.radians(150.0)


# --- catalogue effects -----------------------------------------------------------------------


@pytest.mark.parametrize("tau_s", [0.03, 0.1])
def test_pneumatic_lag_time_constant_at_mid_range(plant: BoucWenPlant, tau_s: float) -> None:
    lag = (Effect("pneumatic_lag", {"time_constant_s": tau_s}),)
    times = []
    for p0, p1 in ((1.35 * BAR, 1.65 * BAR), (1.65 * BAR, 1.35 * BAR)):
        cmd, k = step_command(p0, p1)
        base = mean_time_s(plant.bend_without_noise(cmd, RATE_HZ), k, 1.5)
        slow = mean_time_s(plant.bend_without_noise(cmd, RATE_HZ, lag), k, 1.5)
        times.append(slow - base)
    fill_s, vent_s = times
    assert fill_s == pytest.approx(tau_s, rel=0.4)
    assert vent_s == pytest.approx(tau_s, rel=0.4)
    assert math.sqrt(fill_s * vent_s) == pytest.approx(tau_s, rel=0.15)
    assert vent_s > 1.1 * fill_s  # venting is slower than filling
    # A large step is flow-limited: it ramps rather than relaxing exponentially, so its
    # mean time exceeds the small-signal one.
    cmd, k = np.concatenate([hold(0.0, 1.0), hold(2.8 * BAR, 2.0)]), round(RATE_HZ)
    assert mean_time_s(plant.bend_without_noise(cmd, RATE_HZ, lag), k, 2.0) > 1.2 * tau_s


@pytest.mark.parametrize("delay_s", [0.02, 0.043, 0.06])
def test_transport_delay_shifts_the_step_onset(plant: BoucWenPlant, delay_s: float) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR)
    effects = (Effect("transport_delay", {"delay_s": delay_s}),)

    def onset(bend: np.ndarray) -> int:
        rise = bend[k:] - bend[k - 1]
        return int(np.argmax(rise > 0.05 * rise[-1]))

    base = onset(plant.bend_without_noise(cmd, RATE_HZ))
    late = onset(plant.bend_without_noise(cmd, RATE_HZ, effects))
    assert abs((late - base) - delay_s * RATE_HZ) <= 1.5
    # The line also disperses: the delayed rise is a little slower than the direct one.
    fast = plant.bend_without_noise(cmd, RATE_HZ)
    slow = plant.bend_without_noise(cmd, RATE_HZ, effects)
    shift = round(delay_s * RATE_HZ)
    assert mean_time_s(slow[shift:], k, 1.0) > mean_time_s(fast, k, 1.0)


@pytest.mark.parametrize(("fraction", "tau_s"), [(0.12, 0.8), (0.22, 2.0)])
def test_creep_share_and_mean_time(plant: BoucWenPlant, fraction: float, tau_s: float) -> None:
    cmd = np.concatenate([hold(0.0, 1.0), hold(2.0 * BAR, 25.0 * tau_s)])
    k = round(1.0 * RATE_HZ)
    effects = (Effect("creep", {"fraction": fraction, "time_constant_s": tau_s}),)
    base = plant.bend_without_noise(cmd, RATE_HZ)
    creep = plant.bend_without_noise(cmd, RATE_HZ, effects)
    assert creep[-1] == pytest.approx(base[-1], rel=0.01)  # it all arrives in the end
    deficit = (base - creep)[k:] / base[-1]
    share = deficit[round(0.05 * RATE_HZ)]  # still missing once the fast dynamics settled
    assert share == pytest.approx(fraction, rel=0.25)
    mean_s = np.sum(deficit) * DT_S / share
    assert mean_s == pytest.approx(tau_s, rel=0.3)
    # Power-law, not one exponential: much is missing long after one mean time constant.
    assert deficit[round(3.0 * tau_s * RATE_HZ)] > 0.05 * share


@pytest.mark.parametrize(("f_hz", "zeta"), [(3.2, 0.06), (5.5, 0.14)])
def test_tip_rings_at_its_natural_frequency(plant: BoucWenPlant, f_hz: float, zeta: float) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR)
    effects = (Effect("tip_dynamics", {"natural_frequency_hz": f_hz, "damping_ratio": zeta}),)
    ring = plant.bend_without_noise(cmd, RATE_HZ, effects) - plant.bend_without_noise(cmd, RATE_HZ)
    ring = ring[k + round(0.08 * RATE_HZ) :]  # after the second mode has died out
    crossings = np.flatnonzero(np.diff(np.sign(ring)) != 0)[:7]
    # Linear interpolation of the crossing times.
    t0 = crossings + ring[crossings] / (ring[crossings] - ring[crossings + 1])
    f_ring = 0.5 * (len(t0) - 1) / ((t0[-1] - t0[0]) * DT_S)
    assert f_ring == pytest.approx(f_hz * math.sqrt(1 - zeta**2), rel=0.2)
    peaks = [np.max(np.abs(ring[a:b])) for a, b in itertools.pairwise(crossings)]
    decrement = math.log(peaks[0] / peaks[4]) / 2.0  # per period (half-cycle peaks)
    zeta_ring = decrement / math.hypot(2.0 * math.pi, decrement)
    assert zeta_ring == pytest.approx(zeta, rel=0.35)
    assert peaks[0] > math.radians(0.5)  # a fast 0.8 bar step visibly rings


@pytest.mark.parametrize("rate_deg_per_min", [-1.7, 0.6])
def test_drift_initial_slope(plant: BoucWenPlant, rate_deg_per_min: float) -> None:
    cmd = np.concatenate([ramp(0.0, 1.8 * BAR, 2.0), hold(1.8 * BAR, 58.0)])
    effects = (Effect("drift", {"rate_deg_per_min": rate_deg_per_min}),)
    trend = plant.simulate(cmd, RATE_HZ, effects, seed=5) - plant.simulate(cmd, RATE_HZ, seed=5)
    t = np.arange(1, cmd.size + 1) * DT_S
    first = t < 15.0
    slope_deg_per_min = math.degrees(np.polyfit(t[first], trend[first], 1)[0]) * 60.0
    assert slope_deg_per_min == pytest.approx(rate_deg_per_min, rel=0.3)
    assert abs(trend[0]) < math.radians(0.01)  # from the recording's start
    # Not a pure ramp: the room-temperature swing bends the trend within minutes.
    t5 = np.arange(1, round(300 * RATE_HZ)) * DT_S
    swing = drift_offset_rad(rate_deg_per_min, t5) - math.radians(rate_deg_per_min) / 60.0 * t5
    assert np.max(np.abs(swing)) > math.radians(0.3 * abs(rate_deg_per_min))


# --- effects outside the catalogue -----------------------------------------------------------


@pytest.mark.parametrize("tau_s", [0.03, 0.08, 0.12])
def test_sensor_lag_is_a_butterworth_of_that_time_constant(
    plant: BoucWenPlant, tau_s: float
) -> None:
    cmd, _ = step_command(1.2 * BAR, 2.0 * BAR)
    effects = (Effect("sensor_lag", {"time_constant_s": tau_s}),)
    base = plant.bend_without_noise(cmd, RATE_HZ)
    lagged = plant.bend_without_noise(cmd, RATE_HZ, effects)

    def filtered(tau: float) -> np.ndarray:
        w = 1.0 / tau
        b, a = bilinear([w**2], [1.0, math.sqrt(2.0) * w, w**2], fs=RATE_HZ)
        return lfilter(b, a, base)

    grid = tau_s * np.linspace(0.5, 1.5, 41)
    errors = [np.sqrt(np.mean((filtered(tau) - lagged) ** 2)) for tau in grid]
    assert grid[int(np.argmin(errors))] == pytest.approx(tau_s, rel=0.2)
    # The cut-off of the identified filter is 1 / (2 pi tau) (cross-check with scipy).
    b, a = butter(2, 1.0 / (2 * math.pi * tau_s), fs=RATE_HZ)
    assert np.sqrt(np.mean((lfilter(b, a, base) - lagged) ** 2)) < math.radians(0.3)


@pytest.mark.parametrize("gap_deg", [0.5, 1.2, 2.0])
def test_backlash_gap(plant: BoucWenPlant, gap_deg: float) -> None:
    tri = np.concatenate([ramp(1.0 * BAR, 2.4 * BAR, 8.0), ramp(2.4 * BAR, 1.0 * BAR, 8.0)])
    cmd = np.concatenate([ramp(0.0, 1.0 * BAR, 2.0), tri, tri, tri])
    effects = (Effect("backlash", {"gap_deg": gap_deg}),)
    base = plant.bend_without_noise(cmd, RATE_HZ)
    gapped = plant.bend_without_noise(cmd, RATE_HZ, effects)
    lost = np.degrees(base - gapped)
    k0 = round(2.0 * RATE_HZ) + 2 * tri.size  # last triangle
    up = lost[k0 + round(3.0 * RATE_HZ) : k0 + round(7.0 * RATE_HZ)]
    down = lost[k0 + round(11.0 * RATE_HZ) : k0 + round(15.0 * RATE_HZ)]
    assert np.median(up) - np.median(down) == pytest.approx(gap_deg, rel=0.1)
    assert np.max(lost) <= gap_deg + 1e-9
    assert np.min(lost) >= -1e-9
    # At the top reversal the measured bend stays while the section moves back by the gap.
    top = k0 + int(np.argmax(base[k0 : k0 + tri.size]))
    back = np.degrees(base[top] - base[top:])
    taken_up = int(np.argmax(back > 0.95 * gap_deg))
    assert taken_up > 0
    assert np.max(np.abs(gapped[top : top + taken_up] - gapped[top])) < 1e-9


@pytest.mark.parametrize("percent_per_min", [6.0, -4.0])
def test_gain_drift_rate(plant: BoucWenPlant, percent_per_min: float) -> None:
    # Approach in the direction the gain moves the bend, so the friction does not reverse.
    p0, p1 = (1.6 * BAR, 2.0 * BAR) if percent_per_min > 0 else (2.4 * BAR, 2.0 * BAR)
    cmd, k = step_command(p0, p1, after_s=60.0)
    effects = (Effect("gain_drift", {"percent_per_min": percent_per_min}),)
    ratio = plant.bend_without_noise(cmd, RATE_HZ, effects) / plant.bend_without_noise(cmd, RATE_HZ)
    t = np.arange(1, cmd.size + 1) * DT_S
    hold_part = slice(k + round(10.0 * RATE_HZ), None)
    slope = np.polyfit(t[hold_part], ratio[hold_part], 1)[0]
    assert slope * 60.0 * 100.0 == pytest.approx(percent_per_min, rel=0.25)


@pytest.mark.parametrize(("fraction", "tau_s"), [(0.16, 0.6), (0.28, 1.5)])
def test_slow_lag_share_and_time_constant(
    plant: BoucWenPlant, fraction: float, tau_s: float
) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR, before_s=8.0 * tau_s, after_s=10.0 * tau_s)
    effects = (Effect("slow_lag", {"fraction": fraction, "time_constant_s": tau_s}),)
    base = plant.bend_without_noise(cmd, RATE_HZ)
    slow = plant.bend_without_noise(cmd, RATE_HZ, effects)
    assert slow[k - 1] == pytest.approx(base[k - 1], abs=math.radians(0.05))  # settled before
    deficit = (base - slow)[k:] / (base[-1] - base[k - 1])
    share = deficit[round(0.05 * RATE_HZ)]
    assert share == pytest.approx(fraction, rel=0.2)
    mean_s = np.sum(deficit) * DT_S / share
    assert mean_s == pytest.approx(tau_s, rel=0.3)


def test_effects_combine(plant: BoucWenPlant) -> None:
    """Several effects at once: each still leaves its mark (delay and drift here)."""
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR, after_s=20.0)
    both = (
        Effect("transport_delay", {"delay_s": 0.04}),
        Effect("drift", {"rate_deg_per_min": 1.5}),
    )
    base = plant.bend_without_noise(cmd, RATE_HZ)
    bend = plant.bend_without_noise(cmd, RATE_HZ, both)
    assert np.all(np.abs(bend[k : k + 9] - bend[k - 1]) < math.radians(0.01))  # still dead
    t = np.arange(1, cmd.size + 1) * DT_S
    assert bend[-1] - base[-1] == pytest.approx(float(drift_offset_rad(1.5, t[-1:])[0]), rel=1e-6)


def test_module_imports_only_numpy_scipy_numba_and_the_contract() -> None:
    import foreign_plants.boucwen as module

    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    allowed = {"numpy", "scipy", "numba", "__future__"} | set(sys.stdlib_module_names)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level > 0:  # relative: only the shared contract
                assert node.module == "base", node.module
                continue
            names = [node.module or ""]
        else:
            continue
        for name in names:
            assert name.split(".")[0] in allowed, name
