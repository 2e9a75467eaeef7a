"""The excitation a diagnosis needs: the thesis's signals plus plateaus with fast ramps.

The thesis's DRDPI training set (eight decaying sines, 0.2-0.8 Hz) never holds the pressure
still and never moves it fast, so creep and tip dynamics cannot show in it. The lab's sets
add random plateaus (1-3 s) joined by ramps of 0.5-2 s (at most 20 bar/s), and one signal
with 0.05-0.5 s ramps (at most 30 bar/s), fast enough to ring the tip and to tell a transport
delay from the DRDPI's rate-dependent lag; held-out data uses other seeds.
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
SLOW_RAMP_BAR_PER_S = 20.0
FAST_RAMP_BAR_PER_S = 30.0
RAMP_S = (0.05, 0.5)
"""Ramp lengths [s]: short enough to ring the tip and to tell a delay from a slow response."""


def _plateaus(name: str, seed: int, *, fast: bool = False) -> SignalSpec:
    base = get_preset(_PLATEAUS)
    if not isinstance(base, ArbitrarySpec):
        raise SignalError(f"{_PLATEAUS} is no longer a random-plateau signal")
    if fast:
        return dataclasses.replace(
            base, name=name, seed=seed, ramp_s=RAMP_S, max_ramp_rate=FAST_RAMP_BAR_PER_S
        )
    return dataclasses.replace(base, name=name, seed=seed, max_ramp_rate=SLOW_RAMP_BAR_PER_S)


def lab_training_specs() -> list[SignalSpec]:
    """The thesis's DRDPI training set plus three 40 s plateau signals, one with fast ramps."""
    return [
        *training_set(),
        _plateaus("lab_plateaus_100", 100),
        _plateaus("lab_plateaus_101", 101),
        _plateaus("lab_steps_102", 102, fast=True),
    ]


def lab_test_specs() -> list[SignalSpec]:
    """The thesis's four model test signals plus two plateau signals of other seeds."""
    return [
        *(get_preset(n) for n in TEST_PRESSURE_SIGNALS),
        _plateaus("lab_plateaus_999", 999),
        _plateaus("lab_steps_998", 998, fast=True),
    ]


def lab_spec(name: str) -> SignalSpec | None:
    """The lab's signal ``lab_plateaus_<seed>`` or ``lab_steps_<seed>`` (fast), else None."""
    for prefix, fast in (("lab_plateaus_", False), ("lab_steps_", True)):
        seed = name[len(prefix) :]
        if name.startswith(prefix) and seed.isdigit():
            return _plateaus(name, int(seed), fast=fast)
    return None
