"""The lag's refinements (a gradual flow knee, a limit that follows the upstream pressure).

They are held while the lag's earlier form is polished and opened only where the fill
reaches a flow limit and they remove a clear share of the loss (``greybox_fit.refine_forms``).
Proven on a fill the lab did not write: the Maxwell-slip catheter's orifice fill (ISO 6358
flow into a muscle whose volume grows as it pulls, ``tests/support/foreign_plants``), its
muscle pressure driving a known hysteresis law; and held on a plain first-order fill, where
they have nothing to describe.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from foreign_plants.base import Effect
from foreign_plants.maxwell_slip import MaxwellSlipPlant
from known_laws import lab_protocol, rate_independent_law

from catheter_models.models import greybox_fit
from catheter_models.models.blocks import block
from catheter_models.models.data import Recording
from catheter_models.models.evaluate import pooled_rmse
from catheter_models.models.greybox import GreyBox
from catheter_models.units import pa_to_bar

RATE_HZ = 250.0
NOISE_DEG = 0.02
ORIFICE_LAG_S = 0.08
"""The Maxwell-slip plant's small-signal fill time (its range's upper half: a limit shows)."""


def _behind(fill: str, recordings: list[Recording], seed: int) -> list[Recording]:
    """The law behind the muscle's fill from the valve command, noise on the bend."""
    law, rng = rate_independent_law(), np.random.default_rng(seed)
    plant = MaxwellSlipPlant()
    out = []
    for r in recordings:
        if fill == "orifice":
            lag = Effect("pneumatic_lag", {"time_constant_s": ORIFICE_LAG_S})
            _, muscle_pa = plant.simulate_clean(r.pressure_pa, RATE_HZ, [lag])
            x_bar = pa_to_bar(muscle_pa)
        else:
            plain = [ORIFICE_LAG_S, 1.0, 1e8, 1.0, 0.0, 0.0, 0.0]
            x_bar = block("pneumatic_lag").apply(pa_to_bar(r.pressure_pa), RATE_HZ, plain)
        bend_deg = law.run(x_bar, RATE_HZ) + rng.normal(0.0, NOISE_DEG, x_bar.size)
        out.append(replace(r, angle_rad=np.deg2rad(bend_deg)))
    return out


def _data(fill: str) -> tuple[list[Recording], list[Recording]]:
    train, test = lab_protocol()
    return _behind(fill, train, 1), _behind(fill, test, 2)


def _chain(train: list[Recording]) -> GreyBox:
    core = GreyBox(core="free_pi").fit(train, progress=False)
    return core.with_effect("pneumatic_lag").fit(train, progress=False)


def _refinements(model: GreyBox) -> tuple[float, float]:
    values = model.block_values()["pneumatic_lag"]
    return values["flow_knee"], values["upstream_share"]


@pytest.mark.slow
def test_an_orifice_fill_opens_the_refinements_and_they_remove_most_of_the_miss(
    monkeypatch: pytest.MonkeyPatch,
) -> None:
    train, test = _data("orifice")
    refined = _chain(train)
    knee, upstream = _refinements(refined)
    assert knee > 0.2 or upstream > 0.2, refined.block_values()
    # The same search with every refinement turned down: the lag's earlier form.
    monkeypatch.setattr(greybox_fit, "REFINE_GAIN", 1.0)
    earlier = _chain(train)
    assert _refinements(earlier) == (0.0, 0.0)
    refined_deg = float(np.degrees(pooled_rmse(refined, test)))
    earlier_deg = float(np.degrees(pooled_rmse(earlier, test)))
    assert refined_deg < 0.6 * earlier_deg, (refined_deg, earlier_deg)


@pytest.mark.slow
def test_a_plain_fill_keeps_the_lags_earlier_form() -> None:
    train, _ = _data("plain")
    assert _refinements(_chain(train)) == (0.0, 0.0)
