"""Tests of the thesis's metrics and the regime masks (catheter_models.metrics)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.metrics import (
    REGIMES,
    ErrorMetrics,
    classify_regimes,
    compute_metrics,
    max_abs_error,
    metrics_by_regime,
    nrmse,
    rmse,
)
from catheter_models.units import bar_to_pa, deg_to_rad

RATE_HZ = 250.0

# --- eqs. 5.13-5.15 --------------------------------------------------------------------------

PRED = np.array([1.0, 2.0, 3.0, 4.0])
REF = np.array([1.0, 1.0, 5.0, 4.0])  # errors 0, 1, -2, 0; reference range 4


def test_mae_is_the_maximum_absolute_error_as_in_the_thesis() -> None:
    # The mean absolute error would be 0.75.
    assert max_abs_error(PRED, REF) == 2.0


def test_rmse_and_nrmse_hand_values() -> None:
    assert rmse(PRED, REF) == pytest.approx(math.sqrt(5.0 / 4.0), rel=1e-15)
    assert nrmse(PRED, REF) == pytest.approx(math.sqrt(5.0 / 4.0) / 4.0, rel=1e-15)
    # Normalized by the reference's range, not the prediction's (range 3).
    assert nrmse(PRED, REF) != pytest.approx(math.sqrt(5.0 / 4.0) / 3.0)
    assert nrmse(PRED, REF, normalization_range=10.0) == pytest.approx(math.sqrt(1.25) / 10.0)


def test_compute_metrics_bundles_the_three() -> None:
    m = compute_metrics(PRED, REF)
    assert m == ErrorMetrics(
        rmse=math.sqrt(1.25), mae=2.0, nrmse=math.sqrt(1.25) / 4.0, n_samples=4
    )


@pytest.mark.parametrize("func", [max_abs_error, rmse, nrmse, compute_metrics])
def test_non_finite_input_is_refused_naming_array_and_index(func: object) -> None:
    bad = PRED.copy()
    bad[2] = np.nan
    with pytest.raises(ParameterError, match=r"predicted\[2\] is nan"):
        func(bad, REF)  # type: ignore[operator]
    bad_ref = REF.copy()
    bad_ref[3] = np.inf
    with pytest.raises(ParameterError, match=r"reference\[3\] is inf"):
        func(PRED, bad_ref)  # type: ignore[operator]


def test_length_mismatch_and_empty_are_refused() -> None:
    with pytest.raises(ParameterError, match="equal length, got 4 and 3"):
        rmse(PRED, REF[:3])
    with pytest.raises(ParameterError, match="empty"):
        compute_metrics(np.array([]), np.array([]))


def test_constant_reference_has_no_nrmse() -> None:
    with pytest.raises(ParameterError, match="constant"):
        nrmse(PRED, np.ones(4))
    m = compute_metrics(PRED, np.ones(4))
    assert m.nrmse is None
    assert "NRMSE n/a" in m.format("rad")


def test_format_converts_from_si_to_display_units() -> None:
    m = ErrorMetrics(rmse=deg_to_rad(1.7), mae=deg_to_rad(4.4), nrmse=0.053, n_samples=5000)
    assert m.format() == "RMSE 1.7 deg  MAE 4.4 deg  NRMSE 5.30 %  (n=5000)"
    p = ErrorMetrics(rmse=bar_to_pa(0.12), mae=bar_to_pa(0.5), nrmse=0.02, n_samples=10)
    assert p.format("bar").startswith("RMSE 0.12 bar  MAE 0.5 bar")
    with pytest.raises(ParameterError, match="unknown display unit 'mm'"):
        m.format("mm")


# --- regimes ---------------------------------------------------------------------------------

# Drive [bar] at the corners of a piecewise-linear test signal, and when regimes hold.
CORNERS_S = [0.0, 1.0, 3.0, 5.0, 7.0, 8.0, 9.5, 12.5, 13.5]
CORNERS_BAR = [0.0, 0.0, 2.0, 2.0, 0.0, 0.0, 1.5, 0.5, 0.5]
EDGE_S = 0.06  # smoothing (0.1 s window) may blur a corner by this much


def _triangle(noise_pa: float = 0.0) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.arange(0.0, 13.5, 1.0 / RATE_HZ)
    drive_pa = bar_to_pa(np.interp(t, CORNERS_S, CORNERS_BAR))
    # The tip moves only above the 1 bar opening pressure, 15 deg per bar beyond it.
    angle_rad = deg_to_rad(15.0 * np.maximum(0.0, drive_pa / 1e5 - 1.0))
    if noise_pa:
        drive_pa = drive_pa + np.random.default_rng(7).normal(0.0, noise_pa, t.size)
    return t, drive_pa, angle_rad


def _between(t: np.ndarray, spans: list[tuple[float, float]]) -> np.ndarray:
    out = np.zeros(t.size, dtype=bool)
    for a, b in spans:
        out |= (t >= a) & (t <= b)
    return out


def _assert_mask(
    t: np.ndarray,
    got: np.ndarray,
    expected: np.ndarray,
    margin_s: float,
    edges_s: list[float] = CORNERS_S,
) -> None:
    """``got == expected`` except within ``margin_s`` of an edge."""
    near_edge = np.any(np.abs(t[:, None] - np.array(edges_s)[None, :]) <= margin_s, axis=1)
    wrong = (got != expected) & ~near_edge
    assert not wrong.any(), f"mask wrong at t = {t[wrong][:5]} s"


LOADING = [(1.0, 3.0), (8.0, 9.5)]
UNLOADING = [(5.0, 7.0), (9.5, 12.5)]
PLATEAU = [(0.0, 1.0), (3.0, 5.0), (7.0, 8.0), (12.5, 13.5)]


@pytest.mark.parametrize("noise_pa", [0.0, 1000.0])  # 1000 Pa = 10 mbar sensor noise
def test_loading_unloading_plateau_where_the_drive_does_it(noise_pa: float) -> None:
    t, drive, angle = _triangle(noise_pa)
    r = classify_regimes(t, drive, angle)
    assert tuple(r) == REGIMES
    _assert_mask(t, r["loading"], _between(t, LOADING), EDGE_S)
    _assert_mask(t, r["unloading"], _between(t, UNLOADING), EDGE_S)
    _assert_mask(t, r["plateau"], _between(t, PLATEAU), EDGE_S)
    # Noise must not split a regime: exactly one run per ramp or hold.
    assert np.count_nonzero(np.diff(r["loading"].astype(int)) == 1) == len(LOADING)
    assert np.count_nonzero(np.diff(r["plateau"].astype(int)) == 1) == len(PLATEAU) - 1


def test_fast_motion_is_the_steep_ramps_only() -> None:
    t, drive, angle = _triangle()
    r = classify_regimes(t, drive, angle)
    # 1 bar/s ramps are the peak rate; the 1/3 bar/s fall (9.5-12.5 s) is below half of it.
    _assert_mask(t, r["fast_motion"], _between(t, [(1, 3), (5, 7), (8, 9.5)]), 0.1)
    slower = classify_regimes(t, drive, angle, fast_rate_threshold_per_s=bar_to_pa(0.2))
    _assert_mask(t, slower["fast_motion"], _between(t, [(1, 3), (5, 7), (8, 12.5)]), 0.1)


def test_deadband_is_below_opening_pressure_with_the_tip_still() -> None:
    t, drive, angle = _triangle()
    r = classify_regimes(t, drive, angle)
    # Drive < 1 bar (the default opening threshold) at 0-2 s, 6-9 s and from 11 s on.
    expected = _between(t, [(0.0, 2.0), (6.0, 9.0), (11.0, 13.5)])
    _assert_mask(t, r["deadband"], expected, 0.01, edges_s=[2.0, 6.0, 9.0, 11.0])
    # The tip angle also gates it: a bent tip is not in the deadband.
    bent = classify_regimes(t, drive, np.full_like(angle, deg_to_rad(5.0)))
    assert not bent["deadband"].any()


def test_deadband_threshold_follows_the_drive_unit_for_angle_drives() -> None:
    t = np.arange(0.0, 6.0, 1.0 / RATE_HZ)
    desired_rad = deg_to_rad(np.interp(t, [0, 1, 4, 6], [0, 0, 15, 15]))
    r = classify_regimes(
        t,
        desired_rad,
        desired_rad,
        deadband_drive_threshold=deg_to_rad(2.0),
        deadband_angle_rad=deg_to_rad(3.0),
    )
    # 2 deg desired is reached at t = 1.4 s.
    _assert_mask(t, r["deadband"], t < 1.4, 0.01, edges_s=[1.4])


def test_peaks_and_valleys_sit_at_the_drive_extrema() -> None:
    t, drive, angle = _triangle()
    r = classify_regimes(t, drive, angle)
    # Held top 3-5 s and the sharp top at 9.5 s; held bottoms 0-1 s (start) and 7-8 s.
    peak_core = _between(t, [(3.0, 5.0), (9.45, 9.55)])
    valley_core = _between(t, [(0.0, 1.0), (7.0, 8.0)])
    assert r["peak"][peak_core].all()
    assert r["valley"][valley_core].all()
    far_from_peak = ~_between(t, [(2.8, 5.2), (9.3, 9.7)])
    far_from_valley = ~_between(t, [(0.0, 1.2), (6.8, 8.2)])
    assert not r["peak"][far_from_peak].any()
    # The last hold at 0.5 bar is where the run was cut, not a turn: no valley there.
    assert not r["valley"][far_from_valley].any()


def test_constant_drive_is_all_plateau() -> None:
    t = np.arange(0.0, 2.0, 1.0 / RATE_HZ)
    r = classify_regimes(t, np.full(t.size, 1.5e5), np.zeros(t.size))
    assert r["plateau"].all()
    for name in ("loading", "unloading", "fast_motion", "peak", "valley"):
        assert not r[name].any(), name


def test_classify_refuses_bad_input() -> None:
    t, drive, angle = _triangle()
    with pytest.raises(ParameterError, match=r"drive\[5\] is nan"):
        classify_regimes(t, np.where(np.arange(t.size) == 5, np.nan, drive), angle)
    with pytest.raises(ParameterError, match="angle_rad must have the length"):
        classify_regimes(t, drive, angle[:-1])
    with pytest.raises(ParameterError, match="increase strictly"):
        classify_regimes(t[::-1], drive, angle)
    with pytest.raises(ParameterError, match="smoothing window"):
        classify_regimes(t[:10], drive[:10], angle[:10])
    with pytest.raises(ParameterError, match="rate_threshold_per_s"):
        classify_regimes(t, drive, angle, rate_threshold_fraction=1.5)


def test_jittery_stamps_give_the_same_regimes() -> None:
    t, drive, angle = _triangle()
    jitter = np.random.default_rng(3).uniform(-0.3, 0.3, t.size) / RATE_HZ
    r = classify_regimes(t + jitter, drive, angle)
    _assert_mask(t, r["loading"], _between(t, LOADING), EDGE_S)
    _assert_mask(t, r["unloading"], _between(t, UNLOADING), EDGE_S)


# --- metrics by regime -----------------------------------------------------------------------


def test_metrics_by_regime_hand_values_and_minimum_count() -> None:
    reference = np.array([0.0, 1.0, 2.0, 3.0, 4.0, 4.0, 4.0, 4.0])
    predicted = reference + np.array([0.5, -0.5, 0.5, -0.5, 1.0, 1.0, -1.0, 1.0])
    rising = np.array([True] * 4 + [False] * 4)
    regimes = {"loading": rising, "plateau": ~rising, "peak": np.eye(8, dtype=bool)[7]}
    out = metrics_by_regime(predicted, reference, regimes, min_samples=2)
    assert out["loading"] == ErrorMetrics(rmse=0.5, mae=0.5, nrmse=0.5 / 4.0, n_samples=4)
    # A plateau has a constant reference; NRMSE still uses the whole run's range (4).
    assert out["plateau"] == ErrorMetrics(rmse=1.0, mae=1.0, nrmse=1.0 / 4.0, n_samples=4)
    assert out["peak"] is None  # one sample, fewer than min_samples


def test_metrics_by_regime_refuses_bad_masks() -> None:
    with pytest.raises(ParameterError, match="regime 'x' must be a boolean mask of length 4"):
        metrics_by_regime(PRED, REF, {"x": np.array([1, 0, 1, 0])})
    with pytest.raises(ParameterError, match="regime 'y'"):
        metrics_by_regime(PRED, REF, {"y": np.array([True, False])})


def test_metrics_by_regime_on_classified_run() -> None:
    t, drive, angle = _triangle()
    # A model wrong by 2 deg only below the opening pressure: the deadband carries the error.
    predicted = angle + np.where(drive < 1e5, deg_to_rad(2.0), 0.0)
    out = metrics_by_regime(predicted, angle, classify_regimes(t, drive, angle))
    deadband, peak = out["deadband"], out["peak"]
    assert deadband is not None and peak is not None
    assert deadband.mae == pytest.approx(deg_to_rad(2.0))
    # Only the four crossings sampled at exactly 1 bar may fall on the other side.
    assert deadband.rmse == pytest.approx(deg_to_rad(2.0), rel=4.0 / deadband.n_samples)
    assert peak.mae == 0.0  # the tops are at 1.5 and 2 bar
    assert set(out) == set(REGIMES)
