"""The Maxwell-slip foreign plant: a rig-like scale, and each hidden effect as its parameter says.

These are the properties the lab's foreign-plant benchmarks rely on: if one fails, the lab
would be scored against a ground truth that does not hold what it claims.
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
from foreign_plants.maxwell_slip import P_MAX_PA, MaxwellSlipPlant

RATE_HZ = 250.0
DEG = math.pi / 180.0


@pytest.fixture(scope="module")
def plant() -> MaxwellSlipPlant:
    return MaxwellSlipPlant(0)


def hold(*levels_s: tuple[float, float]) -> np.ndarray:
    """Plateaus (pressure [Pa], duration [s]) back to back."""
    return np.concatenate([np.full(round(d * RATE_HZ), p) for p, d in levels_s])


def sine(freq_hz: float, cycles: int, low_pa: float = 0.0, high_pa: float = P_MAX_PA):
    t = np.arange(round(cycles / freq_hz * RATE_HZ)) / RATE_HZ
    mid, amp = 0.5 * (low_pa + high_pa), 0.5 * (high_pa - low_pa)
    return t, mid - amp * np.cos(2 * np.pi * freq_hz * t)


def loop_width_deg(cmd: np.ndarray, bend: np.ndarray, at_pa: float, skip: int) -> float:
    """Unloading minus loading bend [deg] near one pressure, after ``skip`` samples."""
    c, y = cmd[skip:], bend[skip:]
    rising = np.gradient(c) > 0
    near = np.abs(c - at_pa) < 0.02e5
    return float(np.degrees(y[near & ~rising].mean() - y[near & rising].mean()))


def mean_time_s(y: np.ndarray, start: int, stop: int) -> float:
    """First moment of a step response between samples ``start`` and ``stop`` [s]."""
    before, after = y[start - 1], y[stop - 25 : stop].mean()
    return float(np.sum((after - y[start:stop]) / (after - before))) / RATE_HZ


# ---------------------------------------------------------------------------- contract


def test_module_imports_only_numpy_scipy_numba_stdlib_and_base() -> None:
    import foreign_plants.maxwell_slip as module

    tree = ast.parse(Path(module.__file__).read_text())
    allowed = {"numpy", "scipy", "numba", "__future__"} | set(sys.stdlib_module_names)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            roots = [alias.name.split(".")[0] for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: only the package's own contract
                assert node.module == "base", ast.dump(node)
                continue
            roots = [(node.module or "").split(".")[0]]
            if node.module == "foreign_plants.base":
                continue
        else:
            continue
        for root in roots:
            assert root in allowed, f"imports {root}"


def test_same_seed_same_output_other_seed_other_noise(plant: MaxwellSlipPlant) -> None:
    _, cmd = sine(0.5, 2)
    effects = [Effect("creep", {"fraction": 0.2, "time_constant_s": 1.0})]
    a = plant.simulate(cmd, RATE_HZ, effects, seed=3)
    b = plant.simulate(cmd, RATE_HZ, effects, seed=3)
    c = plant.simulate(cmd, RATE_HZ, effects, seed=4)
    assert a.shape == cmd.shape
    np.testing.assert_array_equal(a, b)
    assert np.abs(a - c).max() > plant.noise_std_rad


@pytest.mark.parametrize("variant", [0, 1, 2, 3])
def test_noise_std_is_what_the_plant_says(variant: int) -> None:
    plant = MaxwellSlipPlant(variant)
    assert 0.03 * DEG <= plant.noise_std_rad <= 0.08 * DEG
    _, cmd = sine(0.3, 3)
    diff = plant.simulate(cmd, RATE_HZ, seed=1) - plant.simulate(cmd, RATE_HZ, seed=2)
    assert np.std(diff) / math.sqrt(2) == pytest.approx(plant.noise_std_rad, rel=0.2)
    # And the noise rides on the clean bend, nothing else.
    clean, _ = plant.simulate_clean(cmd, RATE_HZ)
    resid = plant.simulate(cmd, RATE_HZ, seed=5) - clean
    assert np.std(resid) == pytest.approx(plant.noise_std_rad, rel=0.2)
    assert abs(np.mean(resid)) < 0.2 * plant.noise_std_rad


# ---------------------------------------------------------------------------- scale


@pytest.mark.parametrize("variant", [0, 1, 2, 3, 4])
def test_knee_full_bend_and_saturation(variant: int) -> None:
    plant = MaxwellSlipPlant(variant)
    p_open = plant.opening_pressure_pa
    assert 0.5e5 <= p_open <= 1.2e5
    ramp = np.linspace(0.0, P_MAX_PA, round(30 * RATE_HZ))  # 0.1 bar/s: quasi-static
    bend = plant.simulate(np.concatenate([ramp, np.full(250, P_MAX_PA)]), RATE_HZ, seed=0)
    bend, tail = bend[: ramp.size], bend[ramp.size :]
    assert np.abs(bend[ramp < p_open - 0.15e5]).max() < 0.3 * DEG
    assert 25 * DEG <= tail.mean() <= 50 * DEG
    # Smooth knee: the bend starts within the knee and is well on its way 0.4 bar above.
    assert bend[np.searchsorted(ramp, p_open + 0.1e5)] < 2.5 * DEG
    assert bend[np.searchsorted(ramp, p_open + 0.4e5)] > 3 * DEG

    def slope(lo: float, hi: float) -> float:
        i, j = np.searchsorted(ramp, [lo, hi])
        return float(bend[j] - bend[i]) / (hi - lo)

    # Saturation: the top tenth of the range bends at most half as fast as mid-range.
    assert slope(2.7e5, 3.0e5) < 0.6 * slope(1.4e5, 2.0e5)


def test_quasi_static_loop_is_2_to_6_deg_and_asymmetric(plant: MaxwellSlipPlant) -> None:
    _, cmd = sine(0.05, 2)
    bend, _ = plant.simulate_clean(cmd, RATE_HZ)
    half = cmd.size // 2
    p_mid = 0.5 * (plant.opening_pressure_pa + P_MAX_PA)
    width = loop_width_deg(cmd, bend, p_mid, half)
    assert 2.0 < width < 6.0
    # Loading and unloading differ: the pull's break-away is larger than the release's, so
    # the loading branch sits further from the frictionless curve than the unloading one.
    frictionless = math.degrees(plant.static_bend_rad(p_mid))
    c, y = cmd[half:], np.degrees(bend[half:])
    rising, near = np.gradient(c) > 0, np.abs(c - p_mid) < 0.02e5
    below = frictionless - y[near & rising].mean()
    above = y[near & ~rising].mean() - frictionless
    assert below > 1.2 * above > 0


def test_loops_widen_with_frequency(plant: MaxwellSlipPlant) -> None:
    p_mid = 0.5 * (plant.opening_pressure_pa + P_MAX_PA)
    widths = []
    for freq in (0.2, 0.8):
        _, cmd = sine(freq, 3)
        bend, _ = plant.simulate_clean(cmd, RATE_HZ)
        widths.append(loop_width_deg(cmd, bend, p_mid, cmd.size // 3))
    assert 1.0 < widths[1] - widths[0] < 3.0


def test_base_plant_is_fast_and_still(plant: MaxwellSlipPlant) -> None:
    cmd = hold((1.35e5, 2.0), (1.65e5, 30.0))
    bend, _ = plant.simulate_clean(cmd, RATE_HZ)
    n = round(2.0 * RATE_HZ)
    assert mean_time_s(bend, n, n + 250) < 0.015  # valve, wire and slider viscosity
    # No creep, drift or slow chamber: the bend at 1 s is the bend at 30 s.
    assert abs(bend[n + 250] - bend[-1]) < 0.01 * DEG


def test_simulates_70000_samples_with_all_effects(plant: MaxwellSlipPlant) -> None:
    rng = np.random.default_rng(0)
    effects = [Effect.draw(name, rng) for name in RANGES]
    _, cmd = sine(0.3, 84)
    bend = plant.simulate(cmd[:70_000], RATE_HZ, effects)
    assert np.all(np.isfinite(bend))


@pytest.mark.parametrize("rate_hz", [100.0, 333.0, 1000.0])
def test_finite_for_any_command_and_strongest_effects(rate_hz: float) -> None:
    rng = np.random.default_rng(int(rate_hz))
    n = round(15 * rate_hz)
    cmds = [
        rng.uniform(-1e5, 4e5, n),
        np.repeat(rng.choice([0.0, P_MAX_PA], n // 25 + 1), 25)[:n],
    ]
    for k, cmd in enumerate(cmds):
        plant = MaxwellSlipPlant(int(rng.integers(1, 1000)))
        pick = 0 if k == 0 else 1
        effects = [
            Effect(name, {key: bounds[pick] for key, bounds in params.items()})
            for name, params in RANGES.items()
        ]
        bend = plant.simulate(cmd, rate_hz, effects, seed=k)
        assert bend.shape == cmd.shape
        assert np.all(np.isfinite(bend)) and np.abs(bend).max() < math.pi / 2


# ---------------------------------------------------------------------------- effects


@pytest.mark.parametrize("tau_s", [0.02, 0.06, 0.12])
def test_pneumatic_lag_has_its_time_constant_at_mid_range(
    plant: MaxwellSlipPlant, tau_s: float
) -> None:
    n = round(3 * RATE_HZ)
    cmd = hold((1.35e5, 3), (1.65e5, 3), (1.35e5, 3))
    bend0, pres0 = plant.simulate_clean(cmd, RATE_HZ)
    bend, pres = plant.simulate_clean(
        cmd, RATE_HZ, [Effect("pneumatic_lag", {"time_constant_s": tau_s})]
    )
    # The muscle pressure's small-signal lag (mean time of up and down steps) ...
    lag = [mean_time_s(pres, i, i + n) - mean_time_s(pres0, i, i + n) for i in (n, 2 * n)]
    assert np.mean(lag) == pytest.approx(tau_s, rel=0.15)
    # ... and what the bend shows of it on the up step.
    seen = mean_time_s(bend, n, 2 * n) - mean_time_s(bend0, n, 2 * n)
    assert seen == pytest.approx(tau_s, rel=0.4)


@pytest.mark.parametrize("delay_s", [0.02, 0.045, 0.06])
def test_transport_delay_shifts_the_response(plant: MaxwellSlipPlant, delay_s: float) -> None:
    cmd = hold((1.0e5, 2.0), (2.0e5, 1.0))
    bend0, _ = plant.simulate_clean(cmd, RATE_HZ)
    bend, _ = plant.simulate_clean(cmd, RATE_HZ, [Effect("transport_delay", {"delay_s": delay_s})])
    thr = bend0[499] + 0.05 * (bend0[-1] - bend0[499])
    shift = int(np.argmax(bend > thr)) - int(np.argmax(bend0 > thr))
    assert abs(shift - delay_s * RATE_HZ) <= 1.0


@pytest.mark.parametrize(("fraction", "tau_s"), [(0.12, 0.6), (0.25, 4.0)])
def test_creep_adds_its_share_with_its_mean_time(
    plant: MaxwellSlipPlant, fraction: float, tau_s: float
) -> None:
    cmd = hold((plant.mid_pressure_pa, 15 * tau_s + 10))
    bend0, _ = plant.simulate_clean(cmd, RATE_HZ)
    bend, _ = plant.simulate_clean(
        cmd, RATE_HZ, [Effect("creep", {"fraction": fraction, "time_constant_s": tau_s})]
    )
    i0 = round(0.04 * RATE_HZ)  # the fast part of the step is over
    assert bend[i0] == pytest.approx(bend0[i0], rel=0.05)
    final = bend[-1]
    assert (final - bend[i0]) / final == pytest.approx(fraction, rel=0.2)
    mean = float(np.sum(final - bend[i0:])) / (final - bend[i0]) / RATE_HZ
    assert mean == pytest.approx(tau_s, rel=0.3)
    assert final > bend[round(tau_s * RATE_HZ)] > bend[i0]  # still creeping after tau


@pytest.mark.parametrize(("freq_hz", "zeta"), [(3.0, 0.05), (4.5, 0.1), (6.0, 0.15)])
def test_tip_rings_at_its_frequency_and_damping(
    plant: MaxwellSlipPlant, freq_hz: float, zeta: float
) -> None:
    cmd = hold((1.0e5, 2.0), (plant.mid_pressure_pa, 3.0))
    effect = Effect("tip_dynamics", {"natural_frequency_hz": freq_hz, "damping_ratio": zeta})
    bend = plant.simulate(cmd, RATE_HZ, [effect], seed=0)
    ring = bend[500:] - bend[-125:].mean()
    crossings = np.flatnonzero(np.diff(np.sign(ring)) != 0)[:6]
    freq = RATE_HZ / (2 * np.mean(np.diff(crossings)))
    assert freq == pytest.approx(freq_hz, rel=0.2)
    peaks = [np.abs(ring[a:b]).max() for a, b in itertools.pairwise(crossings)]
    decrement = float(np.mean(np.log(np.array(peaks[:-1]) / np.array(peaks[1:]))))
    assert decrement / math.hypot(math.pi, decrement) == pytest.approx(zeta, rel=0.4)
    # Without the effect the tip follows the wire: no overshoot.
    plain, _ = plant.simulate_clean(cmd, RATE_HZ)
    assert plain.max() - plain[-1] < 0.05 * DEG < ring.max()


@pytest.mark.parametrize("rate_deg_per_min", [0.5, -2.0])
def test_drift_starts_at_its_rate(plant: MaxwellSlipPlant, rate_deg_per_min: float) -> None:
    cmd = hold((1.5e5, 90.0))
    bend0, _ = plant.simulate_clean(cmd, RATE_HZ)
    bend = plant.simulate(
        cmd, RATE_HZ, [Effect("drift", {"rate_deg_per_min": rate_deg_per_min})], seed=0
    )
    t_min = np.arange(cmd.size) / RATE_HZ / 60.0
    early = t_min < 0.5
    slope = np.polyfit(t_min[early], np.degrees(bend - bend0)[early], 1)[0]
    assert slope == pytest.approx(rate_deg_per_min, rel=0.3)
    # Thermal: it levels off (the slope in the third half-minute is smaller).
    late = (t_min > 1.0) & (t_min < 1.5)
    assert abs(np.polyfit(t_min[late], np.degrees(bend - bend0)[late], 1)[0]) < abs(slope)


@pytest.mark.parametrize("tau_s", [0.03, 0.12])
def test_sensor_lag_filters_the_measured_bend(plant: MaxwellSlipPlant, tau_s: float) -> None:
    n = round(2 * RATE_HZ)
    cmd = hold((1.0e5, 2), (2.0e5, 2), (1.0e5, 2))
    bend0, pres0 = plant.simulate_clean(cmd, RATE_HZ)
    bend, pres = plant.simulate_clean(
        cmd, RATE_HZ, [Effect("sensor_lag", {"time_constant_s": tau_s})]
    )
    np.testing.assert_array_equal(pres, pres0)  # only the sensor, not the muscle
    for i in (n, 2 * n):
        lag = mean_time_s(bend, i, i + n) - mean_time_s(bend0, i, i + n)
        assert lag == pytest.approx(tau_s, rel=0.1)


@pytest.mark.parametrize("gap_deg", [0.5, 2.0])
def test_backlash_holds_the_bend_through_the_gap(plant: MaxwellSlipPlant, gap_deg: float) -> None:
    _, cmd = sine(0.1, 2)
    p_mid = 0.5 * (plant.opening_pressure_pa + P_MAX_PA)
    bend0, _ = plant.simulate_clean(cmd, RATE_HZ)
    bend, _ = plant.simulate_clean(cmd, RATE_HZ, [Effect("backlash", {"gap_deg": gap_deg})])
    half = cmd.size // 2
    extra = loop_width_deg(cmd, bend, p_mid, half) - loop_width_deg(cmd, bend0, p_mid, half)
    assert extra == pytest.approx(gap_deg, rel=0.2)
    # After the top of the sine the tip stays while the wire backs through the gap.
    top = half + int(np.argmax(cmd[half:]))
    wire_back = np.degrees(bend0[top] - bend0[top:])
    inside = np.flatnonzero(wire_back < 0.8 * gap_deg)
    inside = inside[inside < np.argmax(wire_back > gap_deg)]
    assert np.ptp(bend[top + inside]) < 0.05 * DEG


@pytest.mark.parametrize("percent_per_min", [5.0, -8.0])
def test_gain_drift_changes_the_bend_at_its_rate(
    plant: MaxwellSlipPlant, percent_per_min: float
) -> None:
    t, cmd = sine(0.5, 30, plant.mid_pressure_pa - 0.2e5, plant.mid_pressure_pa + 0.2e5)
    bend0, _ = plant.simulate_clean(cmd, RATE_HZ)
    bend, _ = plant.simulate_clean(
        cmd, RATE_HZ, [Effect("gain_drift", {"percent_per_min": percent_per_min})]
    )
    per = round(RATE_HZ / 0.5)
    ratio = [bend[i : i + per].mean() / bend0[i : i + per].mean() for i in range(0, t.size, per)]
    minutes = (np.arange(len(ratio)) + 0.5) * per / RATE_HZ / 60
    slope = np.polyfit(minutes, ratio, 1)[0] * 100
    assert slope == pytest.approx(percent_per_min, rel=0.3)


@pytest.mark.parametrize(("fraction", "tau_s"), [(0.15, 1.0), (0.3, 3.0)])
def test_slow_lag_brings_its_share_late(
    plant: MaxwellSlipPlant, fraction: float, tau_s: float
) -> None:
    n = round(5 * RATE_HZ)
    cmd = hold((1.2e5, 5), (2.2e5, 8 * tau_s))
    bend0, pres0 = plant.simulate_clean(cmd, RATE_HZ)
    effect = Effect("slow_lag", {"fraction": fraction, "time_constant_s": tau_s})
    bend, pres = plant.simulate_clean(cmd, RATE_HZ, [effect])
    np.testing.assert_array_equal(pres, pres0)  # the main chamber itself is fast
    # At the end the bend is the plain one; right after the step a share is missing.
    assert bend[-1] == pytest.approx(bend0[-1], abs=0.05 * DEG)
    fast = n + round(0.05 * RATE_HZ)
    missing = (bend0[fast] - bend[fast]) / (bend0[-1] - bend0[n - 1])
    assert missing == pytest.approx(fraction, rel=0.3)
    late = float(np.sum(bend0[-1] - bend[fast:])) / (bend0[-1] - bend[fast]) / RATE_HZ
    assert late == pytest.approx(tau_s, rel=0.3)
