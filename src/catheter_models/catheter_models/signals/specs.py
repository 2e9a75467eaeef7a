"""A generated signal and the preset specs that make one.

:class:`Signal` is a sampled signal in SI units; :class:`SignalSpec` and its subclasses hold a
preset's numbers in the thesis's display units (bar, degrees) and generate a :class:`Signal`
from the equations of :mod:`.generators`. Apart from the equations so that the classes, which
know units, metadata and validation of their fields, read in one place.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Final, Literal

import numpy as np

from catheter_models.contract import SENSOR_RATE_HZ
from catheter_models.errors import SignalError
from catheter_models.units import bar_to_pa, deg_to_rad, pa_to_bar, rad_to_deg

from .generators import (
    FloatArray,
    arbitrary_plateaus,
    chirp,
    descending_sine_nonzero_baseline,
    descending_sine_zero_baseline,
    time_grid_s,
)

SignalKind = Literal["pressure", "angle"]
ParamValue = float | int | str

DEFAULT_RATE_HZ: Final = SENSOR_RATE_HZ
"""Sampling rate of the thesis's rig (laser and pressure transmitter)."""

_UNIT_OF_KIND: Final[Mapping[str, str]] = MappingProxyType({"pressure": "bar", "angle": "deg"})


@dataclass(frozen=True, eq=False)
class Signal:
    """A generated signal on a uniform time grid, in SI units.

    Attributes:
        name: Preset name (or a caller's name for a custom spec).
        kind: ``"pressure"`` (gauge pressure [Pa]) or ``"angle"`` (bending angle [rad]).
        t_s: Sample times [s], float64, starting at 0; read-only.
        values_si: Gauge pressure [Pa] or angle [rad]; read-only.
        params: Flat parameters for bag metadata (``custom_data``); keys carry units.
    """

    name: str
    kind: SignalKind
    t_s: FloatArray
    values_si: FloatArray
    params: Mapping[str, ParamValue] = field(default_factory=dict)

    def __post_init__(self) -> None:
        t = np.array(self.t_s, dtype=np.float64)
        v = np.array(self.values_si, dtype=np.float64)
        if t.ndim != 1 or v.shape != t.shape:
            raise SignalError(
                f"signal {self.name!r}: t_s and values_si must be 1-D of equal length, "
                f"got shapes {t.shape} and {v.shape}"
            )
        if self.kind not in _UNIT_OF_KIND:
            raise SignalError(
                f"signal {self.name!r}: kind must be 'pressure' or 'angle', got {self.kind!r}"
            )
        t.flags.writeable = False
        v.flags.writeable = False
        # Frozen dataclass: assignment in __post_init__ has to go through object.
        object.__setattr__(self, "t_s", t)
        object.__setattr__(self, "values_si", v)
        object.__setattr__(self, "params", MappingProxyType(dict(self.params)))

    @property
    def unit(self) -> str:
        """Display unit: ``"bar"`` for pressure, ``"deg"`` for angle."""
        return _UNIT_OF_KIND[self.kind]

    @property
    def duration_s(self) -> float:
        """Time of the last sample [s]."""
        return float(self.t_s[-1])

    def values_display(self) -> FloatArray:
        """Values in the display unit (:attr:`unit`): gauge bar or degrees."""
        if self.kind == "pressure":
            return pa_to_bar(self.values_si)
        return rad_to_deg(self.values_si)

    def values_bar(self) -> FloatArray:
        """Gauge pressure [bar].

        Raises:
            SignalError: If this is an angle signal.
        """
        if self.kind != "pressure":
            raise SignalError(f"signal {self.name!r} is an angle; use values_deg(), not bar")
        return pa_to_bar(self.values_si)

    def values_deg(self) -> FloatArray:
        """Angle [deg].

        Raises:
            SignalError: If this is a pressure signal.
        """
        if self.kind != "angle":
            raise SignalError(f"signal {self.name!r} is a pressure; use values_bar(), not deg")
        return rad_to_deg(self.values_si)


@dataclass(frozen=True, kw_only=True)
class SignalSpec(ABC):
    """Common part of every preset: what it is, where it comes from, how it deviates.

    Subclasses give the shape; numbers are in the display unit of ``kind`` (:attr:`unit`).

    Attributes:
        name: Registry name.
        kind: ``"pressure"`` or ``"angle"``.
        duration_s: Length of the signal [s].
        source: Thesis equation and section the signal comes from.
        note: Any deviation from the printed numbers and why; empty if none.
    """

    name: str
    kind: SignalKind
    duration_s: float
    source: str
    note: str = ""

    def __post_init__(self) -> None:
        if self.kind not in _UNIT_OF_KIND:
            raise SignalError(f"{self.name}: kind must be 'pressure' or 'angle', got {self.kind!r}")
        if not (math.isfinite(self.duration_s) and self.duration_s > 0.0):
            raise SignalError(
                f"{self.name}: duration_s must be finite and > 0, got {self.duration_s!r}"
            )

    @property
    def unit(self) -> str:
        """Unit of this spec's numbers: ``"bar"`` for pressure, ``"deg"`` for angle."""
        return _UNIT_OF_KIND[self.kind]

    @abstractmethod
    def values_display(self, t_s: FloatArray) -> FloatArray:
        """The signal at ``t_s`` [s], in :attr:`unit`."""

    @abstractmethod
    def shape_params(self) -> dict[str, ParamValue]:
        """Shape parameters for metadata, keys suffixed with their units."""

    def params(self, rate_hz: float = DEFAULT_RATE_HZ) -> dict[str, ParamValue]:
        """Flat description for bag ``custom_data``: identity, source and shape parameters."""
        return {
            "signal": self.name,
            "kind": self.kind,
            "source": self.source,
            "duration_s": self.duration_s,
            "rate_hz": rate_hz,
            **self.shape_params(),
        }

    def generate(self, rate_hz: float = DEFAULT_RATE_HZ) -> Signal:
        """Sample the signal at ``rate_hz`` [Hz] from t = 0 and convert it to SI.

        Returns:
            A :class:`Signal` with gauge pressure [Pa] or angle [rad].

        Raises:
            SignalError: If the rate is not finite and positive, or the result is not finite.
        """
        t_s = time_grid_s(self.duration_s, rate_hz)
        display = self.values_display(t_s)
        bad = np.flatnonzero(~np.isfinite(display))
        if bad.size:
            i = int(bad[0])
            raise SignalError(
                f"{self.name}: value at sample {i} (t = {t_s[i]:.3f} s) is {display[i]}; "
                "check the spec's parameters"
            )
        values_si = bar_to_pa(display) if self.kind == "pressure" else deg_to_rad(display)
        return Signal(
            name=self.name,
            kind=self.kind,
            t_s=t_s,
            values_si=values_si,
            params=self.params(rate_hz),
        )


@dataclass(frozen=True, kw_only=True)
class DescendingSineSpec(SignalSpec):
    """Eq. 4.1 (``baseline="zero"``) or eq. 4.2 (``baseline="nonzero"``).

    Attributes:
        amplitude: A, in :attr:`unit`.
        decay_per_s: tau [1/s].
        freq_hz: f [Hz].
        baseline: ``"zero"`` (eq. 4.1) or ``"nonzero"`` (eq. 4.2).
    """

    amplitude: float
    decay_per_s: float
    freq_hz: float
    baseline: Literal["zero", "nonzero"]

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_finite(self.name, amplitude=self.amplitude, decay_per_s=self.decay_per_s)
        if not (math.isfinite(self.freq_hz) and self.freq_hz > 0.0):
            raise SignalError(f"{self.name}: freq_hz must be finite and > 0, got {self.freq_hz!r}")
        if self.baseline not in ("zero", "nonzero"):
            raise SignalError(
                f"{self.name}: baseline must be 'zero' (eq. 4.1) or 'nonzero' (eq. 4.2), "
                f"got {self.baseline!r}"
            )

    def values_display(self, t_s: FloatArray) -> FloatArray:
        """Eq. 4.1 or 4.2 at ``t_s`` [s], in :attr:`unit`."""
        equation = (
            descending_sine_zero_baseline
            if self.baseline == "zero"
            else descending_sine_nonzero_baseline
        )
        return equation(t_s, self.amplitude, self.decay_per_s, self.freq_hz)

    def shape_params(self) -> dict[str, ParamValue]:
        """A, tau, f and the baseline form."""
        return {
            "baseline": self.baseline,
            f"amplitude_{self.unit}": self.amplitude,
            "decay_per_s": self.decay_per_s,
            "freq_hz": self.freq_hz,
        }


@dataclass(frozen=True, kw_only=True)
class ChirpSpec(SignalSpec):
    """Eqs. 5.16, 5.17, 9.22-9.24: ``A e^{-tau t} (sin(2 pi (f + c t) t - pi/2) + 1) + B``.

    Attributes:
        amplitude: A, in :attr:`unit`.
        decay_per_s: tau [1/s]; negative grows the envelope.
        freq_hz: f [Hz].
        chirp_hz_per_s: c [Hz/s]; instantaneous frequency is ``f + 2 c t``.
        offset: B, in :attr:`unit`.
    """

    amplitude: float
    decay_per_s: float
    freq_hz: float
    chirp_hz_per_s: float = 0.0
    offset: float = 0.0

    def __post_init__(self) -> None:
        super().__post_init__()
        _check_finite(
            self.name,
            amplitude=self.amplitude,
            decay_per_s=self.decay_per_s,
            chirp_hz_per_s=self.chirp_hz_per_s,
            offset=self.offset,
        )
        end_freq_hz = self.freq_hz + 2.0 * self.chirp_hz_per_s * self.duration_s
        if not (math.isfinite(self.freq_hz) and self.freq_hz > 0.0 and end_freq_hz > 0.0):
            # A frequency through zero folds the sine back on itself: no longer a chirp.
            raise SignalError(
                f"{self.name}: the instantaneous frequency f + 2ct must stay > 0 over the "
                f"signal; f = {self.freq_hz} Hz and c = {self.chirp_hz_per_s} Hz/s give "
                f"{end_freq_hz:.3g} Hz at t = {self.duration_s} s. Use c > -f/(2T)"
            )

    def values_display(self, t_s: FloatArray) -> FloatArray:
        """The chirp at ``t_s`` [s], in :attr:`unit`."""
        return chirp(
            t_s,
            self.amplitude,
            self.decay_per_s,
            self.freq_hz,
            chirp_hz_per_s=self.chirp_hz_per_s,
            offset=self.offset,
        )

    def shape_params(self) -> dict[str, ParamValue]:
        """A, tau, f, c and B."""
        return {
            f"amplitude_{self.unit}": self.amplitude,
            "decay_per_s": self.decay_per_s,
            "freq_hz": self.freq_hz,
            "chirp_hz_per_s": self.chirp_hz_per_s,
            f"offset_{self.unit}": self.offset,
        }


@dataclass(frozen=True, kw_only=True)
class ArbitrarySpec(SignalSpec):
    """A seeded random plateau signal (:func:`arbitrary_plateaus`); deterministic per seed.

    Attributes:
        seed: Seed of the numpy Generator.
        level_min: Lowest level, in :attr:`unit`.
        level_max: Highest level, in :attr:`unit`.
        plateau_s: Range of plateau lengths [s].
        ramp_s: Range of ramp lengths [s].
        max_ramp_rate: Largest ramp rate, in :attr:`unit` per second.
        variation_amplitude: Range of small-variation amplitudes, in :attr:`unit`, or None.
        variation_freq_hz: Range of small-variation frequencies [Hz].
        variation_probability: Chance that a plateau carries small variations.
    """

    seed: int
    level_min: float
    level_max: float
    plateau_s: tuple[float, float] = (1.0, 3.0)
    ramp_s: tuple[float, float] = (0.5, 2.0)
    max_ramp_rate: float = math.inf
    variation_amplitude: tuple[float, float] | None = None
    variation_freq_hz: tuple[float, float] = (1.0, 2.0)
    variation_probability: float = 0.5

    def values_display(self, t_s: FloatArray) -> FloatArray:
        """The plateau signal at ``t_s`` [s], in :attr:`unit`; same seed, same signal."""
        return arbitrary_plateaus(
            t_s,
            np.random.default_rng(self.seed),
            self.level_min,
            self.level_max,
            plateau_s=self.plateau_s,
            ramp_s=self.ramp_s,
            max_ramp_rate_per_s=self.max_ramp_rate,
            variation_amplitude=self.variation_amplitude,
            variation_freq_hz=self.variation_freq_hz,
            variation_probability=self.variation_probability,
        )

    def shape_params(self) -> dict[str, ParamValue]:
        """Seed, level range, timing ranges and the small-variation settings."""
        u = self.unit
        out: dict[str, ParamValue] = {
            "seed": self.seed,
            f"level_min_{u}": self.level_min,
            f"level_max_{u}": self.level_max,
            "plateau_min_s": self.plateau_s[0],
            "plateau_max_s": self.plateau_s[1],
            "ramp_min_s": self.ramp_s[0],
            "ramp_max_s": self.ramp_s[1],
            f"max_ramp_rate_{u}_per_s": self.max_ramp_rate,
        }
        if self.variation_amplitude is not None:
            out |= {
                f"variation_amplitude_min_{u}": self.variation_amplitude[0],
                f"variation_amplitude_max_{u}": self.variation_amplitude[1],
                "variation_freq_min_hz": self.variation_freq_hz[0],
                "variation_freq_max_hz": self.variation_freq_hz[1],
                "variation_probability": self.variation_probability,
            }
        return out


def _check_finite(name: str, **values: float) -> None:
    for key, value in values.items():
        if not math.isfinite(value):
            raise SignalError(f"{name}: {key} must be finite, got {value!r}")
