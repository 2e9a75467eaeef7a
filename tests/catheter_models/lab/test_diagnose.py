"""Diagnosis on data with a hidden effect: the simulated plant runs with an effect the
default chain (the DRDPI) lacks; the lab must name it, identify it and remove the error it
causes, and must call a model without a hidden effect adequate.

The plant's physics differ from the blocks' forms (docs/effects.md): the plant fills the
muscle through laminar compressible flow (dP/dt ~ P_valve^2 - P_muscle^2, absolute
pressures), the block is a linear first-order lag; so the test is not code agreeing with
itself. The effect is set strong enough to dominate the DRDPI's own structural error
(0.7 deg held out on this plant without it).
"""

from __future__ import annotations

import numpy as np
import pytest

from catheter_models.errors import ParameterError
from catheter_models.lab.diagnose import diagnose
from catheter_models.lab.greybox import GreyBox
from catheter_models.lab.signals import lab_test_specs, lab_training_specs
from catheter_models.models.data import simulate_recordings
from catheter_models.plant.config import PlantConfig

pytestmark = pytest.mark.slow


def _data(config: PlantConfig) -> tuple[list, list]:
    train = simulate_recordings(lab_training_specs(), config)
    test = simulate_recordings(lab_test_specs(), config, seed0=50)
    return train, test


def test_hidden_pneumatic_lag_is_ranked_first_identified_and_removed() -> None:
    tau_s = 0.2
    config = PlantConfig.thesis_rig(seed=1).with_effect(
        "pneumatic_lag", enabled=True, time_constant_s=tau_s
    )
    train, test = _data(config)
    model = GreyBox().fit(train, progress=False)
    result = diagnose(model, train, test)
    print(result.text())
    best = result.candidates[0]
    assert best.effect == "pneumatic_lag", result.text()
    assert result.verdict == "add pneumatic_lag"
    # Adding it cuts the held-out error by at least half (measured 1.71 -> 0.68 deg).
    assert best.rmse_test_deg <= 0.5 * result.rmse_test_deg, result.text()
    # The plant's time constant is its small-signal one at 1.5 bar; the block's is one
    # linear lag over 0-3 bar (measured 0.164 s against 0.2 s).
    assert best.value_si == pytest.approx(tau_s, rel=0.3), result.text()
    assert "pneumatic_lag" in result.text() and "time_constant_s" in result.text()


def test_nothing_hidden_is_adequate() -> None:
    train, test = _data(PlantConfig.thesis_rig(seed=1))
    model = GreyBox().fit(train, progress=False)
    result = diagnose(model, train, test)
    print(result.text())
    assert result.verdict == "adequate", result.text()
    assert not result.significant
    assert "adequate" in result.text()
    # Every catalogue effect was tried (none is untestable on the lab's excitation).
    assert {c.effect for c in result.candidates} == {
        "transport_delay",
        "pneumatic_lag",
        "creep",
        "tip_dynamics",
        "drift",
    }
    assert all(c.measured_reduction < 0.10 for c in result.candidates)


def test_too_little_excitation_is_said_not_guessed() -> None:
    # Two of the thesis's training sines (non-zero baseline: the pressure never rests), 13 s
    # each: no plateau, so creep cannot be identified, and too short for a drift.
    train = simulate_recordings(["train_nonzero_f0.6", "train_nonzero_f0.8"])
    model = GreyBox(budget={"max_generations": 5, "wall_time_s": 5}).fit(train, progress=False)
    result = diagnose(model, train, train, effects=["creep", "drift"])
    assert "creep" in result.untestable and "plateau" in result.untestable["creep"]
    assert "drift" in result.untestable and "30 s" in result.untestable["drift"]
    assert "not testable here" in result.text()
    with pytest.raises(ParameterError, match="too little excitation to identify creep"):
        model.with_effect("creep").fit(train, progress=False)
    with pytest.raises(ParameterError, match="unknown effect 'friction'"):
        diagnose(model, train, train, effects=["friction"])
    assert np.isfinite(result.rmse_test_deg)
