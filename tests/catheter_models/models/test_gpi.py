"""Tests of the GPI and its inverse (catheter_models.models.gpi, thesis eqs. 9.12-9.21)."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.model_dir import ModelDirError
from catheter_models.models import load_model
from catheter_models.models.base import Recording
from catheter_models.models.data import simulate_recordings
from catheter_models.models.gpi import GPI, GPI_PARAMS_FILE, GPIParams
from catheter_models.models.identify import Budget
from catheter_models.signals import training_set
from catheter_models.units import bar_to_pa, deg_to_rad, rad_to_deg

RATE_HZ = 250.0
# Table 9.3 (0.4 Hz) as printed: c0, c1, c2, c3, beta, rho, tau, q.
TABLE_9_3 = GPIParams(7.751, 0.602, -0.971, 5.037, 1.096, 9.919, 1.272, 1.745)


@pytest.fixture(scope="module")
def group_04() -> list[Recording]:
    """The 0.4 Hz pair of the thesis's training set, through the simulated rig."""
    specs = [s for s in training_set() if s.name.endswith("_f0.4")]
    return simulate_recordings(specs)


@pytest.fixture(scope="module")
def fitted(group_04: list[Recording]) -> GPI:
    budget = Budget(max_generations=80, popsize=8, wall_time_s=15.0)
    return GPI(budget=budget, seed=0).fit(group_04, progress=False)


def test_gpi_fits_one_frequency_of_the_rig(fitted: GPI, group_04: list[Recording]) -> None:
    for rec in group_04:
        err = rad_to_deg(fitted.predict(rec.pressure_pa) - rec.angle_rad)
        # Rate-independent and without a deadband operator, the GPI stays near 1 deg on the
        # rig (the thesis's GPIs were used only to generate data); 1.5 deg bounds a bad fit.
        assert float(np.sqrt(np.mean(err**2))) < 1.5, rec.name


def test_inverse_gpi_undoes_the_gpi(fitted: GPI, group_04: list[Recording]) -> None:
    p = group_04[0].pressure_pa
    np.testing.assert_allclose(fitted.inverse_predict(fitted.predict(p)), p, atol=1e-6)


def test_thesis_table_9_3_inverse_is_exact_on_a_signal() -> None:
    model = GPI.from_params(TABLE_9_3)
    t = np.arange(3000) / RATE_HZ
    p = bar_to_pa(1.4 * np.exp(-0.1 * t) * (np.sin(2 * math.pi * 0.4 * t - math.pi / 2) + 1.0))
    np.testing.assert_allclose(model.inverse_predict(model.predict(p)), p, atol=1e-6)


def test_streams_equal_batch(fitted: GPI, group_04: list[Recording]) -> None:
    p = group_04[1].pressure_pa
    stream = fitted.stream()
    np.testing.assert_array_equal([stream.step(float(v)) for v in p], fitted.predict(p))
    angle = group_04[1].angle_rad
    inverse = fitted.inverse_stream()
    streamed = [inverse.step(float(v)) for v in angle]
    np.testing.assert_array_equal(streamed, fitted.inverse_predict(angle))


def test_inverse_is_finite_beyond_the_gpi_range(fitted: GPI) -> None:
    out = fitted.inverse_predict(deg_to_rad(np.array([0.0, 500.0, -500.0, 1e6])))
    assert np.all(np.isfinite(out))
    assert out[1] > bar_to_pa(3.0) > out[2]


def test_save_then_load_and_tampering(fitted: GPI, tmp_path: Path) -> None:
    fitted.save(tmp_path / "g")
    loaded = load_model(tmp_path / "g")
    assert isinstance(loaded, GPI)
    assert loaded.params_ == fitted.params_
    p = bar_to_pa(np.linspace(0.0, 3.0, 50))
    np.testing.assert_array_equal(loaded.predict(p), fitted.predict(p))
    path = tmp_path / "g" / GPI_PARAMS_FILE
    path.write_text(path.read_text().replace('"q": ', '"q": 1'))
    with pytest.raises(ModelDirError, match="sha256"):
        GPI.load(tmp_path / "g")


def test_bad_gpi_parameters_are_refused() -> None:
    good = TABLE_9_3.to_dict()
    with pytest.raises(ParameterError, match="c1"):
        GPIParams.from_dict({**good, "c1": 0.0})
    with pytest.raises(ParameterError, match="q"):
        GPIParams.from_dict({**good, "q": -1.0})
    with pytest.raises(ParameterError, match="rho"):
        GPIParams.from_dict({**good, "rho": math.inf})
    with pytest.raises(ParameterError, match="unknown"):
        GPI(bounds={"rho": (0.0, 1.0)})  # the search uses p1, the first play's weight
