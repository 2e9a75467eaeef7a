"""Excitation and test signals of the thesis, as named presets.

The thesis drives the catheter with pressure signals (training, eqs. 4.1/4.2; modelling tests,
sec. 5.4.2) and asks the controller to follow angle trajectories (control tests, sec. 9.3).
This package holds the equations (unit-agnostic: the output has the unit of the amplitude), the
designed "arbitrary" signals the thesis shows but never defines, and a registry of presets
that generate SI arrays ready for a simulator, a node or a bag.

A preset keeps its numbers in the units the thesis prints them in (bar for pressure, degrees
for angle; ``spec.unit`` says which) so a reader can compare it with the thesis line by line.
:meth:`SignalSpec.generate` converts to SI (gauge pascal, radian) through :mod:`units`.

Where a printed number cannot produce what the thesis's figures and tables show, the preset
deviates and its ``note`` says how and why.

One module per job: :mod:`.generators` (the equations), :mod:`.specs` (:class:`Signal` and
the preset classes), :mod:`.presets` (the thesis's preset tables and the registry) and
:mod:`.validation` (checks on a pressure signal or a trajectory before it is driven). Every
public name is re-exported here, so callers import from ``catheter_models.signals``.
"""

from __future__ import annotations

from .generators import (
    FloatArray,
    arbitrary_plateaus,
    chirp,
    descending_sine_nonzero_baseline,
    descending_sine_zero_baseline,
    instantaneous_frequency_hz,
    time_grid_s,
)
from .presets import (
    CLSTM_DECAYS_PER_S,
    CLSTM_DURATION_S,
    PRESETS,
    TEST_PRESSURE_SIGNALS,
    TEST_TRAJECTORIES,
    TRAINING_AMPLITUDE_BAR,
    TRAINING_DECAY_PER_S,
    TRAINING_DURATION_S,
    TRAINING_FREQS_HZ,
    clstm_training_set,
    get_preset,
    training_set,
)
from .specs import (
    DEFAULT_RATE_HZ,
    ArbitrarySpec,
    ChirpSpec,
    DescendingSineSpec,
    ParamValue,
    Signal,
    SignalKind,
    SignalSpec,
)
from .validation import (
    THESIS_MAX_ANGLE_RAD,
    THESIS_MAX_PRESSURE_PA,
    check_pressure_signal,
    check_trajectory,
)

__all__ = [
    "CLSTM_DECAYS_PER_S",
    "CLSTM_DURATION_S",
    "DEFAULT_RATE_HZ",
    "PRESETS",
    "TEST_PRESSURE_SIGNALS",
    "TEST_TRAJECTORIES",
    "THESIS_MAX_ANGLE_RAD",
    "THESIS_MAX_PRESSURE_PA",
    "TRAINING_AMPLITUDE_BAR",
    "TRAINING_DECAY_PER_S",
    "TRAINING_DURATION_S",
    "TRAINING_FREQS_HZ",
    "ArbitrarySpec",
    "ChirpSpec",
    "DescendingSineSpec",
    "FloatArray",
    "ParamValue",
    "Signal",
    "SignalKind",
    "SignalSpec",
    "arbitrary_plateaus",
    "check_pressure_signal",
    "check_trajectory",
    "chirp",
    "clstm_training_set",
    "descending_sine_nonzero_baseline",
    "descending_sine_zero_baseline",
    "get_preset",
    "instantaneous_frequency_hz",
    "time_grid_s",
    "training_set",
]
