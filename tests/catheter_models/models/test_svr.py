"""The SVR forward model: numpy kernel = sklearn, stream = predict, safe round trip, memory."""

import json
import math

import numpy as np
import pytest
from sklearn.svm import SVR

from catheter_models.errors import ParameterError, SignalError
from catheter_models.model_dir import ModelDirError
from catheter_models.models import load_model
from catheter_models.models import svr as svr_module
from catheter_models.models.base import InsufficientDataError, NotFittedError, Recording
from catheter_models.models.data import simulate_recording, simulate_recordings
from catheter_models.models.svr import (
    REST_PRESSURE_PA,
    SVRModel,
    SVRWeights,
    lagged_windows,
)
from catheter_models.signals import training_set

# Small enough that a fit takes well under a second; large enough to learn the loops.
TINY = {
    "c_grid": (1.0, 10.0),
    "gamma_grid": (0.1, 1.0),
    "folds": 3,
    "grid_samples": 600,
    "fit_samples": 2000,
}


@pytest.fixture(scope="module")
def train() -> list[Recording]:
    specs = training_set()
    return simulate_recordings([specs[1], specs[6]])  # zero baseline 0.4 Hz, non-zero 0.6 Hz


@pytest.fixture(scope="module")
def test_recording() -> Recording:
    return simulate_recording("model_test_descending_sine")


@pytest.fixture(scope="module")
def model(train: list[Recording]) -> SVRModel:
    return SVRModel(**TINY).fit(train, progress=False)


def rms(error: np.ndarray) -> float:
    return float(np.sqrt(np.mean(error**2)))


def test_lagged_windows_newest_first_and_padded_rows() -> None:
    rows = lagged_windows(np.arange(10.0), n_taps=3, stride=2)
    assert rows.shape == (6, 3)
    np.testing.assert_array_equal(rows[0], [4.0, 2.0, 0.0])
    np.testing.assert_array_equal(rows[-1], [9.0, 7.0, 5.0])
    assert lagged_windows(np.arange(4.0), n_taps=3, stride=2).shape == (0, 3)


def test_numpy_kernel_equals_sklearn(
    train: list[Recording], monkeypatch: pytest.MonkeyPatch
) -> None:
    rng = np.random.default_rng(1)
    p = train[0].pressure_pa
    x = 2.0 * lagged_windows(p, n_taps=7, stride=9) / p.max() - 1.0
    y = train[0].angle_rad[6 * 9 :]  # the bend at each window's newest sample
    rows = np.sort(rng.choice(x.shape[0], 800, replace=False))
    estimator = SVR(kernel="rbf", C=10.0, gamma=0.3, epsilon=0.001).fit(x[rows], y[rows])
    weights = SVRWeights.from_estimator(estimator)
    assert weights.dual_coef.size > 50  # a kernel sum worth checking
    # Force many small blocks so the chunking is exercised, not just one matmul.
    monkeypatch.setattr(svr_module, "_KERNEL_BLOCK_ELEMENTS", 1000 * weights.dual_coef.size)
    np.testing.assert_allclose(weights.decision(x), estimator.predict(x), rtol=0, atol=1e-9)
    far = rng.uniform(-3.0, 3.0, size=(50, 7))  # away from the data: kernel near 0
    np.testing.assert_allclose(weights.decision(far), estimator.predict(far), rtol=0, atol=1e-9)


def test_fit_records_grid_and_choice(model: SVRModel) -> None:
    extra = model.fit_report_.extra
    table = extra["cross_validation"]["table"]
    assert len(table) == 4
    chosen = [row for row in table if row["rank"] == 1]
    assert {"C": chosen[0]["C"], "gamma": chosen[0]["gamma"]} == {
        "C": model.hyperparameters_["C"],
        "gamma": model.hyperparameters_["gamma"],
    }
    assert all(math.isfinite(row["rmse_rad"]) and row["rmse_rad"] > 0 for row in table)
    assert extra["n_support_vectors"] == model.weights_.dual_coef.size > 0
    assert extra["window"]["padding_pa"] == REST_PRESSURE_PA
    json.dumps(model.fit_report_.to_dict())  # lands in the manifest as JSON


def test_stream_equals_predict(model: SVRModel, test_recording: Recording) -> None:
    pressure = test_recording.pressure_pa[:1200]
    batch = model.predict(pressure)
    stream = model.stream()
    stepped = np.array([stream.step(float(v)) for v in pressure])
    np.testing.assert_allclose(stepped, batch, rtol=0, atol=1e-12)
    stream.reset()
    again = np.array([stream.step(float(v)) for v in pressure[:300]])
    np.testing.assert_allclose(again, batch[:300], rtol=0, atol=1e-12)


def test_save_load_predicts_identically(model: SVRModel, train, test_recording, tmp_path) -> None:
    manifest = model.save(tmp_path / "svr", training=train)
    assert set(manifest.files) == {"svr.npz", "svr.json"}
    assert manifest.metrics["fit"]["hyperparameters"]["C"] == model.hyperparameters_["C"]
    assert manifest.normalization["angle_rad"] == model.angle_scaler_.to_dict()
    for loaded in (SVRModel.load(tmp_path / "svr"), load_model(tmp_path / "svr")):
        assert isinstance(loaded, SVRModel)
        assert loaded.fitted_rate_hz == model.fitted_rate_hz
        assert loaded._settings() == model._settings()
        assert (
            loaded.fit_report_.extra["hyperparameters"]["gamma"] == model.hyperparameters_["gamma"]
        )
        np.testing.assert_array_equal(
            loaded.predict(test_recording.pressure_pa), model.predict(test_recording.pressure_pa)
        )


def test_tampered_weights_are_refused(model: SVRModel, tmp_path) -> None:
    model.save(tmp_path / "svr")
    path = tmp_path / "svr" / "svr.npz"
    data = bytearray(path.read_bytes())
    data[len(data) // 2] ^= 0x01
    path.write_bytes(bytes(data))
    with pytest.raises(ModelDirError, match=r"'svr.npz' fails its sha256 check"):
        SVRModel.load(tmp_path / "svr")


def test_nan_input_is_refused(model: SVRModel) -> None:
    with pytest.raises(SignalError, match="non-finite"):
        model.predict(np.array([0.0, 1.0e5, np.nan, 2.0e5]))
    with pytest.raises(SignalError, match="not finite"):
        model.stream().step(float("nan"))


def test_too_little_data_says_how_much_more(train: list[Recording]) -> None:
    short = Recording("short", 250.0, train[0].pressure_pa[:1000], train[0].angle_rad[:1000])
    with pytest.raises(InsufficientDataError, match=r"record 1500 more samples \(≈ 6 s"):
        SVRModel(**TINY).fit([short], progress=False)


def test_unfitted_and_bad_settings_are_refused(train: list[Recording]) -> None:
    with pytest.raises(NotFittedError, match="not fitted"):
        SVRModel().predict([0.0, 1.0])
    with pytest.raises(ParameterError, match="n_taps = 0"):
        SVRModel(n_taps=0).fit(train, progress=False)
    with pytest.raises(ParameterError, match="gamma_grid"):
        SVRModel(gamma_grid=(0.1, -1.0)).fit(train, progress=False)


def test_window_beats_memoryless_regression(model: SVRModel, train: list[Recording]) -> None:
    # The same learner, grid, epsilon and data with a one-sample window. A static map can at
    # best run through the middle of the loop, off by half its width (up to ~3 deg) on both
    # branches; the window sees whether the pressure rises or falls. Scored on a signal of the
    # training family at a frequency the fixture did not train on, with its own sensor noise.
    static = SVRModel(**{**TINY, "n_taps": 1}).fit(train, progress=False)
    held_out = simulate_recordings([training_set()[2]], seed0=7)[0]  # zero baseline, 0.6 Hz
    truth = held_out.angle_rad
    windowed_error = model.predict(held_out.pressure_pa) - truth
    static_error = static.predict(held_out.pressure_pa) - truth
    windowed_rmse, static_rmse = rms(windowed_error), rms(static_error)
    assert windowed_rmse < 0.8 * static_rmse, (windowed_rmse, static_rmse)  # 0.81 vs 1.23 deg
    windowed_max, static_max = np.abs(windowed_error).max(), np.abs(static_error).max()
    assert windowed_max < 0.6 * static_max, (windowed_max, static_max)  # 2.6 vs 5.2 deg
