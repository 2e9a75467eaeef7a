"""A known hysteresis law and the lab's protocol, for tests of the grey box's search.

A test hides an input block (a delay, a foreign fill) in front of a law the chain's core can
match exactly, so what the search finds is the block's doing alone. The tests of the delay
search (tests/catheter_models/models/test_greybox_search.py) and of the lag's refinements
(test_lag_refinement.py) share the law and the signals.
"""

from __future__ import annotations

import numpy as np

from catheter_models.lab.signals import lab_spec
from catheter_models.models.cores import FreePI
from catheter_models.models.data import Recording, simulate_recordings
from catheter_models.signals import SignalSpec, get_preset


def rate_independent_law() -> FreePI:
    """A play law with no rate factor: any rate dependence in a fit is the hidden block's."""
    law = FreePI()
    rng = np.random.default_rng(11)
    weights = np.abs(rng.normal(0.0, 1.0, law.n_columns)) * 0.15
    weights[-1] = 0.0
    law.load_values({"weights": list(weights), "beta_s": 0.0})
    return law


def _signals(*names: str) -> list[SignalSpec]:
    specs = [lab_spec(n) or get_preset(n) for n in names]
    return [s for s in specs if s is not None]


def lab_protocol() -> tuple[list[Recording], list[Recording]]:
    """Training and held-out recordings (the simulated rig's, bends to be replaced).

    The lab's protocol: sines, and plateaus reached by fast steps. On sines alone a delay
    and a rate factor are one thing (a play's threshold widened by beta times the speed lags
    a ramp by beta); a step's onset and a reversal tell them apart.
    """
    train = simulate_recordings(_signals("train_zero_f0.8", "lab_steps_7", "lab_plateaus_7"))
    test = simulate_recordings(_signals("lab_steps_9", "model_test_up_chirp"), seed0=7)
    return train, test
