"""Tests of the thesis's excitation and test signals (catheter_models.signals)."""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from catheter_models.errors import SignalError
from catheter_models.signals import (
    PRESETS,
    TEST_PRESSURE_SIGNALS,
    TEST_TRAJECTORIES,
    THESIS_MAX_ANGLE_RAD,
    THESIS_MAX_PRESSURE_PA,
    ChirpSpec,
    DescendingSineSpec,
    arbitrary_plateaus,
    check_pressure_signal,
    check_trajectory,
    chirp,
    clstm_training_set,
    descending_sine_nonzero_baseline,
    descending_sine_zero_baseline,
    get_preset,
    instantaneous_frequency_hz,
    time_grid_s,
    training_set,
)
from catheter_models.units import bar_to_pa, deg_to_rad

RATE_HZ = 250.0


def _local_maxima(x: np.ndarray) -> np.ndarray:
    return np.flatnonzero((x[1:-1] > x[:-2]) & (x[1:-1] >= x[2:])) + 1


# --- equations -------------------------------------------------------------------------------


def test_eq41_zero_baseline_hand_values() -> None:
    a, tau, f = 1.5, 0.15, 0.4
    half_period_s = 1.0 / (2.0 * f)
    t = np.array([0.0, half_period_s / 2.0, half_period_s, 2.0 * half_period_s])
    p = descending_sine_zero_baseline(t, a, tau, f)
    expected = [0.0, a * math.exp(-tau * t[1]), 2.0 * a * math.exp(-tau * t[2]), 0.0]
    np.testing.assert_allclose(p, expected, atol=1e-12)


def test_eq42_nonzero_baseline_starts_at_zero_and_settles_at_amplitude() -> None:
    a, tau, f = 1.5, 0.15, 0.2
    t = np.array([0.0, 1.0 / (2.0 * f), 200.0])
    p = descending_sine_nonzero_baseline(t, a, tau, f)
    np.testing.assert_allclose(p[:2], [0.0, a * math.exp(-tau * t[1]) + a], atol=1e-12)
    assert p[2] == pytest.approx(a, abs=1e-9)


def test_chirp_without_chirp_and_offset_is_eq41() -> None:
    t = np.linspace(0.0, 10.0, 1001)
    np.testing.assert_allclose(
        chirp(t, 1.2, 0.1, 0.7, chirp_hz_per_s=0.0),
        descending_sine_zero_baseline(t, 1.2, 0.1, 0.7),
        rtol=0,
        atol=1e-12,
    )


def test_chirp_phase_is_as_printed_so_frequency_is_f_plus_2ct() -> None:
    # Peaks of sin(2 pi (f + c t) t - pi/2) sit where (f + c t) t = k + 1/2.
    f, c = 0.3, 0.05
    t = np.arange(0.0, 12.0, 1e-4)
    wave = chirp(t, 1.0, 0.0, f, chirp_hz_per_s=c)
    peak_times = t[_local_maxima(wave)]
    k = np.arange(peak_times.size)
    expected = (-f + np.sqrt(f * f + 4.0 * c * (k + 0.5))) / (2.0 * c)
    np.testing.assert_allclose(peak_times, expected, atol=2e-4)
    assert instantaneous_frequency_hz(np.array([10.0]), f, c)[0] == pytest.approx(f + 2 * c * 10)


# --- presets ---------------------------------------------------------------------------------


def test_training_set_matches_thesis_sec_411() -> None:
    specs = training_set()
    assert [s.name for s in specs] == [
        f"train_{b}_f{f:g}" for b in ("zero", "nonzero") for f in (0.2, 0.4, 0.6, 0.8)
    ]
    for spec in specs:
        assert isinstance(spec, DescendingSineSpec)
        assert (spec.kind, spec.amplitude, spec.decay_per_s, spec.duration_s) == (
            "pressure",
            1.5,
            0.15,
            13.4,
        )
    total = sum(s.generate(RATE_HZ).t_s.size for s in specs)
    assert abs(total - 26798) <= len(specs)  # rounding of each signal to whole samples


def test_clstm_set_is_40_pressure_groups_of_thesis_size() -> None:
    specs = clstm_training_set()
    combos = {(s.baseline, s.freq_hz, s.decay_per_s) for s in specs}  # type: ignore[attr-defined]
    assert len(specs) == 40
    assert combos == {
        (b, f, tau)
        for b in ("zero", "nonzero")
        for f in (0.2, 0.4, 0.6, 0.8)
        for tau in (0.02, 0.05, 0.1, 0.15, 0.2)
    }
    assert all(s.kind == "pressure" for s in specs)
    total = sum(s.generate(RATE_HZ).t_s.size for s in specs)
    assert abs(total - 260269) / 260269 < 2e-3


def test_every_preset_stays_within_thesis_limits() -> None:
    for name, spec in PRESETS.items():
        sig = spec.generate(RATE_HZ)
        if sig.kind == "pressure":
            check_pressure_signal(sig.values_si, 0.0, THESIS_MAX_PRESSURE_PA)
        else:
            check_trajectory(
                sig.t_s,
                sig.values_si,
                THESIS_MAX_ANGLE_RAD,
                max_rate_rad_s=deg_to_rad(60.0),
                max_accel_rad_s2=deg_to_rad(1000.0),
            )
        assert sig.name == name


def test_test_signal_tuples_name_the_thesis_order() -> None:
    assert TEST_PRESSURE_SIGNALS == (
        "model_test_descending_sine",
        "model_test_down_chirp",
        "model_test_up_chirp",
        "model_test_arbitrary_plateaus",
    )
    assert TEST_TRAJECTORIES == (
        "traj_descending_sine",
        "traj_down_chirp",
        "traj_up_chirp",
        "traj_arbitrary_small_variations",
    )
    assert all(get_preset(n).kind == "pressure" for n in TEST_PRESSURE_SIGNALS)
    assert all(get_preset(n).kind == "angle" for n in TEST_TRAJECTORIES)


@pytest.mark.parametrize("name", ["model_test_down_chirp", "traj_down_chirp"])
def test_down_chirps_halve_their_frequency_over_the_signal(name: str) -> None:
    spec = get_preset(name)
    assert isinstance(spec, ChirpSpec)
    sig = spec.generate(RATE_HZ)
    peaks_s = sig.t_s[_local_maxima(sig.values_si)]
    periods_s = np.diff(peaks_s)
    mid_s = 0.5 * (peaks_s[1:] + peaks_s[:-1])
    expected_s = 1.0 / instantaneous_frequency_hz(mid_s, spec.freq_hz, spec.chirp_hz_per_s)
    np.testing.assert_allclose(periods_s, expected_s, rtol=0.02)
    assert periods_s[-1] > 1.5 * periods_s[0]
    end_hz = instantaneous_frequency_hz(
        np.array([spec.duration_s]), spec.freq_hz, spec.chirp_hz_per_s
    )[0]
    assert end_hz == pytest.approx(spec.freq_hz / 2.0)
    assert len(peaks_s) >= 6  # "several waves" (figs. 5.7, 9.6)


def test_printed_down_chirp_rate_is_refused() -> None:
    # Printed c = -0.1 drives f + 2ct through zero at 3.5 s.
    with pytest.raises(SignalError, match="f \\+ 2ct"):
        ChirpSpec(
            name="printed",
            kind="pressure",
            source="eq. 5.16",
            amplitude=0.9,
            offset=1.2,
            freq_hz=0.7,
            decay_per_s=0.1,
            chirp_hz_per_s=-0.1,
            duration_s=20.0,
        )


def test_up_chirp_stays_in_studied_band_and_grows() -> None:
    spec = get_preset("model_test_up_chirp")
    assert isinstance(spec, ChirpSpec)
    end_hz = instantaneous_frequency_hz(
        np.array([spec.duration_s]), spec.freq_hz, spec.chirp_hz_per_s
    )[0]
    assert end_hz < 1.0
    bar = spec.generate(RATE_HZ).values_bar()
    peaks = bar[_local_maxima(bar)]
    assert np.all(np.diff(peaks) > 0.0)  # ascending
    assert peaks[-1] > 2.5
    assert "0.15" in spec.note and "-0.05" in spec.note


def test_trajectory_one_has_the_range_table_11_1_implies() -> None:
    deg = get_preset("traj_descending_sine").generate(RATE_HZ).values_deg()
    assert np.ptp(deg) == pytest.approx(18.5, abs=0.5)


def test_generated_signal_is_si_on_a_grid_from_zero_and_read_only() -> None:
    sig = get_preset("model_test_descending_sine").generate(100.0)
    assert sig.t_s.dtype == np.float64
    assert sig.t_s[0] == 0.0
    np.testing.assert_allclose(np.diff(sig.t_s), 0.01)
    assert sig.t_s.size == 2000
    np.testing.assert_allclose(sig.values_si, bar_to_pa(sig.values_bar()))
    np.testing.assert_allclose(sig.values_display(), sig.values_bar())
    assert sig.unit == "bar"
    with pytest.raises(ValueError, match="read-only"):
        sig.values_si[0] = 1.0
    with pytest.raises(SignalError, match="is an angle"):
        get_preset("traj_up_chirp").generate().values_bar()
    with pytest.raises(SignalError, match="is a pressure"):
        sig.values_deg()


def test_angle_preset_is_radians() -> None:
    sig = get_preset("traj_down_chirp").generate(RATE_HZ)
    assert sig.values_si[0] == pytest.approx(deg_to_rad(8.0))  # B = 8 deg at t = 0
    assert sig.unit == "deg"
    np.testing.assert_allclose(sig.values_display(), sig.values_deg())


def test_params_carry_units_and_serialize_for_bag_metadata() -> None:
    sig = get_preset("traj_down_chirp").generate(RATE_HZ)
    assert sig.params["amplitude_deg"] == 10.0
    assert sig.params["offset_deg"] == 8.0
    assert sig.params["rate_hz"] == RATE_HZ
    assert sig.params["signal"] == "traj_down_chirp"
    json.dumps(dict(sig.params))
    p = get_preset("model_test_arbitrary_plateaus").generate().params
    assert p["level_max_bar"] == 3.0 and "seed" in p


def test_get_preset_lists_valid_names() -> None:
    with pytest.raises(SignalError, match=r"train_zero_f0\.2") as info:
        get_preset("train_zero_f0.3")
    assert "traj_up_chirp" in str(info.value)


def test_generate_refuses_bad_rate() -> None:
    with pytest.raises(SignalError, match="rate_hz"):
        get_preset("traj_up_chirp").generate(0.0)
    with pytest.raises(SignalError, match="rate_hz"):
        get_preset("traj_up_chirp").generate(math.nan)


# --- arbitrary signals -----------------------------------------------------------------------


def _flat_runs_s(x: np.ndarray, rate_hz: float) -> list[float]:
    still = np.concatenate(([False], np.abs(np.diff(x)) < 1e-12, [False]))
    edges = np.diff(still.astype(int))
    starts, stops = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    return [(b - a) / rate_hz for a, b in zip(starts, stops, strict=True)]


def test_arbitrary_pressure_is_deterministic_with_plateaus_and_smooth_ramps() -> None:
    spec = get_preset("model_test_arbitrary_plateaus")
    a, b = spec.generate(RATE_HZ), spec.generate(RATE_HZ)
    np.testing.assert_array_equal(a.values_si, b.values_si)
    bar = a.values_bar()
    assert bar[0] == 0.0 and bar[-1] == pytest.approx(0.0, abs=1e-12)
    plateaus = _flat_runs_s(bar, RATE_HZ)
    inner = plateaus[1:-1]  # the first and last holds bracket the run
    assert len(inner) >= 5
    assert all(0.95 <= p <= 3.05 for p in inner)
    rate_bar_s = np.diff(bar) * RATE_HZ
    assert np.max(np.abs(rate_bar_s)) <= 6.0 + 1e-9  # the preset's ramp cap
    # Raised-cosine ramps: no jump in rate, so the second difference stays small.
    assert np.max(np.abs(np.diff(rate_bar_s))) < 0.2


def test_arbitrary_seed_changes_signal() -> None:
    t = time_grid_s(30.0, RATE_HZ)
    a = arbitrary_plateaus(t, np.random.default_rng(1), 0.0, 3.0)
    b = arbitrary_plateaus(t, np.random.default_rng(2), 0.0, 3.0)
    assert not np.allclose(a, b)
    assert a.min() >= 0.0 and a.max() <= 3.0


def test_arbitrary_trajectory_has_small_fast_variations_on_plateaus() -> None:
    deg = get_preset("traj_arbitrary_small_variations").generate(RATE_HZ).values_deg()
    ext = np.flatnonzero(np.diff(np.sign(np.diff(deg))) != 0) + 1
    swings = np.abs(np.diff(deg[ext]))
    gaps_s = np.diff(ext) / RATE_HZ
    # Half periods of 1-2 Hz wiggles, each swing at most 2 x 1.5 deg.
    small_fast = (swings > 0.3) & (swings <= 3.0) & (gaps_s >= 0.24) & (gaps_s <= 0.52)
    assert np.count_nonzero(small_fast) >= 10
    assert np.all(np.diff(deg) * RATE_HZ <= 40.0 + 20.0)  # ramp cap plus wiggle rate


def test_pressure_arbitrary_has_no_variations() -> None:
    bar = get_preset("model_test_arbitrary_plateaus").generate(RATE_HZ).values_bar()
    ext = np.flatnonzero(np.diff(np.sign(np.diff(bar))) != 0) + 1
    swings = np.abs(np.diff(bar[ext]))
    assert np.all(swings[swings > 1e-9] > 0.2)


def test_arbitrary_refuses_variation_larger_than_range() -> None:
    t = time_grid_s(30.0, RATE_HZ)
    with pytest.raises(SignalError, match="variation_amplitude"):
        arbitrary_plateaus(t, np.random.default_rng(0), 0.0, 2.0, variation_amplitude=(0.5, 1.5))


def test_arbitrary_refuses_too_short_grid() -> None:
    with pytest.raises(SignalError, match="too short"):
        arbitrary_plateaus(time_grid_s(2.0, RATE_HZ), np.random.default_rng(0), 0.0, 3.0)


# --- validation ------------------------------------------------------------------------------


def test_check_pressure_signal_names_first_offence() -> None:
    p = bar_to_pa(np.array([0.0, 1.0, 3.5, np.nan]))
    with pytest.raises(SignalError, match=r"sample 2 .*3\.5 bar.*above the maximum"):
        check_pressure_signal(p, 0.0, bar_to_pa(3.0))
    with pytest.raises(SignalError, match="sample 1 is nan"):
        check_pressure_signal(np.array([0.0, np.nan, -5.0]), 0.0, 3e5)
    with pytest.raises(SignalError, match=r"sample 0 .*below the minimum"):
        check_pressure_signal(np.array([-1.0]), 0.0, 3e5)
    check_pressure_signal(bar_to_pa(np.array([0.0, 3.0])), 0.0, bar_to_pa(3.0))


def test_check_trajectory_names_offence() -> None:
    t = np.arange(10) / RATE_HZ
    ok = deg_to_rad(np.linspace(0.0, 1.0, 10))
    lim = (deg_to_rad(35.0), deg_to_rad(60.0), deg_to_rad(1e4))
    check_trajectory(t, ok, *lim)

    step = ok.copy()
    step[5:] += deg_to_rad(5.0)
    with pytest.raises(SignalError, match=r"rate at sample 5 \(t = 0\.0200 s\)"):
        check_trajectory(t, step, *lim)

    high = ok.copy()
    high[7] = deg_to_rad(40.0)
    with pytest.raises(SignalError, match=r"angle at sample 7 .*40 deg"):
        check_trajectory(t, high, *lim)

    with pytest.raises(SignalError, match=r"angle_rad\[3\] is nan"):
        check_trajectory(t, np.where(np.arange(10) == 3, np.nan, ok), *lim)

    back = t.copy()
    back[4] = back[3]
    with pytest.raises(SignalError, match=r"t_s\[4\]"):
        check_trajectory(back, ok, *lim)

    kink = deg_to_rad(np.concatenate((np.zeros(5), np.arange(1, 6) * 0.2)))
    with pytest.raises(SignalError, match="acceleration at sample"):
        check_trajectory(t, kink, deg_to_rad(35.0), deg_to_rad(60.0), deg_to_rad(100.0))
