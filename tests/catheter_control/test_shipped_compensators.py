"""The compensators the node hosts: the shipped models load, verify, and compensate."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from catheter_control.control_core import ControlCore, StaticInverseCompensator
from catheter_control.models import (
    COMPENSATORS,
    DEFAULT_COMPENSATOR,
    ModelCompensator,
    load_compensator,
    shipped_model_dir,
)
from catheter_control.trajectory import TrajectoryLimits, TrajectoryPlan, preset_knots
from catheter_models.errors import ParameterError
from catheter_models.model_dir import ModelDirError
from catheter_models.models.drdpi import DRDPI, DRDPIParams
from catheter_models.models.evaluate import track
from catheter_models.static_map import StaticMap


@pytest.mark.parametrize("kind", ["idrdpi", "clstm"])
def test_shipped_compensator_beats_the_static_inverse(kind: str) -> None:
    comp = load_compensator(kind, "")
    assert isinstance(comp, ModelCompensator)
    assert comp.preview_s >= 0.0
    ours = track(comp, "traj_up_chirp").metrics.rmse
    static = StaticInverseCompensator(StaticMap.load(shipped_model_dir("static_map")))
    baseline = track(static, "traj_up_chirp").metrics.rmse
    # Measured: IDRDPI 0.74 deg, c-LSTM 0.15 deg, static inverse 1.07 deg (docs/benchmarks.md).
    assert ours < 0.85 * baseline, (kind, np.degrees(ours), np.degrees(baseline))


# Offline tracking bounds [deg] for the shipped c-LSTM, the simulated rig in the loop with the
# node's limits. Measured 0.19 / 0.22 / 0.15 / 0.46 deg (docs/benchmarks.md); the bounds are
# 1.5x those: deterministic, so they fail a retrained model that lost a fifth of its accuracy
# on any one trajectory, not noise. The graph over DDS is tested on two of them
# (tests/integration/test_compensator.py): real time costs 20-40 s per trajectory there.
SHIPPED_CLSTM_BOUND_DEG = {
    "traj_descending_sine": 0.29,
    "traj_down_chirp": 0.33,
    "traj_up_chirp": 0.22,
    "traj_arbitrary_small_variations": 0.69,
}


@pytest.mark.parametrize("name", sorted(SHIPPED_CLSTM_BOUND_DEG))
def test_the_shipped_c_lstm_follows_each_thesis_trajectory(name: str) -> None:
    rmse_deg = float(np.degrees(track(load_compensator("clstm", ""), name).metrics.rmse))
    assert rmse_deg < SHIPPED_CLSTM_BOUND_DEG[name], (name, rmse_deg)


def test_the_default_is_the_c_lstm() -> None:
    assert DEFAULT_COMPENSATOR == "clstm"
    assert set(COMPENSATORS) == {"none", "idrdpi", "clstm", "greybox"}


def test_the_shipped_c_lstm_in_a_1_khz_loop_is_stepped_at_250_hz() -> None:
    """The real ONNX c-LSTM: a 1 kHz loop commands what a 250 Hz loop does at its samples."""
    plan = TrajectoryPlan.from_knots(*preset_knots("traj_up_chirp"), TrajectoryLimits(), 1000.0)
    commands = {}
    for rate_hz in (250.0, 1000.0):
        comp = load_compensator("clstm", "")
        assert comp.sample_period_s == pytest.approx(1 / 250)
        core = ControlCore(comp, 0.0, 3e5, 1e12)  # no slew limit: compare the model alone
        core.start(plan, 0.0)
        n = round(5.0 * rate_hz)
        commands[rate_hz] = np.array([core.tick(k / rate_hz, 1 / rate_hz) for k in range(n)])
        assert core.model_steps == round(5.0 * 250) + 1  # one sample read ahead
    slow = np.array([o.pressure_pa for o in commands[250.0]])
    fast = np.array([o.pressure_pa for o in commands[1000.0]])
    np.testing.assert_allclose(fast[::4], slow, rtol=0, atol=1e-3)
    assert np.all(np.abs(np.diff(fast)) <= np.abs(np.diff(slow)).max() / 4 + 1e-3)


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
