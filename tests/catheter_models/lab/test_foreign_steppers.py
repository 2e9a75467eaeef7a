"""A foreign plant stepped one sample at a time is the same plant as one simulated whole.

Closed-loop benchmarks put a controller between the laser and the valve, so they run the
plant sample by sample; they are only worth anything if that plant is the one the lab and
the open-loop benchmarks see. Every effect is switched on, at once where a plant allows,
so that each piece of carried state (delay line, creep bank, tip, sensor filter, drift) is
crossed by the split.
"""

from __future__ import annotations

import numpy as np
import pytest
from foreign_plants import PLANTS
from foreign_plants.base import RANGES, Effect

RATE_HZ = 250.0


def _command(n: int) -> np.ndarray:
    """Ramps, holds and fast reversals over the whole range (with values outside it)."""
    rng = np.random.default_rng(7)
    t = np.arange(n) / RATE_HZ
    slow = 1.5e5 + 1.3e5 * np.sin(2 * np.pi * 0.4 * t)
    fast = 0.3e5 * np.sign(np.sin(2 * np.pi * 3.0 * t))
    cmd = slow + fast + 0.05e5 * rng.standard_normal(n)
    cmd[n // 3 : n // 3 + 50] = 3.5e5  # above the valve's range: clipped alike
    cmd[n // 2 : n // 2 + 50] = -0.2e5
    return cmd


def _effects(names: tuple[str, ...]) -> list[Effect]:
    rng = np.random.default_rng(3)
    return [Effect.draw(name, rng) for name in names]


# Every effect once; the delay with its neighbours so the line and the lags interact.
GROUPS = [
    (),
    ("transport_delay", "pneumatic_lag", "creep"),
    ("tip_dynamics", "drift", "sensor_lag"),
    ("backlash", "gain_drift", "slow_lag"),
]


@pytest.mark.parametrize("plant_name", ["maxwell_slip", "boucwen", "duhem"])
@pytest.mark.parametrize("names", GROUPS, ids=lambda g: "+".join(g) or "nothing")
def test_stepping_equals_simulating_the_whole_command(
    plant_name: str, names: tuple[str, ...]
) -> None:
    assert all(name in RANGES for name in names)
    plant = PLANTS[plant_name](1)
    effects = _effects(names)
    cmd = _command(1500)
    whole = plant.simulate(cmd, RATE_HZ, effects, seed=11)
    stepper = plant.stepper(RATE_HZ, effects, seed=11)
    stepped = np.array([stepper.step(float(u)) for u in cmd])
    # Same arithmetic in the same order: equal to the last bit but for the quantiser's
    # rounding of a value that lands on a half step (none is expected).
    np.testing.assert_array_equal(stepped, whole)
    # And the run moved the catheter: the equality is not one of two flat lines.
    assert np.ptp(whole) > np.radians(5.0)


@pytest.mark.parametrize("plant_name", ["maxwell_slip", "boucwen", "duhem"])
def test_a_stepper_starts_from_rest_each_time(plant_name: str) -> None:
    plant = PLANTS[plant_name](0)
    cmd = _command(300)
    first = [plant.stepper(RATE_HZ, seed=2).step(float(u)) for u in cmd[:1]]
    stepper = plant.stepper(RATE_HZ, seed=2)
    for u in cmd:
        stepper.step(float(u))
    again = [plant.stepper(RATE_HZ, seed=2).step(float(u)) for u in cmd[:1]]
    assert first == again
