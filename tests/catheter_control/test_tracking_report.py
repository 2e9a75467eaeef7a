"""The tracking report scores on header stamps and refuses runs it cannot score."""

from pathlib import Path

import numpy as np
import pytest

from catheter_control.tracking_report import (
    RunRecord,
    TrackingError,
    save_plot,
    score_record,
    score_run,
    timing_summary,
    timing_text,
)


def test_scores_aligned_on_stamps_within_window(tmp_path) -> None:
    td = np.arange(0.0, 10.0, 0.004)
    desired = np.radians(10.0) * (1 - np.cos(td))
    tm = td + 0.002  # measurements between set-points
    measured = np.radians(10.0) * (1 - np.cos(tm)) + np.radians(0.5)
    r = score_run(td, desired, tm, measured, window_s=(1.0, 9.0))
    assert np.degrees(r.overall.rmse) == pytest.approx(0.5, abs=0.02)
    assert r.t_s[0] == 0.0 and r.t_s[-1] == pytest.approx(8.0, abs=0.01)
    path = save_plot(r, tmp_path / "p.png", "test")
    assert path.stat().st_size > 10_000
    assert "RMSE" in r.text("x") and "maximum absolute error" in r.text("x")


def test_no_measurements_is_a_clear_error() -> None:
    td = np.arange(0.0, 1.0, 0.004)
    with pytest.raises(TrackingError, match="tip/angle"):
        score_run(td, td, [], [])
    with pytest.raises(TrackingError, match="overlap"):
        score_run(td, td, [5.0, 6.0], [0.0, 0.0])


def test_timing_summary_differences_counters_and_keeps_the_worst_window() -> None:
    comp = [
        {
            "ticks": "1000",
            "missed_deadlines": "2",
            "lateness_p99_ms": "0.20",
            "compute_p99_ms": "0.10",
            "control_rate_hz": "1000",
        },
        {
            "ticks": "2000",
            "missed_deadlines": "2",
            "lateness_p99_ms": "0.90",
            "compute_p99_ms": "0.12",
            "control_rate_hz": "1000",
        },
        {
            "ticks": "2999",
            "missed_deadlines": "3",
            "lateness_p99_ms": "0.30",
            "compute_p99_ms": "0.11",
            "control_rate_hz": "1000",
        },
    ]
    # The first driver report came before any command: its latency fields are empty.
    driver = [
        {"command_latency_p50_ms": "", "command_latency_p99_ms": "", "command_latency_max_ms": ""},
        {
            "command_latency_p50_ms": "0.3",
            "command_latency_p99_ms": "0.8",
            "command_latency_max_ms": "2.5",
        },
    ]
    timing = timing_summary(comp, driver)
    assert timing["ticks"] == 1999 and timing["missed_deadlines"] == 1
    assert timing["missed_fraction"] == pytest.approx(1 / 2000)
    assert timing["lateness_p99_ms"] == 0.90 and timing["compute_p99_ms"] == 0.12
    assert timing["command_latency_p99_ms"] == 0.8 and timing["command_latency_max_ms"] == 2.5
    text = timing_text(timing)
    assert "missed deadlines 1 (0.050 %)" in text and "p99 0.800 ms" in text


def test_timing_summary_without_reports_says_nothing_it_does_not_know() -> None:
    timing = timing_summary([], [])
    assert timing["ticks"] == 0 and timing["missed_fraction"] is None
    assert "n/a" in timing_text(timing)


def _vented_run(first_deg: float, rest_deg: float = 1.0, heard_before_s: float = 1.0) -> RunRecord:
    """A sine from ``first_deg`` on a catheter that cannot go below ``rest_deg``.

    The bend is heard from ``heard_before_s`` before the first set-point.
    """
    run = RunRecord()
    for ti in np.arange(-heard_before_s, 0.0, 0.004):
        run.measured.append(float(ti), np.radians(max(first_deg, rest_deg)))
    t = np.arange(0.0, 10.0, 0.004)
    desired = first_deg + 5.0 * (1.0 - np.cos(t))
    measured = np.maximum(desired, rest_deg)
    for ti, d, m in zip(t, np.radians(desired), np.radians(measured), strict=True):
        run.desired.append(float(ti), float(d))
        run.measured.append(float(ti), float(m))
    return run


def test_a_catheter_that_rests_bent_when_vented_is_told_apart_from_the_tracking(
    tmp_path: Path,
) -> None:
    result = score_record(_vented_run(0.0), duration_s=10.0, lead_s=0.0)
    vented = result.vented
    assert vented is not None
    assert np.degrees(vented.rest_bend_rad) == pytest.approx(1.0)
    # Everything the run misses lies below the rest: the bound is the whole error.
    assert vented.bound_rmse_rad == pytest.approx(result.overall.rmse, rel=1e-9)
    assert vented.above_rmse_rad == pytest.approx(0.0, abs=1e-12)
    below = np.radians(5.0) * (1 - np.cos(np.arange(0.0, 10.0, 0.004))) < np.radians(1.0)
    assert vented.below_share == pytest.approx(below.mean(), abs=0.01)
    assert "rests at 1.00 deg vented" in result.text("x")
    assert result.to_json()["vented_floor"]["rest_bend_deg"] == pytest.approx(1.0)
    assert save_plot(result, tmp_path / "p.png", "x").stat().st_size > 10_000


def test_a_run_that_does_not_start_from_rest_says_nothing_of_the_vented_bend() -> None:
    assert score_record(_vented_run(3.0), duration_s=10.0, lead_s=0.0).vented is None
    # Nothing heard before the run: where it rested is not known.
    assert score_record(_vented_run(0.0, heard_before_s=0.0), 10.0, 0.0).vented is None


def test_a_catheter_that_rests_straight_is_not_told_of_a_floor() -> None:
    result = score_record(_vented_run(0.0, rest_deg=0.0), duration_s=10.0, lead_s=0.0)
    assert result.vented is not None and not result.vented.matters
    assert "vented" not in result.text("x")
    assert result.to_json()["vented_floor"]["bound_rmse_deg"] == 0.0
