"""The compensators the node hosts: the shipped models load, verify, and compensate."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from catheter_control.control_core import StaticInverseCompensator
from catheter_control.models import (
    COMPENSATORS,
    DEFAULT_COMPENSATOR,
    ModelCompensator,
    load_compensator,
    shipped_model_dir,
)
from catheter_models.errors import ParameterError
from catheter_models.model_dir import ModelDirError
from catheter_models.models.drdpi import DRDPI, DRDPIParams
from catheter_models.models.evaluate import track
from catheter_models.static_map import StaticMap


@pytest.mark.parametrize("kind", ["idrdpi", "clstm"])
def test_shipped_compensator_beats_the_static_inverse(kind: str) -> None:
    comp = load_compensator(kind, "", control_rate_hz=250.0)
    assert isinstance(comp, ModelCompensator)
    assert comp.preview_s >= 0.0
    ours = track(comp, "traj_up_chirp").metrics.rmse
    static = StaticInverseCompensator(StaticMap.load(shipped_model_dir("static_map")))
    baseline = track(static, "traj_up_chirp").metrics.rmse
    # Measured: IDRDPI 0.74 deg, c-LSTM 0.15 deg, static inverse 1.07 deg (docs/benchmarks.md).
    assert ours < 0.85 * baseline, (kind, np.degrees(ours), np.degrees(baseline))


def test_the_default_is_the_c_lstm() -> None:
    assert DEFAULT_COMPENSATOR == "clstm"
    assert set(COMPENSATORS) == {"none", "idrdpi", "clstm"}


def test_a_model_fitted_at_another_rate_is_refused() -> None:
    with pytest.raises(ParameterError, match=r"fitted at 250 Hz.*control_rate_hz is 1000 Hz"):
        load_compensator("clstm", "", control_rate_hz=1000.0)


def test_a_tampered_shipped_model_is_refused(tmp_path: Path) -> None:
    copy = tmp_path / "clstm"
    shutil.copytree(shipped_model_dir("clstm"), copy)
    onnx = copy / "model.onnx"
    data = bytearray(onnx.read_bytes())
    data[len(data) // 2] ^= 0x01  # one flipped bit in the weights
    onnx.write_bytes(bytes(data))
    with pytest.raises(ModelDirError, match=r"'model.onnx' fails its sha256 check"):
        load_compensator("clstm", str(copy))


def test_a_forward_model_is_not_a_compensator(tmp_path: Path) -> None:
    forward = DRDPI.from_params(
        DRDPIParams(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1e3, 10.0, 0.1, 0.0, 12.0, 0.5)
    )
    forward.save(tmp_path / "drdpi")
    with pytest.raises(ModelDirError, match="holds a 'drdpi' model, expected 'idrdpi'"):
        load_compensator("idrdpi", str(tmp_path / "drdpi"))


def test_unknown_compensator_lists_the_known_ones() -> None:
    with pytest.raises(ParameterError, match="available: none, idrdpi, clstm"):
        load_compensator("pid", "")
