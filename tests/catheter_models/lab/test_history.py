"""The lab's history: versions appended in plain files, read back, plotted."""

from pathlib import Path

import numpy as np
import pytest

from catheter_models.lab import history
from catheter_models.models.base import Recording


class _Fixed:
    """A forward 'model' whose error is a known constant."""

    kind = "greybox"
    direction = "forward"

    def __init__(self, bias_rad: float, chain: tuple[str, ...]) -> None:
        self.bias = bias_rad
        self.chain = chain

    def predict(self, x: np.ndarray) -> np.ndarray:
        return np.zeros(len(x)) + self.bias

    def predict_recording(self, rec: Recording) -> np.ndarray:
        return self.predict(rec.pressure_pa)


def _rec() -> Recording:
    return Recording("r", 250.0, np.zeros(500), np.zeros(500), source="bag:abc")


def test_versions_are_appended_read_back_and_plotted(tmp_path: Path) -> None:
    lab = tmp_path / "lab"
    v1 = history.record(lab, tmp_path / "m1", _Fixed(np.radians(2.0), ("drdpi",)), test=[_rec()])
    v2 = history.record(
        lab,
        tmp_path / "m2",
        _Fixed(np.radians(0.5), ("pneumatic_lag", "drdpi")),
        test=[_rec()],
        added="pneumatic_lag",
        parent=v1.version,
    )
    versions = history.load_history(lab)
    assert [v.version for v in versions] == [1, 2]
    assert versions[0].rmse_test_deg == pytest.approx(2.0)
    assert versions[1].rmse_test_deg == pytest.approx(0.5) and versions[1].parent == 1
    assert versions[1].test_sources == ["bag:abc"] and versions[1].rmse_train_deg is None
    assert history.find(versions, tmp_path / "m2") == v2
    text = history.history_text(versions)
    assert "pneumatic_lag -> drdpi" in text and "2.000" in text and "0.500" in text
    png = history.plot_history(versions, tmp_path / "h.png")
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_damaged_history_line_is_named(tmp_path: Path) -> None:
    (tmp_path / history.HISTORY_FILE).write_text('{"version": 1}\nnot json\n')
    with pytest.raises(history.HistoryError, match=r"history\.jsonl:1"):
        history.load_history(tmp_path)


def test_no_history_yet_says_how_to_start(tmp_path: Path) -> None:
    assert history.load_history(tmp_path) == []
    assert "catheter-lab add" in history.history_text([])
