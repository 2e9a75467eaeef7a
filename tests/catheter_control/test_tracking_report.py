"""The tracking report scores on header stamps and refuses runs it cannot score."""

import numpy as np
import pytest

from catheter_control.tracking_report import TrackingError, save_plot, score_run


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
