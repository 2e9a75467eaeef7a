"""Tests of the residual tests (catheter_models.lab.residuals) on residuals of known structure."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
from scipy.signal import butter, sosfiltfilt

from catheter_models.errors import ParameterError
from catheter_models.lab.residuals import (
    TEST_NAMES,
    CorrelationTest,
    ResidualReport,
    dominant_lag_s,
    plot_residual_tests,
    residual_tests,
)

RATE_HZ = 250.0
ANALYSIS_STEP_S = 1.0 / 25.0  # one sample at the default analysis rate
DURATION_S = 120.0


def smooth_input_pa(seed: int, duration_s: float = DURATION_S) -> np.ndarray:
    """A random pressure drive: noise low-passed at 1 Hz around 2 bar, swinging about ±1 bar."""
    rng = np.random.default_rng(seed)
    n = round(duration_s * RATE_HZ)
    edge = round(5.0 * RATE_HZ)  # cut the filter's start-up transients, steps in the drive
    sos = butter(4, 1.0, fs=RATE_HZ, output="sos")
    x = sosfiltfilt(sos, rng.standard_normal(n + 2 * edge))[edge:-edge]
    return 2e5 + 1e5 * x / np.std(x)


def delayed(signal: np.ndarray, delay_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(residual, input) where residual(t) = input(t - delay), both of equal length."""
    k = round(delay_s * RATE_HZ)
    return signal[:-k], signal[k:]


def scaled_rad(x: np.ndarray) -> np.ndarray:
    """A residual in rad shaped like ``x`` (the tests are invariant to its scale)."""
    return 0.05 * (x - x.mean()) / np.std(x)


# --- white residual: no false alarms -----------------------------------------------------------


def test_white_residual_passes_every_test() -> None:
    rng = np.random.default_rng(11)
    u = smooth_input_pa(1)
    e = 0.01 * rng.standard_normal(u.size)
    report = residual_tests(e, u, RATE_HZ)

    assert [t.name for t in report.tests] == list(TEST_NAMES)
    assert report.rate_hz == 25.0
    assert report.n_samples == round(DURATION_S * 25.0)
    assert report.ljung_box.p_value > 0.05
    assert not report.ljung_box.significant
    assert len(report.significant()) <= 1
    assert dominant_lag_s(report) is None
    for test in report.tests:
        assert np.all(np.abs(test.values) <= 1.0)
        assert test.band == pytest.approx(1.96 / np.sqrt(report.n_samples), rel=1e-3)
        assert test.limit >= test.band
    assert report.by_name("autocorrelation").values[0] == pytest.approx(1.0)


# --- each structure lights its own test --------------------------------------------------------


def test_delayed_input_shows_as_input_cross_peak_at_positive_lag() -> None:
    rng = np.random.default_rng(2)
    e, u = delayed(smooth_input_pa(2), 0.1)
    e = scaled_rad(e) + 0.005 * rng.standard_normal(e.size)
    report = residual_tests(e, u, RATE_HZ)

    test = report.by_name("input_cross")
    assert test.significant
    assert test.peak_value > 0.9
    assert test.peak_lag_s == pytest.approx(0.1, abs=ANALYSIS_STEP_S + 1e-9)
    lag = dominant_lag_s(report)
    assert lag is not None
    assert lag == pytest.approx(0.1, abs=ANALYSIS_STEP_S + 1e-9)
    assert "residual vs input: peak" in test.evidence()


def test_residual_proportional_to_rate_peaks_at_lag_zero() -> None:
    rng = np.random.default_rng(3)
    u = smooth_input_pa(3)
    rate_pa_s = np.gradient(u) * RATE_HZ
    e = scaled_rad(rate_pa_s) + 0.005 * rng.standard_normal(u.size)
    report = residual_tests(e, u, RATE_HZ)

    test = report.by_name("rate_cross")
    assert test.significant
    assert test.peak_value > 0.9
    assert abs(test.peak_lag_s) <= ANALYSIS_STEP_S + 1e-9


def test_ar1_residual_fails_whiteness() -> None:
    rng = np.random.default_rng(4)
    u = smooth_input_pa(4)
    w = rng.standard_normal(u.size)
    e = np.empty_like(w)
    e[0] = w[0]
    for i in range(1, e.size):  # time constant 0.2 s at 250 Hz
        e[i] = 0.98 * e[i - 1] + w[i]
    report = residual_tests(0.01 * e, u, RATE_HZ)

    test = report.by_name("autocorrelation")
    assert test.significant
    assert test.peak_lag_s == pytest.approx(ANALYSIS_STEP_S)  # lag 0 is not a peak candidate
    assert test.peak_value == pytest.approx(0.98**10, abs=0.1)
    assert report.ljung_box.significant
    assert report.ljung_box.p_value < 0.05
    assert report.ljung_box.dof == 20


def test_linear_trend_is_drift() -> None:
    rng = np.random.default_rng(5)
    u = smooth_input_pa(5)
    t_s = np.arange(u.size) / RATE_HZ
    e = np.deg2rad(1.0 / 60.0) * t_s + 0.005 * rng.standard_normal(u.size)  # 1 deg/min
    report = residual_tests(e, u, RATE_HZ)

    test = report.by_name("time_trend")
    assert test.lags_s.tolist() == [0.0]
    assert test.limit == pytest.approx(test.band)
    assert test.significant
    assert test.peak_value > 0.5
    assert "time_trend" in report.significant()


def test_squared_symmetric_input_shows_in_u2_e_not_input_cross() -> None:
    # Odd harmonics of 0.1 Hz over whole periods: u(t + 5 s) = -u(t), so u'^2 holds only even
    # harmonics and is orthogonal to u at every lag, while it is the residual itself.
    rng = np.random.default_rng(6)
    t_s = np.arange(round(DURATION_S * RATE_HZ)) / RATE_HZ
    harmonics = [(6e4, 0.1), (3e4, 0.3), (2e4, 0.7)]
    u = 2e5 + sum(a * np.sin(2 * np.pi * f * t_s + rng.uniform(0, 2 * np.pi)) for a, f in harmonics)
    dev = (u - u.mean()) / 1e5
    e = 0.05 * (dev**2 - np.mean(dev**2)) + 0.002 * rng.standard_normal(u.size)
    report = residual_tests(e, u, RATE_HZ)

    assert report.by_name("u2_e").significant
    assert report.by_name("u2_e").peak_value > 0.9
    assert abs(report.by_name("u2_e").peak_lag_s) <= ANALYSIS_STEP_S + 1e-9
    assert not report.by_name("input_cross").significant


# --- segments ----------------------------------------------------------------------------------


def test_segments_pool_recordings_without_crossing_the_boundary() -> None:
    rng = np.random.default_rng(7)
    e_a, u_a = delayed(smooth_input_pa(7, 60.0), 0.1)
    e_b, u_b = delayed(smooth_input_pa(8, 60.0), 0.1)
    e_a = scaled_rad(e_a) + 0.005 * rng.standard_normal(e_a.size)
    e_b = scaled_rad(e_b) + 0.005 * rng.standard_normal(e_b.size) + 0.3  # offsets jump
    u_b = u_b + 1.5e5
    e = np.concatenate([e_a, e_b])
    u = np.concatenate([u_a, u_b])
    segments = [(0, e_a.size), (e_a.size, e.size)]

    pooled = residual_tests(e, u, RATE_HZ, segments=segments).by_name("input_cross")
    alone_a = residual_tests(e_a, u_a, RATE_HZ).by_name("input_cross")
    alone_b = residual_tests(e_b, u_b, RATE_HZ).by_name("input_cross")
    assert pooled.significant
    for alone in (alone_a, alone_b):
        assert pooled.peak_lag_s == pytest.approx(alone.peak_lag_s, abs=ANALYSIS_STEP_S + 1e-9)
    assert pooled.peak_lag_s == pytest.approx(0.1, abs=ANALYSIS_STEP_S + 1e-9)


def test_jump_between_segments_creates_no_correlation() -> None:
    rng = np.random.default_rng(9)
    u = np.concatenate([smooth_input_pa(9, 60.0), smooth_input_pa(10, 60.0) + 2e5])
    e = 0.01 * rng.standard_normal(u.size)
    half = u.size // 2
    e[half:] += 0.1  # a new recording with another sensor zero
    segments = [(0, half), (half, u.size)]

    split = residual_tests(e, u, RATE_HZ, segments=segments)
    joined = residual_tests(e, u, RATE_HZ)  # the same arrays taken as one recording
    # Margins far beyond chance (|z| > 5 under the null), so the test holds for any seed:
    assert split.ljung_box.p_value > 1e-3
    assert joined.ljung_box.p_value < 1e-6
    for name in ("autocorrelation", "time_trend", "input_cross"):
        assert abs(split.by_name(name).peak_value) < 5.0 / np.sqrt(split.n_samples)
        # As one recording, the jump looks like a correlated, drifting residual.
        assert joined.by_name(name).significant
        assert abs(joined.by_name(name).peak_value) > 0.5


def test_samples_outside_segments_are_ignored() -> None:
    rng = np.random.default_rng(12)
    u = smooth_input_pa(12, 60.0)
    e = 0.01 * rng.standard_normal(u.size)
    e_gap = e.copy()
    e_gap[5000:6000] = 1e3  # a glitch left out of both segments
    segments = [(0, 5000), (6000, u.size)]
    a = residual_tests(e, u, RATE_HZ, segments=segments)
    b = residual_tests(e_gap, u, RATE_HZ, segments=segments)
    for ta, tb in zip(a.tests, b.tests, strict=True):
        np.testing.assert_allclose(ta.values, tb.values)
    assert a.n_samples == (5000 + u.size - 6000) // 10


# --- output ------------------------------------------------------------------------------------


def white_report() -> ResidualReport:
    rng = np.random.default_rng(13)
    e, u = delayed(smooth_input_pa(13, 30.0), 0.1)
    return residual_tests(scaled_rad(e) + 0.01 * rng.standard_normal(e.size), u, RATE_HZ)


def test_text_dict_and_evidence() -> None:
    report = white_report()
    text = report.text()
    for name in (*TEST_NAMES, "ljung_box"):
        assert name in text
    data = json.loads(json.dumps(report.to_dict()))
    assert [t["name"] for t in data["tests"]] == list(TEST_NAMES)
    assert data["significant"] == report.significant()
    assert data["n_samples"] == report.n_samples
    test = report.by_name("input_cross")
    assert isinstance(test, CorrelationTest)
    assert test.evidence().startswith("residual vs input: peak ")
    assert " at +0.08 s " in test.evidence() or " at +0.12 s " in test.evidence()
    with pytest.raises(KeyError, match="input_cross"):
        report.by_name("nonsense")
    with pytest.raises(ValueError, match="read-only"):
        test.values[0] = 0.0


def test_plot_writes_png(tmp_path: Path) -> None:
    out = plot_residual_tests(white_report(), tmp_path / "lab" / "residuals.png")
    assert out == tmp_path / "lab" / "residuals.png"
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


# --- bad input ---------------------------------------------------------------------------------


def test_bad_input_raises_value_error_naming_the_problem() -> None:
    u = smooth_input_pa(14, 10.0)
    e = np.zeros(u.size)
    e_nan = e.copy()
    e_nan[7] = np.nan
    with pytest.raises(ValueError, match=r"residual\[7\] is nan"):
        residual_tests(e_nan, u, RATE_HZ)
    with pytest.raises(ValueError, match="equal length"):
        residual_tests(e[:-1], u, RATE_HZ)
    with pytest.raises(ValueError, match="rate_hz"):
        residual_tests(e, u, 0.0)
    with pytest.raises(ValueError, match="rate_hz"):
        residual_tests(e, u, -250.0)
    with pytest.raises(ValueError, match="after decimation"):
        residual_tests(e[:400], u[:400], RATE_HZ)
    with pytest.raises(ValueError, match="max_lag_s"):
        residual_tests(e, u, RATE_HZ, max_lag_s=0.01)
    with pytest.raises(ParameterError, match="overlap"):
        residual_tests(e, u, RATE_HZ, segments=[(0, 1500), (1000, 2500)])
    with pytest.raises(ParameterError, match="0 <= start < stop"):
        residual_tests(e, u, RATE_HZ, segments=[(0, u.size + 1)])


def test_constant_residual_gives_zero_correlations() -> None:
    u = smooth_input_pa(15, 10.0)
    report = residual_tests(np.full(u.size, 0.2), u, RATE_HZ)
    assert report.significant() == []
    assert report.ljung_box.p_value == pytest.approx(1.0)
    for test in report.tests:
        assert np.all(test.values[test.lags_s != 0] == 0.0)
