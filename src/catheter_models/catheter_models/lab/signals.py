"""The excitation a diagnosis needs: the thesis's signals plus plateaus with fast ramps.

The thesis's DRDPI training set (eight decaying sines, 0.2-0.8 Hz) never holds the pressure
still and never moves it fast, so creep and tip dynamics cannot show in it. The lab's sets
add random plateaus (1-3 s) joined by ramps of up to 20 bar/s; held-out data uses other seeds.
"""

from __future__ import annotations

import dataclasses

from catheter_models.errors import SignalError
from catheter_models.signals import (
    TEST_PRESSURE_SIGNALS,
    ArbitrarySpec,
    SignalSpec,
    get_preset,
    training_set,
)

_PLATEAUS = "model_test_arbitrary_plateaus"
FAST_RAMP_BAR_PER_S = 20.0


def _plateaus(name: str, seed: int) -> SignalSpec:
    base = get_preset(_PLATEAUS)
    if not isinstance(base, ArbitrarySpec):
        raise SignalError(f"{_PLATEAUS} is no longer a random-plateau signal")
    return dataclasses.replace(base, name=name, seed=seed, max_ramp_rate=FAST_RAMP_BAR_PER_S)


def lab_training_specs() -> list[SignalSpec]:
    """The thesis's DRDPI training set plus two 40 s plateau signals (seeds 100, 101)."""
    return [*training_set(), _plateaus("lab_plateaus_100", 100), _plateaus("lab_plateaus_101", 101)]


def lab_test_specs() -> list[SignalSpec]:
    """The thesis's four model test signals plus one plateau signal of another seed."""
    return [get_preset(n) for n in TEST_PRESSURE_SIGNALS] + [_plateaus("lab_plateaus_999", 999)]


def lab_spec(name: str) -> SignalSpec | None:
    """The lab's plateau signal called ``name`` (``lab_plateaus_<seed>``), else None."""
    prefix = "lab_plateaus_"
    if not name.startswith(prefix) or not name[len(prefix) :].isdigit():
        return None
    return _plateaus(name, int(name[len(prefix) :]))
