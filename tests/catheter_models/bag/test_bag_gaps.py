"""A bag with a hole in it: `bag info` counts it, and training data warns before it interpolates."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from catheter_models.bag.from_arrays import write_bag_from_arrays
from catheter_models.bag.info import bag_info
from catheter_models.gaps import BagGapWarning
from catheter_models.models.data import recording_from_bag


def _bag(path: Path, lost: slice | None) -> Path:
    t_s = np.arange(2500) / 250.0
    keep = np.ones(t_s.size, bool)
    if lost is not None:
        keep[lost] = False
    t_s = t_s[keep]
    p_pa = 1.0e5 * (1.0 + np.sin(t_s))
    return write_bag_from_arrays(
        path, t_s, p_pa, p_pa, np.radians(5.0) * np.sin(t_s), start_time_ns=1_700_000_000 * 10**9
    )


def test_bag_info_counts_lost_samples_per_stream(tmp_path: Path) -> None:
    text = bag_info(_bag(tmp_path / "holed", slice(1000, 1022)))
    section = text.split("gaps (from header stamps):")[1].split("custom_data")[0]
    for topic in ("pressure/command", "pressure/measured", "tip/angle"):
        line = next(x for x in section.splitlines() if x.strip().startswith(f"/catheter/{topic}"))
        assert "lost 22 samples in 1 gap(s), longest 92 ms" in line, line
    clean = bag_info(_bag(tmp_path / "whole", None))
    section = clean.split("gaps (from header stamps):")[1].split("custom_data")[0]
    assert all(x.strip().endswith("none") for x in section.strip().splitlines()), section


def test_training_data_says_where_it_interpolates(tmp_path: Path) -> None:
    with pytest.warns(BagGapWarning) as seen:
        recording = recording_from_bag(_bag(tmp_path / "holed", slice(1000, 1022)))
    said = [str(w.message) for w in seen]
    for topic in ("pressure/command", "tip/angle"):
        assert any(
            f"{topic} lacks 22 samples in 1 gap(s)" in m and "after t = 3.996 s" in m for m in said
        ), said
    assert recording.pressure_pa.size == 2500  # the grid spans the hole, as it says
    # How it spans it: the command held from before the hole, the bend interpolated.
    assert any(m.startswith(f"{tmp_path / 'holed'}: pressure/command") for m in said), said
    for m in said:
        fill = "holds the last command over it" if ": pressure/command" in m else "interpolates"
        assert fill in m, m
    np.testing.assert_array_equal(recording.pressure_pa[1000:1022], recording.pressure_pa[999])
