"""The recurrent black-box reference: it starts where the filter bank is and learns what the
filter bank's linear columns cannot."""

from __future__ import annotations

import math

import numpy as np
import pytest

from catheter_models.lab import references
from catheter_models.lab.floors import FilterBankReference
from catheter_models.lab.recurrent_reference import NAME, RecurrentReference
from catheter_models.lab.references import FILTER_BANK, reference_floor
from catheter_models.models.base import Recording

RATE_HZ = 250.0


def _recording(seed: int, duration_s: float) -> Recording:
    """A bend the filter bank cannot write: its gain is set by the pressure 0.3 s ago.

    ``bend = x(t) * (10 + 20 x(t - 0.3 s))`` deg with x in bar: a product of the input
    with a delayed copy of itself, outside any sum of filtered plays.
    """
    rng = np.random.default_rng(seed)
    n = round(duration_s * RATE_HZ)
    levels = rng.uniform(0.0, 1.5, n // 125 + 1)
    x = np.convolve(np.repeat(levels, 125)[:n], np.ones(25) / 25.0, mode="same")
    late = np.concatenate([np.zeros(75), x[:-75]])
    bend_deg = x * (10.0 + 20.0 * late) + rng.normal(0.0, 0.05, n)
    return Recording(
        name=f"product_{seed}",
        rate_hz=RATE_HZ,
        pressure_pa=x * 1e5,
        angle_rad=np.radians(bend_deg),
        source="test",
    )


@pytest.mark.timeout(900)  # 45-80 s idle; minutes beside two busy loops
@pytest.mark.slow
def test_it_learns_what_the_filter_bank_cannot_and_is_chosen_as_the_stronger(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    train, test = [_recording(1, 120.0)], [_recording(2, 40.0)]
    bank_deg = FilterBankReference().fit(train).rmse_deg(test)
    reference = RecurrentReference(starts=2, max_epochs=8, patience=8).fit(train)
    assert len(reference.report_) == 2
    # Each start keeps its best epoch; epoch 0 is the filter bank on the training part.
    assert all(r.best_epoch > 0 for r in reference.report_)
    assert reference.rmse_deg(test) < 0.7 * bank_deg
    monkeypatch.setitem(references.RECURRENT_SETTINGS, "starts", 1)
    monkeypatch.setitem(references.RECURRENT_SETTINGS, "max_epochs", 4)
    deg, name, fitted = reference_floor("stronger", train, test)
    assert name == NAME and set(fitted) == {NAME, FILTER_BANK}
    assert deg == min(fitted.values()) and math.isclose(fitted[FILTER_BANK], bank_deg)


def test_too_little_training_data_is_refused_with_the_length_it_needs() -> None:
    with pytest.raises(Exception, match="needs at least 19 s of training data"):
        RecurrentReference().fit([_recording(1, 10.0)])


def test_an_unknown_reference_is_refused_by_name() -> None:
    with pytest.raises(ValueError, match="unknown reference 'lstm'"):
        reference_floor("lstm", [_recording(1, 10.0)], [_recording(2, 10.0)])
