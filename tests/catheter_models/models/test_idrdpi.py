"""Tests of the inverse DRDPI compensator (catheter_models.models.idrdpi, thesis ch. 9)."""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.model_dir import ModelDirError
from catheter_models.models import load_model
from catheter_models.models.base import Recording
from catheter_models.models.data import simulate_recordings
from catheter_models.models.drdpi import DRDPI, PARAMS_FILE, DRDPIParams
from catheter_models.models.evaluate import tracking_score
from catheter_models.models.identify import Budget
from catheter_models.models.idrdpi import (
    IDRDPI,
    dominant_frequency_hz,
    frequency_tag_hz,
    group_by_frequency,
)
from catheter_models.plant import PlantConfig
from catheter_models.signals import training_set
from catheter_models.units import deg_to_rad, rad_to_deg

RATE_HZ = 250.0
SMALL = Budget(max_generations=40, popsize=5, wall_time_s=6.0, polish_max_evals=20)
# A DRDPI with plays, a knee at y = 10 and rate dependence (forward units: bar -> deg).
KNOWN = DRDPIParams(
    alpha0=3.0 * math.exp(0.5),
    alpha1=-1.0 * math.exp(1.0),
    alpha2=0.0,
    beta0=0.5,
    beta1=1.0,
    beta2=0.0,
    dp=10.0,
    dn=10.0,
    zeta=0.1,
    beta=0.02,
    a0=2.0,
    g0=0.05,
)


@pytest.fixture(scope="module")
def training() -> list[Recording]:
    return simulate_recordings(training_set())


@pytest.fixture(scope="module")
def small_training(training: list[Recording]) -> list[Recording]:
    """One recording per frequency (the zero-baseline ones), to keep the fits quick."""
    return [r for r in training if r.name.startswith("train_zero_")]


def test_frequency_groups_by_name_and_by_spectrum_agree(training: list[Recording]) -> None:
    by_name = group_by_frequency(training, "name")
    assert [g.frequency_hz for g in by_name] == pytest.approx([0.2, 0.4, 0.6, 0.8])
    assert all(len(g.recordings) == 2 for g in by_name)
    untagged = [replace(r, name=f"bag_{i}") for i, r in enumerate(training)]
    by_spectrum = group_by_frequency(untagged, "auto")  # no tags: estimates are used
    assert [g.frequency_hz for g in by_spectrum] == pytest.approx([0.2, 0.4, 0.6, 0.8], abs=0.03)
    for a, b in zip(by_name, by_spectrum, strict=True):
        assert {r.pressure_pa.tobytes() for r in a.recordings} == {
            r.pressure_pa.tobytes() for r in b.recordings
        }
    with pytest.raises(ParameterError, match="_f<Hz>"):
        group_by_frequency(untagged, "name")


def test_frequency_helpers() -> None:
    assert frequency_tag_hz("train_zero_f0.6") == 0.6
    assert frequency_tag_hz("clstm_zero_f0.4_tau0.1") == 0.4
    assert frequency_tag_hz("model_test_up_chirp") is None
    t = np.arange(4000) / RATE_HZ
    x = np.exp(-0.15 * t) * (np.sin(2 * math.pi * 0.6 * t - math.pi / 2) + 1.0)
    assert dominant_frequency_hz(x, RATE_HZ) == pytest.approx(0.6, abs=0.01)


def test_analytic_inverse_of_a_known_drdpi_composed_with_it_is_near_identity() -> None:
    forward = DRDPI.from_params(KNOWN)
    inverse = IDRDPI.from_params(KNOWN)
    t = np.arange(round(40 * RATE_HZ)) / RATE_HZ
    desired_deg = 8.0 * (1.0 - np.cos(2 * math.pi * 0.05 * t))  # slow: 2.5 deg/s at most
    achieved_deg = rad_to_deg(forward.predict(inverse.predict(deg_to_rad(desired_deg))))
    # Exact but for the inverse's estimate of the pressure rate in its thresholds: it divides
    # its input's rate by the major-loop slope, while plays that stick (from rest, after a
    # reversal) make the true slope up to W_N / a0 times steeper. With beta = 0.02 s that
    # shifts the thresholds by a few hundredths of a bar for a moment: < 0.1 deg here.
    np.testing.assert_allclose(achieved_deg, desired_deg, atol=0.1)
    assert float(np.sqrt(np.mean((achieved_deg - desired_deg) ** 2))) < 0.01


@pytest.mark.parametrize(
    ("method", "structure"),
    [("analytic", "inverse"), ("gpi", "inverse"), ("direct", "inverse"), ("direct", "drdpi")],
)
def test_each_method_fits_and_tracks_better_than_doing_nothing(
    small_training: list[Recording], method: str, structure: str, tmp_path: Path
) -> None:
    model = IDRDPI(
        method=method,  # type: ignore[arg-type]
        structure=structure,  # type: ignore[arg-type]
        budget=SMALL,
        gpi_budget=SMALL,
        virtual_samples=10_000,
        seed=0,
    ).fit(small_training, progress=False)
    result = tracking_score(model, "traj_descending_sine")
    nothing_rad = float(np.sqrt(np.mean(result.desired_rad**2)))  # zero command: no bend
    assert result.metrics.rmse < 0.3 * nothing_rad
    assert np.all(np.isfinite(result.command_pa))
    # the stream (what the compensator steps) is predict, sample by sample
    desired = result.desired_rad[:800]
    stream = model.stream()
    np.testing.assert_array_equal([stream.step(float(v)) for v in desired], model.predict(desired))
    # and it survives a round trip through a model directory
    model.save(tmp_path / "m")
    loaded = load_model(tmp_path / "m")
    assert isinstance(loaded, IDRDPI)
    assert loaded.params_ == model.params_
    assert loaded.structure_ == structure
    assert len(loaded.gpis_) == (4 if method == "gpi" else 0)
    np.testing.assert_array_equal(loaded.predict(desired), model.predict(desired))


def test_a_dead_time_read_ahead_tracks_a_delayed_plant_and_survives_saving(
    tmp_path: Path,
) -> None:
    # Our plant with 80 ms of transport delay. A delay commutes with the hysteresis, so an
    # IDRDPI told the dead time (as commission tells it what tune found) must track the
    # delayed plant as well as the same fit tracks the plant without the delay; told
    # nothing, the fit takes the delay up in its rate terms and tracks worse.
    zero = [s for s in training_set() if s.name.startswith("train_zero_")]
    plain = PlantConfig.thesis_rig()
    delayed = plain.with_effect("transport_delay", delay_s=0.08)
    trajectories = ("traj_descending_sine", "traj_up_chirp")

    def rmse_deg(model: IDRDPI, config: PlantConfig) -> list[float]:
        return [math.degrees(tracking_score(model, t, config).metrics.rmse) for t in trajectories]

    fit = {"budget": SMALL, "seed": 0}
    undelayed = rmse_deg(IDRDPI(**fit).fit(simulate_recordings(zero, plain), progress=False), plain)
    train = simulate_recordings(zero, delayed)
    told = IDRDPI(**fit, preview_s=0.08).fit(train, progress=False)
    assert told.preview_samples == 20
    with_preview = rmse_deg(told, delayed)
    without = rmse_deg(IDRDPI(**fit).fit(train, progress=False), delayed)
    for a, b, c in zip(undelayed, with_preview, without, strict=True):
        assert b == pytest.approx(a, rel=0.05, abs=0.02), (undelayed, with_preview)
        assert c > b + 0.1, (with_preview, without)
    model = told
    model.save(tmp_path / "m")
    loaded = load_model(tmp_path / "m")
    assert isinstance(loaded, IDRDPI) and loaded.preview_samples == 20
    desired = deg_to_rad(np.linspace(0.0, 20.0, 500))
    np.testing.assert_array_equal(loaded.predict(desired), model.predict(desired))
    # predict reads the set-point ahead as the node does: the stream fed 20 samples early.
    stream = model.stream()
    ahead = np.concatenate([desired[20:], np.full(20, desired[-1])])
    np.testing.assert_array_equal([stream.step(float(v)) for v in ahead], model.predict(desired))


def test_a_model_saved_before_the_preview_loads_without_one() -> None:
    # The shipped IDRDPI was saved before preview_s existed (its manifest has no such key).
    root = Path(__file__).resolve().parents[3]
    shipped = load_model(root / "src/catheter_control/catheter_control/data/idrdpi")
    assert isinstance(shipped, IDRDPI)
    assert shipped.preview_s == 0.0 and shipped.preview_samples == 0


def test_pressure_is_finite_for_any_finite_desired_angle() -> None:
    model = IDRDPI.from_params(KNOWN)
    wild = deg_to_rad(np.array([0.0, 1e4, -1e4, 0.0, 1e-9, 35.0, 1e6]))
    assert np.all(np.isfinite(model.predict(wild)))


def test_a_tampered_idrdpi_is_refused(tmp_path: Path) -> None:
    IDRDPI.from_params(KNOWN).save(tmp_path / "m")
    path = tmp_path / "m" / PARAMS_FILE
    path.write_text(path.read_text().replace('"zeta": 0.1', '"zeta": 0.2'))
    with pytest.raises(ModelDirError, match="sha256"):
        IDRDPI.load(tmp_path / "m")


def test_settings_are_checked() -> None:
    with pytest.raises(ParameterError, match="structure is 'inverse'"):
        IDRDPI(method="analytic", structure="drdpi")
    with pytest.raises(ParameterError, match="method"):
        IDRDPI(method="genetic")  # type: ignore[arg-type]
    with pytest.raises(ParameterError, match="virtual_samples"):
        IDRDPI(method="gpi", virtual_samples=10)
    with pytest.raises(ParameterError, match=r"preview_s = 2.0 must be in \[0, 0.5\] s"):
        IDRDPI(preview_s=2.0)
