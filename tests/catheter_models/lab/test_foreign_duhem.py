"""Tests of the Duhem foreign plant (the third law): its scale, its loops and its effects.

As for the other foreign plants, each effect is read the way a person at a rig would: the
same catheter with the effect and without it, the difference read against the effect's
parameter, on noise-free runs where noise would only blur the read-out.
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
from foreign_plants.duhem import DuhemPlant, drift_offset_rad
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


@pytest.fixture(scope="module")
def plant() -> DuhemPlant:
    return DuhemPlant(0)


# --- contract basics -------------------------------------------------------------------------


def test_deterministic_for_a_seed_and_different_for_another(plant: DuhemPlant) -> None:
    _, cmd = sine_command(0.3, 3)
    effects = (Effect("creep", {"fraction": 0.2, "time_constant_s": 2.0}),)
    a = plant.simulate(cmd, RATE_HZ, effects, seed=3)
    b = plant.simulate(cmd, RATE_HZ, effects, seed=3)
    c = plant.simulate(cmd, RATE_HZ, effects, seed=4)
    assert a.shape == cmd.shape
    np.testing.assert_array_equal(a, b)
    assert np.std(a - c) > 0.5 * plant.noise_std_rad
    assert np.max(np.abs(DuhemPlant(7).simulate(cmd, RATE_HZ, seed=3) - a)) > math.radians(1)


@pytest.mark.parametrize("variant", [0, 5, 11])
def test_noise_std_matches_noise_std_rad(variant: int) -> None:
    p = DuhemPlant(variant)
    cmd = np.concatenate([ramp(0.0, 2.0 * BAR, 2.0), hold(2.0 * BAR, 30.0)])
    hold_part = slice(round(4.0 * RATE_HZ), None)
    a = p.simulate(cmd, RATE_HZ, seed=1)[hold_part]
    b = p.simulate(cmd, RATE_HZ, seed=2)[hold_part]
    assert np.std(a - b) / math.sqrt(2.0) == pytest.approx(p.noise_std_rad, rel=0.1)
    assert np.std(a) == pytest.approx(p.noise_std_rad, rel=0.2)  # a hold does not move
    assert math.radians(0.03) <= p.noise_std_rad <= math.radians(0.081)


@pytest.mark.parametrize("variant", [0, 1, 2, 3, 4, 5, 6, 7])
def test_opening_knee_bend_at_3_bar_and_saturation(variant: int) -> None:
    p = DuhemPlant(variant)
    cmd = np.concatenate([ramp(0.0, 3.0 * BAR, 30.0), hold(3.0 * BAR, 1.0)])
    bend = np.degrees(p.bend_without_noise(cmd, RATE_HZ))
    rising = slice(0, round(30.0 * RATE_HZ))
    c, y = cmd[rising], bend[rising]
    opening = p.params.opening_pa
    assert 0.6 * BAR <= opening <= 1.1 * BAR
    assert np.max(np.abs(y[c < 0.85 * opening])) < 0.25  # no bend below the opening
    assert np.interp(opening + 0.4 * BAR, c, y) > 2.0
    slope = np.gradient(y, c)
    knee = (c > opening - 0.2 * BAR) & (c < opening + 0.4 * BAR)
    assert np.max(np.abs(np.diff(slope[knee]))) < 0.05 * np.max(slope)  # a smooth knee
    assert 25.0 <= bend[-1] <= 50.0
    mid_slope = np.mean(slope[(c > 1.4 * BAR) & (c < 1.9 * BAR)])
    assert np.mean(slope[c > 2.8 * BAR]) < 0.5 * mid_slope  # the wall saturates the bend


@pytest.mark.parametrize("variant", [0, 1, 2, 3])
def test_slow_loop_width_and_widening_with_frequency(variant: int) -> None:
    p = DuhemPlant(variant)
    assert 2.0 <= loop_width_deg(p, 0.1) <= 6.0
    assert 1.0 <= loop_width_deg(p, 0.8) - loop_width_deg(p, 0.2) <= 3.0


def test_minor_loops_are_not_congruent_and_do_not_close(plant: DuhemPlant) -> None:
    """A Preisach-type law draws the same minor loop, shifted, whatever came before, and a
    loop closes where it started (return-point memory). This law does neither: the same
    1.4-1.8 bar swing after a rise from vented and after a descent from 2.8 bar draws loops
    of different shapes, and the first loop after each does not close."""
    shapes, misses = [], []
    for top in (None, 2.8 * BAR):
        parts = [ramp(0.0, 1.4 * BAR, 3.0)]
        if top is not None:
            parts = [ramp(0.0, top, 3.0), ramp(top, 1.4 * BAR, 3.0)]
        for _ in range(3):
            parts += [ramp(1.4 * BAR, 1.8 * BAR, 2.0), ramp(1.8 * BAR, 1.4 * BAR, 2.0)]
        y = np.degrees(plant.bend_without_noise(np.concatenate(parts), RATE_HZ))
        n, period = y.size, round(4.0 * RATE_HZ)
        second = y[n - 2 * period - 1 : n - period]  # turning point at 1.4 bar to the next
        shapes.append(second - second[0])
        misses.append(abs(second[-1] - second[0]))
    assert np.max(np.abs(shapes[0] - shapes[1])) > 0.05
    assert max(misses) > 0.05


def test_pulling_and_releasing_differ(plant: DuhemPlant) -> None:
    """Release friction is stronger: after a reversal at the top the bend holds over a longer
    pressure span than after a reversal at the bottom."""
    cmd = np.concatenate([ramp(0.0, 2.2 * BAR, 4.0), ramp(2.2 * BAR, 1.2 * BAR, 10.0)])
    cmd = np.concatenate([cmd, ramp(1.2 * BAR, 2.2 * BAR, 10.0)])
    bend = np.degrees(plant.bend_without_noise(cmd, RATE_HZ))

    def stick_pa(k: int) -> float:
        moved = np.abs(bend[k:] - bend[k]) > 1.5
        return abs(cmd[k + int(np.argmax(moved))] - cmd[k])

    assert stick_pa(round(4.0 * RATE_HZ)) > 1.1 * stick_pa(round(14.0 * RATE_HZ))


def test_no_effect_means_no_lag_creep_drift_or_ringing(plant: DuhemPlant) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR, after_s=20.0)
    bend = np.degrees(plant.bend_without_noise(cmd, RATE_HZ))
    settled = bend[k + round(0.1 * RATE_HZ)]
    assert abs(bend[-1] - settled) < 0.02  # nothing slow after 0.1 s
    assert np.max(bend[k:]) - bend[-1] < 0.02  # no overshoot
    assert mean_time_s(np.radians(bend), k, 1.0) < 0.02  # fast valve, stiff section


@pytest.mark.parametrize("rate_hz", [100.0, 250.0, 1000.0])
@pytest.mark.parametrize("end", [0, 1])
def test_finite_for_any_command_and_effects(rate_hz: float, end: int) -> None:
    rng = np.random.default_rng(int(rate_hz) + end)
    n = round(40.0 * rate_hz)
    cmd = np.repeat(rng.uniform(-0.5 * BAR, 4.0 * BAR, n // 50 + 1), 50)[:n]
    cmd[: n // 4] = rng.uniform(0.0, 3.0 * BAR, n // 4)  # white noise: sub-sample chatter
    effects = tuple(Effect(name, {k: v[end] for k, v in r.items()}) for name, r in RANGES.items())
    for subset in (effects, effects[::2], ()):
        bend = DuhemPlant(end * 17).simulate(cmd, rate_hz, subset, seed=1)
        assert bend.shape == cmd.shape
        assert np.all(np.isfinite(bend))
        assert np.max(np.abs(bend)) < math.radians(150.0)


# --- catalogue effects -----------------------------------------------------------------------


@pytest.mark.parametrize("tau_s", [0.03, 0.1])
def test_pneumatic_lag_at_mid_range_and_slower_near_vented(plant: DuhemPlant, tau_s: float) -> None:
    lag = (Effect("pneumatic_lag", {"time_constant_s": tau_s}),)

    def added_s(p0: float, p1: float) -> float:
        cmd, k = step_command(p0, p1)
        base = mean_time_s(plant.bend_without_noise(cmd, RATE_HZ), k, 1.5)
        return mean_time_s(plant.bend_without_noise(cmd, RATE_HZ, lag), k, 1.5) - base

    fill_s, vent_s = added_s(1.35 * BAR, 1.65 * BAR), added_s(1.65 * BAR, 1.35 * BAR)
    assert math.sqrt(fill_s * vent_s) == pytest.approx(tau_s, rel=0.15)
    assert vent_s > 1.1 * fill_s  # the exhaust port is the smaller one
    # Laminar compressible flow: the same step is slower at a lower absolute pressure.
    assert added_s(1.05 * BAR, 1.25 * BAR) > 1.1 * added_s(2.35 * BAR, 2.55 * BAR)


@pytest.mark.parametrize("delay_s", [0.02, 0.043, 0.06])
def test_transport_delay_is_a_dead_time_with_dispersion(plant: DuhemPlant, delay_s: float) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR)
    effects = (Effect("transport_delay", {"delay_s": delay_s}),)
    fast = plant.bend_without_noise(cmd, RATE_HZ)
    slow = plant.bend_without_noise(cmd, RATE_HZ, effects)
    # The wave front arrives on average delay_s late...
    extra_s = mean_time_s(slow, k, 1.0) - mean_time_s(fast, k, 1.0)
    assert extra_s == pytest.approx(delay_s, abs=1.5 * DT_S)
    # ...nothing arrives before the dead time, and the front is rounded, not shifted whole.
    dead = round(0.8 * delay_s * RATE_HZ) - 1
    assert np.all(np.abs(slow[k : k + dead] - slow[k - 1]) < 1e-9)
    shifted = fast[k - round(delay_s * RATE_HZ) : k - round(delay_s * RATE_HZ) + 100]
    assert np.max(np.abs(slow[k : k + 100] - shifted)) > math.radians(0.3)


@pytest.mark.parametrize(("fraction", "tau_s"), [(0.12, 0.8), (0.22, 2.0)])
def test_creep_share_mean_time_and_load_dependence(
    plant: DuhemPlant, fraction: float, tau_s: float
) -> None:
    effects = (Effect("creep", {"fraction": fraction, "time_constant_s": tau_s}),)

    def deficit(p_pa: float) -> tuple[np.ndarray, float]:
        cmd = np.concatenate([hold(0.0, 1.0), hold(p_pa, 25.0 * tau_s)])
        base = plant.bend_without_noise(cmd, RATE_HZ)
        creep = plant.bend_without_noise(cmd, RATE_HZ, effects)
        assert creep[-1] == pytest.approx(base[-1], rel=0.01)  # it all arrives
        d = (base - creep)[round(RATE_HZ) :] / base[-1]
        return d, float(d[round(0.05 * RATE_HZ)])

    d, share = deficit(2.0 * BAR)
    assert share == pytest.approx(fraction, rel=0.25)
    assert np.sum(d) * DT_S / share == pytest.approx(tau_s, rel=0.3)
    assert d[round(3.0 * tau_s * RATE_HZ)] > 0.03 * share  # a spread, not one exponential
    assert deficit(2.6 * BAR)[1] > 1.1 * share > 1.2 * deficit(1.4 * BAR)[1]  # Schapery


def test_tip_rings_at_its_natural_frequency(plant: DuhemPlant) -> None:
    f_hz, zeta = 4.5, 0.08
    cmd, k = step_command(1.3 * BAR, 1.6 * BAR)
    effects = (Effect("tip_dynamics", {"natural_frequency_hz": f_hz, "damping_ratio": zeta}),)
    ring = plant.bend_without_noise(cmd, RATE_HZ, effects) - plant.bend_without_noise(cmd, RATE_HZ)
    ring = ring[k + round(0.05 * RATE_HZ) :]
    crossings = np.flatnonzero(np.diff(np.sign(ring)) != 0)[:7]
    t0 = crossings + ring[crossings] / (ring[crossings] - ring[crossings + 1])
    f_ring = 0.5 * (len(t0) - 1) / ((t0[-1] - t0[0]) * DT_S)
    assert f_ring == pytest.approx(f_hz * math.sqrt(1 - zeta**2), rel=0.15)
    peaks = [np.max(np.abs(ring[a:b])) for a, b in itertools.pairwise(crossings)]
    decrement = math.log(peaks[0] / peaks[4]) / 2.0
    zeta_ring = decrement / math.hypot(2.0 * math.pi, decrement)
    assert zeta_ring == pytest.approx(zeta, rel=0.4)
    assert peaks[0] > math.radians(0.5)


def test_tip_rings_faster_higher_up(plant: DuhemPlant) -> None:
    effects = (Effect("tip_dynamics", {"natural_frequency_hz": 4.0, "damping_ratio": 0.05}),)

    def ring_hz(p0: float, p1: float) -> float:
        cmd, k = step_command(p0, p1)
        ring = plant.bend_without_noise(cmd, RATE_HZ, effects) - plant.bend_without_noise(
            cmd, RATE_HZ
        )
        ring = ring[k + round(0.05 * RATE_HZ) :]
        crossings = np.flatnonzero(np.diff(np.sign(ring)) != 0)[:7]
        return 0.5 * (len(crossings) - 1) / ((crossings[-1] - crossings[0]) * DT_S)

    assert ring_hz(2.2 * BAR, 2.5 * BAR) > 1.05 * ring_hz(1.0 * BAR, 1.3 * BAR)


@pytest.mark.parametrize("rate_deg_per_min", [-1.7, 0.6])
def test_drift_initial_slope_and_warm_up(plant: DuhemPlant, rate_deg_per_min: float) -> None:
    cmd = np.concatenate([ramp(0.0, 1.8 * BAR, 2.0), hold(1.8 * BAR, 58.0)])
    effects = (Effect("drift", {"rate_deg_per_min": rate_deg_per_min}),)
    trend = plant.simulate(cmd, RATE_HZ, effects, seed=5) - plant.simulate(cmd, RATE_HZ, seed=5)
    t = np.arange(1, cmd.size + 1) * DT_S
    first = t < 15.0
    slope_deg_per_min = math.degrees(np.polyfit(t[first], trend[first], 1)[0]) * 60.0
    assert slope_deg_per_min == pytest.approx(rate_deg_per_min, rel=0.3)
    assert abs(trend[0]) < math.radians(0.01)
    # A warm-up: after 10 minutes it moves at under a third of its first rate.
    late = np.diff(drift_offset_rad(rate_deg_per_min, np.array([600.0, 660.0])))[0]
    assert abs(math.degrees(late)) < abs(rate_deg_per_min) / 3.0


# --- effects outside the catalogue -----------------------------------------------------------


@pytest.mark.parametrize("tau_s", [0.03, 0.08, 0.12])
def test_sensor_lag_is_a_boxcar_of_twice_the_time_constant(plant: DuhemPlant, tau_s: float) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR)
    effects = (Effect("sensor_lag", {"time_constant_s": tau_s}),)
    base = plant.bend_without_noise(cmd, RATE_HZ)
    lagged = plant.bend_without_noise(cmd, RATE_HZ, effects)
    extra_s = mean_time_s(lagged, k, 1.0) - mean_time_s(base, k, 1.0)
    assert extra_s == pytest.approx(tau_s, abs=DT_S)
    # A finite window, not a filter with a tail: a boxcar of 2 tau over the samples
    # reproduces it (to the sub-steps it averages over), a one-pole lag of tau does not.
    m = round(2.0 * tau_s * RATE_HZ)
    padded = np.concatenate([np.full(m, base[0]), base])
    boxcar = np.convolve(padded, np.ones(m + 1) / (m + 1), mode="valid")[: base.size]
    alpha = 1.0 - math.exp(-DT_S / tau_s)
    pole = np.empty_like(base)
    acc = base[0]
    for i, b in enumerate(base):
        acc += alpha * (b - acc)
        pole[i] = acc
    miss_boxcar = np.max(np.abs(boxcar - lagged)[k:])
    assert miss_boxcar < 0.3 * np.max(np.abs(pole - lagged)[k:])


@pytest.mark.parametrize("gap_deg", [0.5, 1.2, 2.0])
def test_backlash_gap(plant: DuhemPlant, gap_deg: float) -> None:
    tri = np.concatenate([ramp(1.0 * BAR, 2.4 * BAR, 8.0), ramp(2.4 * BAR, 1.0 * BAR, 8.0)])
    cmd = np.concatenate([ramp(0.0, 1.0 * BAR, 2.0), tri, tri, tri])
    effects = (Effect("backlash", {"gap_deg": gap_deg}),)
    lost = np.degrees(
        plant.bend_without_noise(cmd, RATE_HZ) - plant.bend_without_noise(cmd, RATE_HZ, effects)
    )
    k0 = round(2.0 * RATE_HZ) + 2 * tri.size
    up = lost[k0 + round(3.0 * RATE_HZ) : k0 + round(7.0 * RATE_HZ)]
    down = lost[k0 + round(11.0 * RATE_HZ) : k0 + round(15.0 * RATE_HZ)]
    assert np.median(up) - np.median(down) == pytest.approx(gap_deg, rel=0.1)
    assert np.max(lost) <= gap_deg + 1e-9
    assert np.min(lost) >= -1e-9


def test_gain_drift_rate(plant: DuhemPlant) -> None:
    """The friction and the wall hold another share of the bend on each branch, so the
    bend's gain moves at another rate on each; the stated rate is their geometric mean."""
    ratios = []
    for percent_per_min in (6.0, -4.0):
        # Approach in the direction the gain moves the bend: the friction does not reverse.
        p0, p1 = (1.4 * BAR, 1.8 * BAR) if percent_per_min > 0 else (2.2 * BAR, 1.8 * BAR)
        cmd, k = step_command(p0, p1, after_s=60.0)
        effects = (Effect("gain_drift", {"percent_per_min": percent_per_min}),)
        hold_part = slice(k + round(10.0 * RATE_HZ), None)  # bent: the ratio is defined
        drifting = plant.bend_without_noise(cmd, RATE_HZ, effects)[hold_part]
        gain = drifting / plant.bend_without_noise(cmd, RATE_HZ)[hold_part]
        t = np.arange(1, cmd.size + 1)[hold_part] * DT_S
        slope = np.polyfit(t, gain, 1)[0] * 60.0 * 100.0
        ratios.append(slope / percent_per_min)
    assert math.sqrt(ratios[0] * ratios[1]) == pytest.approx(1.0, rel=0.15)
    assert all(0.6 < r < 1.5 for r in ratios)


@pytest.mark.parametrize(("fraction", "tau_s"), [(0.16, 0.6), (0.28, 1.5)])
def test_slow_lag_share_and_time_constant(plant: DuhemPlant, fraction: float, tau_s: float) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR, before_s=8.0 * tau_s, after_s=10.0 * tau_s)
    effects = (Effect("slow_lag", {"fraction": fraction, "time_constant_s": tau_s}),)
    base = plant.bend_without_noise(cmd, RATE_HZ)
    slow = plant.bend_without_noise(cmd, RATE_HZ, effects)
    assert abs(slow[k - 1] - slow[k - 1 - round(RATE_HZ)]) < math.radians(0.01)  # settled
    deficit = (base - slow)[k:] / (base[-1] - base[k - 1])
    share = deficit[round(0.05 * RATE_HZ)]
    assert share == pytest.approx(fraction, rel=0.25)
    assert np.sum(deficit) * DT_S / share == pytest.approx(tau_s, rel=0.3)


def test_effects_combine(plant: DuhemPlant) -> None:
    cmd, k = step_command(1.2 * BAR, 2.0 * BAR, after_s=20.0)
    both = (
        Effect("transport_delay", {"delay_s": 0.04}),
        Effect("drift", {"rate_deg_per_min": 1.5}),
    )
    delayed = plant.bend_without_noise(cmd, RATE_HZ, both[:1])
    bend = plant.bend_without_noise(cmd, RATE_HZ, both)
    assert np.all(np.abs(bend[k : k + 7] - bend[k - 1]) < math.radians(0.01))  # still dead
    t = np.arange(1, cmd.size + 1) * DT_S
    assert bend[-1] - delayed[-1] == pytest.approx(
        float(drift_offset_rad(1.5, t[-1:])[0]), rel=1e-6
    )


def test_module_imports_only_numpy_scipy_numba_and_the_contract() -> None:
    import foreign_plants.duhem as module

    tree = ast.parse(Path(module.__file__).read_text(encoding="utf-8"))
    allowed = {"numpy", "scipy", "numba", "__future__"} | set(sys.stdlib_module_names)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            names = [alias.name for alias in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level > 0:
                assert node.module == "base", node.module
                continue
            names = [node.module or ""]
        else:
            continue
        for name in names:
            assert name.split(".")[0] in allowed, name
