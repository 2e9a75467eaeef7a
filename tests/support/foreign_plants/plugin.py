"""The foreign plants as plants of the rig's contract, for ``sim_hardware`` and the emulated rig.

Each factory takes no arguments and returns a plant with ``rate_hz``, ``reset()`` and
``step(pressure_command_pa) -> (pressure_measured_pa, bend_rad)`` (docs/simulated_rig.md,
"Your own plant"), so it is named on the command line as ``foreign_plants.plugin:boucwen_lag``
with ``tests/support`` on ``PYTHONPATH``. The bend is the foreign plant's (its own hysteresis,
physics and sensor noise); the measured pressure comes from a valve and transmitter written
here, apart from ``catheter_models.plant``: a first-order regulator (8 ms) limited to 0-3 bar,
read by a transmitter with 400 Pa of white noise and a 10 Pa resolution.

Factories: ``maxwell_slip``, ``boucwen``, ``duhem`` (nothing hidden) and each with ``_lag``
(pneumatic lag), ``_delay`` (transport delay) or ``_tip`` (a ringing tip), every strength in
the middle of :data:`~foreign_plants.base.RANGES`. Variant 0 of each plant, fixed seeds.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Final

import numpy as np

from . import PLANTS
from .base import RANGES, Effect, PlantStepper

RATE_HZ: Final = 250.0
"""The sample rate of every plant here [Hz]."""
_BEND_SEED: Final = 5
_VALVE_SEED: Final = 9
_VALVE_TIME_CONSTANT_S: Final = 0.008
_VALVE_MAX_PA: Final = 3.0e5
_TRANSMITTER_NOISE_PA: Final = 400.0
_TRANSMITTER_RESOLUTION_PA: Final = 10.0


def _mid(effect: str) -> Effect:
    """``effect`` at the middle of its real-rig range."""
    return Effect(effect, {k: 0.5 * (low + high) for k, (low, high) in RANGES[effect].items()})


class _Valve:
    """The regulator and its transmitter: a first-order lag towards the clipped command."""

    def __init__(self, rate_hz: float, seed: int) -> None:
        self._alpha = 1.0 - math.exp(-1.0 / (rate_hz * _VALVE_TIME_CONSTANT_S))
        self._rng = np.random.default_rng(seed)
        self._pressure_pa = 0.0

    def step(self, command_pa: float) -> float:
        target_pa = min(max(command_pa, 0.0), _VALVE_MAX_PA)
        self._pressure_pa += self._alpha * (target_pa - self._pressure_pa)
        reading_pa = self._pressure_pa + _TRANSMITTER_NOISE_PA * float(self._rng.standard_normal())
        return round(reading_pa / _TRANSMITTER_RESOLUTION_PA) * _TRANSMITTER_RESOLUTION_PA


class ForeignRigPlant:
    """A foreign plant with a valve: the rig's plant contract.

    Args:
        plant_name: ``maxwell_slip``, ``boucwen`` or ``duhem``.
        effects: what the plant hides.
        rate_hz: its sample rate [Hz].
    """

    def __init__(
        self, plant_name: str, effects: Sequence[Effect] = (), rate_hz: float = RATE_HZ
    ) -> None:
        self.plant_name = plant_name
        self.rate_hz = rate_hz
        self._plant = PLANTS[plant_name](0)
        self._effects = tuple(effects)
        self._bend: PlantStepper
        self._valve: _Valve
        self.reset()

    def reset(self) -> None:
        """Back to rest: a fresh stepper (vented, straight) and valve, seeds from the start."""
        self._bend = self._plant.stepper(self.rate_hz, self._effects, seed=_BEND_SEED)
        self._valve = _Valve(self.rate_hz, _VALVE_SEED)

    def step(self, pressure_command_pa: float) -> tuple[float, float]:
        """One sample: the transmitter's reading [Pa] and the measured bend [rad]."""
        return self._valve.step(pressure_command_pa), self._bend.step(pressure_command_pa)


def maxwell_slip() -> ForeignRigPlant:
    """Maxwell-slip catheter, nothing hidden."""
    return ForeignRigPlant("maxwell_slip")


def maxwell_slip_lag() -> ForeignRigPlant:
    """Maxwell-slip catheter with a pneumatic lag."""
    return ForeignRigPlant("maxwell_slip", [_mid("pneumatic_lag")])


def maxwell_slip_delay() -> ForeignRigPlant:
    """Maxwell-slip catheter with a transport delay."""
    return ForeignRigPlant("maxwell_slip", [_mid("transport_delay")])


def maxwell_slip_tip() -> ForeignRigPlant:
    """Maxwell-slip catheter with a ringing tip."""
    return ForeignRigPlant("maxwell_slip", [_mid("tip_dynamics")])


def boucwen() -> ForeignRigPlant:
    """Bouc-Wen catheter, nothing hidden."""
    return ForeignRigPlant("boucwen")


def boucwen_lag() -> ForeignRigPlant:
    """Bouc-Wen catheter with a pneumatic lag."""
    return ForeignRigPlant("boucwen", [_mid("pneumatic_lag")])


def boucwen_delay() -> ForeignRigPlant:
    """Bouc-Wen catheter with a transport delay."""
    return ForeignRigPlant("boucwen", [_mid("transport_delay")])


def boucwen_tip() -> ForeignRigPlant:
    """Bouc-Wen catheter with a ringing tip."""
    return ForeignRigPlant("boucwen", [_mid("tip_dynamics")])


def duhem() -> ForeignRigPlant:
    """Duhem catheter, nothing hidden."""
    return ForeignRigPlant("duhem")


def duhem_lag() -> ForeignRigPlant:
    """Duhem catheter with a pneumatic lag."""
    return ForeignRigPlant("duhem", [_mid("pneumatic_lag")])


def duhem_delay() -> ForeignRigPlant:
    """Duhem catheter with a transport delay."""
    return ForeignRigPlant("duhem", [_mid("transport_delay")])


def duhem_tip() -> ForeignRigPlant:
    """Duhem catheter with a ringing tip."""
    return ForeignRigPlant("duhem", [_mid("tip_dynamics")])


FACTORIES: Final = (
    "maxwell_slip",
    "maxwell_slip_lag",
    "maxwell_slip_delay",
    "maxwell_slip_tip",
    "boucwen",
    "boucwen_lag",
    "boucwen_delay",
    "boucwen_tip",
    "duhem",
    "duhem_lag",
    "duhem_delay",
    "duhem_tip",
)
"""Every factory of this module, by name."""
