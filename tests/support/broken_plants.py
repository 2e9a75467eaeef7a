"""Plants of a rig that does not respond, for ``commission``'s stop (test support only).

Each is a plant in the contract of docs/simulated_rig.md ("Your own plant"): a factory with
no arguments returning an object with ``rate_hz``, ``reset()`` and ``step(pressure_command_pa)
-> (pressure_measured_pa, bend_rad)``. They are written against that contract alone, as a lab
would write its own.
"""

from __future__ import annotations

import math
import random

_RATE_HZ = 250.0
_VALVE_TIME_CONSTANT_S = 0.01


class _Valve:
    """A first-order valve with a little transmitter noise."""

    def __init__(self) -> None:
        self.rng = random.Random(7)
        self.pressure_pa = 0.0

    def step(self, command_pa: float) -> float:
        alpha = 1.0 / (_VALVE_TIME_CONSTANT_S * _RATE_HZ)
        self.pressure_pa += alpha * (command_pa - self.pressure_pa)
        return self.pressure_pa + self.rng.gauss(0.0, 300.0)


class FrozenLaser:
    """The valve works and the catheter bends, but the laser reports one value for ever."""

    rate_hz = _RATE_HZ

    def __init__(self) -> None:
        self.valve = _Valve()

    def reset(self) -> None:
        self.valve = _Valve()

    def step(self, pressure_command_pa: float) -> tuple[float, float]:
        return self.valve.step(pressure_command_pa), math.radians(2.0)


class DeadValve:
    """The valve never opens: the muscle stays vented, the transmitter reads ambient."""

    rate_hz = _RATE_HZ

    def __init__(self) -> None:
        self.rng = random.Random(3)

    def reset(self) -> None:
        self.rng = random.Random(3)

    def step(self, pressure_command_pa: float) -> tuple[float, float]:
        return self.rng.gauss(0.0, 300.0), self.rng.gauss(0.0, math.radians(0.05))


def frozen_laser() -> FrozenLaser:
    """Factory of the contract: ``broken_plants:frozen_laser``."""
    return FrozenLaser()


def dead_valve() -> DeadValve:
    """Factory of the contract: ``broken_plants:dead_valve``."""
    return DeadValve()
