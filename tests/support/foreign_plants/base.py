"""The contract every foreign plant meets: pressure command in, measured bend out.

A foreign plant is a simulated PAM catheter written apart from ``catheter_models.plant``
and from every other foreign plant: its own hysteresis law, its own opening knee and
saturation, its own sensor, and its own physics for each effect it can hide. The lab never
imports this package (a test checks); only tests and benchmarks do, as the ground truth the
lab is scored against. Each plant says, in its module docstring, which physics it uses.

Units at this boundary are SI: gauge pressure [Pa] in, bend [rad] out, time [s].
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field
from typing import ClassVar, Final

import numpy as np
import numpy.typing as npt

FloatArray = npt.NDArray[np.float64]

CATALOGUE: Final = ("pneumatic_lag", "transport_delay", "creep", "tip_dynamics", "drift")
"""Effects the lab has a block for (hidden here with the plant's own physics)."""

OUTSIDE: Final = ("sensor_lag", "backlash", "gain_drift", "slow_lag")
"""Effects the lab has no block for: the honest answer is 'unexplained'."""

RANGES: Final[Mapping[str, Mapping[str, tuple[float, float]]]] = {
    # Strengths seen on real rigs (issue 13); a case draws each uniformly (log-uniform for
    # time constants spanning a decade or more).
    "pneumatic_lag": {"time_constant_s": (0.02, 0.12)},
    "transport_delay": {"delay_s": (0.02, 0.06)},
    "creep": {"fraction": (0.10, 0.25), "time_constant_s": (0.5, 10.0)},
    "tip_dynamics": {"natural_frequency_hz": (3.0, 6.0), "damping_ratio": (0.05, 0.15)},
    "drift": {"rate_deg_per_min": (0.5, 2.0)},
    # Outside the catalogue.
    "sensor_lag": {"time_constant_s": (0.03, 0.12)},
    "backlash": {"gap_deg": (0.5, 2.0)},
    "gain_drift": {"percent_per_min": (3.0, 8.0)},
    "slow_lag": {"fraction": (0.15, 0.30), "time_constant_s": (0.5, 3.0)},
}
"""Each effect's parameters and the range a case draws them from.

Meaning of each parameter, which every plant must honour in its own physics:

* ``pneumatic_lag.time_constant_s``: small-signal time constant of the muscle pressure
  behind the valve, at mid-range pressure.
* ``transport_delay.delay_s``: dead time between the valve command and the muscle.
* ``creep.fraction``, ``creep.time_constant_s``: share of a step's final bend that arrives
  by slow relaxation, and the (mean) time it takes.
* ``tip_dynamics.natural_frequency_hz``, ``tip_dynamics.damping_ratio``: the tip's ringing
  after a fast step, at mid-range bend.
* ``drift.rate_deg_per_min``: initial rate of an offset drift of the measured bend (sign
  drawn by the case), from each recording's start.
* ``sensor_lag.time_constant_s``: the angle sensor's own filter, on the measured bend.
* ``backlash.gap_deg``: slack between muscle and wire: the bend stays while the pull
  reverses through the gap (in bend-equivalent degrees).
* ``gain_drift.percent_per_min``: the bend's gain changes by this share per minute (sign
  drawn), from each recording's start (e.g. the wire warming).
* ``slow_lag.fraction``, ``slow_lag.time_constant_s``: a second, slow share of the muscle
  pressure that fills through a leak or a second chamber.
"""

_LOG_UNIFORM: Final = {("creep", "time_constant_s"), ("slow_lag", "time_constant_s")}
_SIGNED: Final = {("drift", "rate_deg_per_min"), ("gain_drift", "percent_per_min")}


@dataclass(frozen=True)
class Effect:
    """One hidden effect and its strength (parameter names and units as in :data:`RANGES`)."""

    name: str
    params: Mapping[str, float] = field(default_factory=dict)

    def __post_init__(self) -> None:
        if self.name not in RANGES:
            raise ValueError(f"unknown effect {self.name!r}; known: {', '.join(RANGES)}")
        missing = set(RANGES[self.name]) - set(self.params)
        unknown = set(self.params) - set(RANGES[self.name])
        if missing or unknown:
            raise ValueError(
                f"{self.name}: parameters must be {sorted(RANGES[self.name])}, "
                f"got {sorted(self.params)}"
            )

    @property
    def in_catalogue(self) -> bool:
        """Whether the lab has a block for this effect."""
        return self.name in CATALOGUE

    @classmethod
    def draw(cls, name: str, rng: np.random.Generator) -> Effect:
        """A strength drawn from the real-rig range (sign drawn for drifts)."""
        params: dict[str, float] = {}
        for key, (low, high) in RANGES[name].items():
            if (name, key) in _LOG_UNIFORM:
                value = math.exp(rng.uniform(math.log(low), math.log(high)))
            else:
                value = float(rng.uniform(low, high))
            if (name, key) in _SIGNED and rng.random() < 0.5:
                value = -value
            params[key] = float(value)
        return cls(name, params)

    def label(self) -> str:
        """Short text for tables, e.g. ``creep(fraction=0.18, time_constant_s=2.3)``."""
        inner = ", ".join(f"{k}={v:.3g}" for k, v in self.params.items())
        return f"{self.name}({inner})"


class PlantStepper(ABC):
    """A foreign plant run one sample at a time from rest, so a controller can close its loop
    through it. Stepping a command through it gives exactly what ``simulate`` gives for the
    whole command with the same effects and seed (a test checks)."""

    @abstractmethod
    def step(self, pressure_command_pa: float) -> float:
        """Hold ``pressure_command_pa`` [Pa] for one sample; the measured bend [rad] at its end."""


class ForeignPlant(ABC):
    """A simulated catheter with its own physics. Subclasses set the class attributes.

    ``ForeignPlant(variant)``: ``variant`` draws the plant's own nominal parameters (gain,
    opening pressure, friction, saturation...) within plausible ranges, so that each variant
    is another catheter of the same make; variant 0 is the plant's nominal one.
    """

    def __init__(self, variant: int = 0) -> None:
        self.variant = int(variant)

    name: ClassVar[str]
    """Registry name, e.g. ``"maxwell_slip"``."""
    hysteresis_law: ClassVar[str]
    """One line: the law of its loops (e.g. 'Maxwell-slip elasto-plastic elements')."""
    supports: ClassVar[tuple[str, ...]] = (*CATALOGUE, *OUTSIDE)
    """Effects it can hide (all of :data:`RANGES` unless a plant says otherwise)."""

    def effects_by_name(self, effects: Sequence[Effect]) -> dict[str, Effect]:
        """``effects`` by name; an effect given twice, or one this plant cannot hide, is refused."""
        by_name: dict[str, Effect] = {}
        for effect in effects:
            if effect.name in by_name:
                raise ValueError(f"effect {effect.name!r} given twice")
            if effect.name not in self.supports:
                raise ValueError(f"{self.name} cannot hide {effect.name!r}")
            by_name[effect.name] = effect
        return by_name

    @property
    @abstractmethod
    def noise_std_rad(self) -> float:
        """Standard deviation of the angle sensor's white noise [rad] (the truth the lab's
        noise-floor estimate is checked against)."""

    @abstractmethod
    def simulate(
        self,
        pressure_command_pa: FloatArray,
        rate_hz: float,
        effects: Sequence[Effect] = (),
        seed: int = 0,
    ) -> FloatArray:
        """The measured bend [rad] at each command sample, starting from rest (vented,
        straight). ``seed`` fixes the sensor noise; the same call gives the same output."""

    @abstractmethod
    def stepper(
        self, rate_hz: float, effects: Sequence[Effect] = (), seed: int = 0
    ) -> PlantStepper:
        """The plant of :meth:`simulate`, from rest, one command sample at a time."""
