"""Excitation and test signals of the thesis, as named presets.

The thesis drives the catheter with pressure signals (training, eqs. 4.1/4.2; modelling tests,
sec. 5.4.2) and asks the controller to follow angle trajectories (control tests, sec. 9.3).
This module holds the equations (unit-agnostic: the output has the unit of the amplitude), the
designed "arbitrary" signals the thesis shows but never defines, and a registry of presets
that generate SI arrays ready for a simulator, a node or a bag.

A preset keeps its numbers in the units the thesis prints them in (bar for pressure, degrees
for angle; ``spec.unit`` says which) so a reader can compare it with the thesis line by line.
:meth:`SignalSpec.generate` converts to SI (gauge pascal, radian) through :mod:`units`.

Where a printed number cannot produce what the thesis's figures and tables show, the preset
deviates and its ``note`` says how and why.
"""

from __future__ import annotations

import math
from abc import ABC, abstractmethod
from collections.abc import Mapping
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Final, Literal

import numpy as np
import numpy.typing as npt

from .errors import SignalError
from .units import bar_to_pa, deg_to_rad, pa_to_bar, rad_to_deg

FloatArray = npt.NDArray[np.float64]
SignalKind = Literal["pressure", "angle"]
ParamValue = float | int | str

DEFAULT_RATE_HZ: Final = 250.0
"""Sampling rate of the thesis's rig (laser and pressure transmitter)."""

THESIS_MAX_PRESSURE_PA: Final = bar_to_pa(3.0)
"""Highest gauge pressure the thesis commands (A = 1.5 bar in eq. 4.1 peaks at 3 bar)."""
THESIS_MAX_ANGLE_RAD: Final = deg_to_rad(35.0)
"""Upper bound for desired angles: the rig bends about 30 deg at 3 bar; 35 deg leaves margin."""

_UNIT_OF_KIND: Final[Mapping[str, str]] = MappingProxyType({"pressure": "bar", "angle": "deg"})


# --------------------------------------------------------------------------------------------
# Equations (unit-agnostic)
# --------------------------------------------------------------------------------------------


def descending_sine_zero_baseline(
    t_s: FloatArray, amplitude: float, decay_per_s: float, freq_hz: float
) -> FloatArray:
    """Eq. 4.1: ``A e^{-tau t} (sin(2 pi f t - pi/2) + 1)``; starts and returns to zero.

    Args:
        t_s: Sample times [s].
        amplitude: A, in the unit the output should have (bar in the thesis).
        decay_per_s: tau [1/s]; negative values grow the envelope.
        freq_hz: f [Hz].

    Returns:
        The signal, in the unit of ``amplitude``.
    """
    return chirp(t_s, amplitude, decay_per_s, freq_hz, chirp_hz_per_s=0.0, offset=0.0)


def descending_sine_nonzero_baseline(
    t_s: FloatArray, amplitude: float, decay_per_s: float, freq_hz: float
) -> FloatArray:
    """Eq. 4.2: ``A e^{-tau t} sin(2 pi f t - pi/2) + A``; starts at zero, settles at A.

    Args:
        t_s: Sample times [s].
        amplitude: A, in the unit the output should have (bar in the thesis).
        decay_per_s: tau [1/s].
        freq_hz: f [Hz].

    Returns:
        The signal, in the unit of ``amplitude``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    envelope = amplitude * np.exp(-decay_per_s * t)
    out: FloatArray = envelope * np.sin(2.0 * math.pi * freq_hz * t - math.pi / 2.0) + amplitude
    return out


def chirp(
    t_s: FloatArray,
    amplitude: float,
    decay_per_s: float,
    freq_hz: float,
    *,
    chirp_hz_per_s: float,
    offset: float = 0.0,
) -> FloatArray:
    """Eqs. 5.16, 5.17, 9.22-9.24: ``A e^{-tau t} (sin(2 pi (f + c t) t - pi/2) + 1) + B``.

    The phase is kept exactly as printed, ``2 pi (f + c t) t``, so the instantaneous
    frequency is ``f + 2 c t`` (see :func:`instantaneous_frequency_hz`), not ``f + c t``.

    Args:
        t_s: Sample times [s].
        amplitude: A, in the unit the output should have (bar or deg in the thesis).
        decay_per_s: tau [1/s]; negative values grow the envelope ("ascending").
        freq_hz: f, the instantaneous frequency at t = 0 [Hz].
        chirp_hz_per_s: c [Hz/s].
        offset: B, the baseline, in the unit of ``amplitude``.

    Returns:
        The signal, in the unit of ``amplitude``.
    """
    t = np.asarray(t_s, dtype=np.float64)
    phase_rad = 2.0 * math.pi * (freq_hz + chirp_hz_per_s * t) * t - math.pi / 2.0
    out: FloatArray = amplitude * np.exp(-decay_per_s * t) * (np.sin(phase_rad) + 1.0) + offset
    return out


def instantaneous_frequency_hz(
    t_s: FloatArray, freq_hz: float, chirp_hz_per_s: float
) -> FloatArray:
    """Instantaneous frequency ``f + 2 c t`` [Hz] of :func:`chirp` (derivative of its phase)."""
    out: FloatArray = freq_hz + 2.0 * chirp_hz_per_s * np.asarray(t_s, dtype=np.float64)
    return out


def time_grid_s(duration_s: float, rate_hz: float) -> FloatArray:
    """Sample times ``k / rate_hz`` [s] for ``round(duration_s * rate_hz)`` samples from 0.

    Raises:
        SignalError: If the duration or rate is not finite and positive.
    """
    if not (math.isfinite(rate_hz) and rate_hz > 0.0):
        raise SignalError(f"rate_hz must be finite and > 0 (e.g. 250.0), got {rate_hz!r}")
    if not (math.isfinite(duration_s) and duration_s > 0.0):
        raise SignalError(f"duration_s must be finite and > 0, got {duration_s!r}")
    n_samples = round(duration_s * rate_hz)
    if n_samples < 2:
        raise SignalError(
            f"duration_s={duration_s} at rate_hz={rate_hz} gives {n_samples} sample(s); "
            "a signal needs at least 2"
        )
    out: FloatArray = np.arange(n_samples, dtype=np.float64) / rate_hz
    return out


def _raised_cosine_step(u: FloatArray) -> FloatArray:
    """0 for u <= 0, 1 for u >= 1, ``(1 - cos(pi u)) / 2`` between: a step with no rate jump."""
    out: FloatArray = 0.5 * (1.0 - np.cos(math.pi * np.clip(u, 0.0, 1.0)))
    return out


def arbitrary_plateaus(
    t_s: FloatArray,
    rng: np.random.Generator,
    level_min: float,
    level_max: float,
    *,
    plateau_s: tuple[float, float] = (1.0, 3.0),
    ramp_s: tuple[float, float] = (0.5, 2.0),
    max_ramp_rate_per_s: float = math.inf,
    min_step_fraction: float = 0.15,
    variation_amplitude: tuple[float, float] | None = None,
    variation_freq_hz: tuple[float, float] = (1.0, 2.0),
    variation_probability: float = 0.5,
) -> FloatArray:
    """Random levels joined by raised-cosine ramps, with optional small fast variations.

    The thesis shows such signals (figs. 5.9, 9.10) but gives no equation; this is a design.
    The signal starts at ``level_min`` (catheter straight, valve vented), holds there for a
    first plateau, then alternates ramp and plateau between random levels, and ends with a
    ramp back to ``level_min`` and a hold, so every run starts and ends at rest.

    Args:
        t_s: Sample times [s], increasing from 0.
        rng: Random generator; the same seed gives the same signal.
        level_min: Lowest level, in the output's unit.
        level_max: Highest level, in the output's unit.
        plateau_s: Range of plateau lengths [s].
        ramp_s: Range of ramp lengths [s]; a ramp is lengthened if needed so that its peak
            rate stays within ``max_ramp_rate_per_s``.
        max_ramp_rate_per_s: Largest ramp rate, in the output's unit per second.
        min_step_fraction: Smallest change between consecutive levels, as a fraction of the
            range, so that every ramp is visible.
        variation_amplitude: Range of the amplitude of the small variations, in the output's
            unit; ``None`` for none (a plain plateau signal).
        variation_freq_hz: Range of the frequency of the small variations [Hz].
        variation_probability: Chance that a plateau carries small variations.

    Returns:
        The signal, in the unit of ``level_min``/``level_max``.

    Raises:
        SignalError: If a range is empty or inverted, or the time grid is too short.
    """
    t = np.asarray(t_s, dtype=np.float64)
    duration_s = float(t[-1]) if t.size else 0.0
    _check_range("level", (level_min, level_max), allow_equal=False)
    _check_range("plateau_s", plateau_s, positive=True)
    _check_range("ramp_s", ramp_s, positive=True)
    if not max_ramp_rate_per_s > 0.0:
        raise SignalError(f"max_ramp_rate_per_s must be > 0, got {max_ramp_rate_per_s!r}")
    if not 0.0 <= min_step_fraction < 0.5:
        raise SignalError(f"min_step_fraction must be in [0, 0.5), got {min_step_fraction!r}")
    span = level_max - level_min
    var_max = 0.0
    if variation_amplitude is not None:
        _check_range("variation_amplitude", variation_amplitude, positive=True)
        _check_range("variation_freq_hz", variation_freq_hz, positive=True)
        var_max = variation_amplitude[1]
        if 2.0 * var_max >= span:
            raise SignalError(
                f"variation_amplitude up to {var_max} does not fit in the level range "
                f"[{level_min}, {level_max}]; it must be below half the range"
            )

    def ramp_length_s(delta: float) -> float:
        # The raised cosine peaks at pi/2 times its mean rate.
        drawn = float(rng.uniform(*ramp_s))
        return max(drawn, 0.5 * math.pi * abs(delta) / max_ramp_rate_per_s)

    worst_final_ramp_s = max(ramp_s[1], 0.5 * math.pi * span / max_ramp_rate_per_s)
    reserve_s = worst_final_ramp_s + plateau_s[0]
    if duration_s < plateau_s[0] + reserve_s:
        raise SignalError(
            f"a {duration_s:.3g} s grid is too short for a plateau signal; it needs at least "
            f"{plateau_s[0] + reserve_s:.3g} s"
        )

    values = np.full_like(t, level_min)
    level = level_min
    cursor_s = float(rng.uniform(*plateau_s))
    while True:
        wants_variation = variation_amplitude is not None and (
            rng.uniform() < variation_probability
        )
        margin = var_max if wants_variation else 0.0
        low, high = level_min + margin, level_max - margin
        target = _draw_level(rng, level, low, high, min_step_fraction * span)
        ramp = ramp_length_s(target - level)
        hold = float(rng.uniform(*plateau_s))
        if cursor_s + ramp + hold + reserve_s > duration_s:
            break
        values += (target - level) * _raised_cosine_step((t - cursor_s) / ramp)
        if wants_variation and variation_amplitude is not None:
            values += _windowed_variation(
                t,
                cursor_s + ramp,
                hold,
                float(rng.uniform(*variation_amplitude)),
                float(rng.uniform(*variation_freq_hz)),
            )
        cursor_s += ramp + hold
        level = target

    final_ramp = ramp_length_s(level_min - level)
    values += (level_min - level) * _raised_cosine_step((t - cursor_s) / final_ramp)
    # Rounding may leave the final hold a few ulps off level_min; pin it for exact ranges.
    out: FloatArray = np.clip(values, level_min, level_max)
    return out


def _draw_level(
    rng: np.random.Generator, current: float, low: float, high: float, min_step: float
) -> float:
    """A uniform level in [low, high] at least ``min_step`` away from ``current``."""
    # Rejection sampling ends fast: at most a third of [low, high] is excluded.
    for _ in range(1000):
        candidate = float(rng.uniform(low, high))
        if abs(candidate - current) >= min_step:
            return candidate
    raise SignalError(
        f"cannot draw a level in [{low}, {high}] at least {min_step} away from {current}; "
        "widen the level range or lower min_step_fraction"
    )


def _windowed_variation(
    t_s: FloatArray, start_s: float, length_s: float, amplitude: float, freq_hz: float
) -> FloatArray:
    """A sine of whole periods inside a plateau, faded in and out so its rate is continuous."""
    n_periods = max(1, math.floor(length_s * freq_hz))
    span_s = n_periods / freq_hz
    # Centred, so the variation never spills into the neighbouring ramps.
    begin_s = start_s + 0.5 * max(0.0, length_s - span_s)
    local_s = t_s - begin_s
    inside = (local_s >= 0.0) & (local_s <= span_s)
    fade_s = 0.5 / freq_hz
    envelope = _raised_cosine_step(local_s / fade_s) * _raised_cosine_step(
        (span_s - local_s) / fade_s
    )
    out: FloatArray = np.where(
        inside, amplitude * envelope * np.sin(2.0 * math.pi * freq_hz * local_s), 0.0
    )
    return out


def _check_range(
    name: str, bounds: tuple[float, float], *, positive: bool = False, allow_equal: bool = True
) -> None:
    lo, hi = bounds
    if not (math.isfinite(lo) and math.isfinite(hi)):
        raise SignalError(f"{name} range must be finite, got ({lo!r}, {hi!r})")
    if hi < lo or (not allow_equal and hi == lo):
        raise SignalError(f"{name} range must be (low, high) with low < high, got ({lo}, {hi})")
    if positive and lo <= 0.0:
        raise SignalError(f"{name} range must be > 0, got ({lo}, {hi})")


# --------------------------------------------------------------------------------------------
# Generated signals
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Specs (presets)
# --------------------------------------------------------------------------------------------


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


# --------------------------------------------------------------------------------------------
# Presets
# --------------------------------------------------------------------------------------------

TRAINING_AMPLITUDE_BAR: Final = 1.5
TRAINING_DECAY_PER_S: Final = 0.15
TRAINING_FREQS_HZ: Final = (0.2, 0.4, 0.6, 0.8)
TRAINING_DURATION_S: Final = 13.4
CLSTM_DECAYS_PER_S: Final = (0.02, 0.05, 0.1, 0.15, 0.2)
CLSTM_DURATION_S: Final = 26.0
_BASELINE_FORMS: Final[tuple[tuple[Literal["zero", "nonzero"], str], ...]] = (
    ("zero", "4.1"),
    ("nonzero", "4.2"),
)


def _training_specs() -> tuple[DescendingSineSpec, ...]:
    specs = []
    for baseline, eq in _BASELINE_FORMS:
        for f_hz in TRAINING_FREQS_HZ:
            specs.append(
                DescendingSineSpec(
                    name=f"train_{baseline}_f{f_hz:g}",
                    kind="pressure",
                    amplitude=TRAINING_AMPLITUDE_BAR,
                    decay_per_s=TRAINING_DECAY_PER_S,
                    freq_hz=f_hz,
                    baseline=baseline,
                    duration_s=TRAINING_DURATION_S,
                    source=f"eq. {eq}, sec. 4.1.1 / 5.3.2 (DRDPI training set)",
                    note=(
                        "The thesis gives only the total, 26798 samples over 8 signals at "
                        "250 Hz; 13.4 s per signal is that total divided evenly."
                    ),
                )
            )
    return tuple(specs)


def _clstm_specs() -> tuple[DescendingSineSpec, ...]:
    specs = []
    for baseline, eq in _BASELINE_FORMS:
        for f_hz in TRAINING_FREQS_HZ:
            for tau in CLSTM_DECAYS_PER_S:
                specs.append(
                    DescendingSineSpec(
                        name=f"clstm_{baseline}_f{f_hz:g}_tau{tau:g}",
                        kind="pressure",
                        amplitude=TRAINING_AMPLITUDE_BAR,
                        decay_per_s=tau,
                        freq_hz=f_hz,
                        baseline=baseline,
                        duration_s=CLSTM_DURATION_S,
                        source=f"eq. {eq}, sec. 10.3.1 (c-LSTM training set)",
                        note=(
                            "The thesis gives only the total, 260269 samples over 40 groups "
                            "at 250 Hz; 26 s per group is that total divided evenly. A = 1.5 "
                            "bar is assumed as in sec. 4.1.1 (not restated in sec. 10.3.1)."
                        ),
                    )
                )
    return tuple(specs)


_MODEL_TEST_SPECS: Final[tuple[SignalSpec, ...]] = (
    DescendingSineSpec(
        name="model_test_descending_sine",
        kind="pressure",
        amplitude=1.5,
        decay_per_s=0.12,
        freq_hz=0.7,
        baseline="zero",
        duration_s=20.0,
        source="eq. 4.1, sec. 5.4.2 test 1 (fig. 5.6)",
        note="Duration not printed; 20 s covers the waves of fig. 5.6.",
    ),
    ChirpSpec(
        name="model_test_down_chirp",
        kind="pressure",
        amplitude=0.9,
        offset=1.2,
        freq_hz=0.7,
        decay_per_s=0.1,
        chirp_hz_per_s=-0.7 / (4.0 * 20.0),
        duration_s=20.0,
        source="eq. 5.16, sec. 5.4.2 test 2 (fig. 5.7)",
        note=(
            "Printed c = -0.1 makes the instantaneous frequency f + 2ct reach zero at 3.5 s, "
            "which cannot give the several waves of fig. 5.7. Used c = -f/(4T) = -0.00875 Hz/s "
            "with T = 20 s, so the frequency falls from 0.7 Hz to 0.35 Hz."
        ),
    ),
    ChirpSpec(
        name="model_test_up_chirp",
        kind="pressure",
        amplitude=0.6,
        freq_hz=0.3,
        decay_per_s=-0.05,
        chirp_hz_per_s=0.015,
        duration_s=18.0,
        source="eq. 5.17, sec. 5.4.2 test 3 (fig. 5.8)",
        note=(
            "Printed tau = 0.05, c = 0.15 pass 1 Hz (the studied band) at 2.3 s and peak at "
            "1.2 bar, which cannot give the ~21 deg range implied by table 8.3 (RMSE/NRMSE). "
            "Used tau = -0.05 (a growing, 'ascending' envelope), c = 0.015 Hz/s and T = 18 s: "
            "the frequency rises from 0.3 to 0.84 Hz and the peak stays below 3 bar."
        ),
    ),
    ArbitrarySpec(
        name="model_test_arbitrary_plateaus",
        kind="pressure",
        seed=5409,
        level_min=0.0,
        level_max=3.0,
        max_ramp_rate=6.0,
        duration_s=40.0,
        source="sec. 5.4.2 test 4 (fig. 5.9); no equation in the thesis",
        note=(
            "Designed: random levels in 0-3 bar, plateaus of 1-3 s, raised-cosine ramps of "
            "0.5-2 s capped at 6 bar/s (about the peak rate of test 1), fixed seed."
        ),
    ),
)

_TRAJECTORY_SPECS: Final[tuple[SignalSpec, ...]] = (
    ChirpSpec(
        name="traj_descending_sine",
        kind="angle",
        amplitude=10.0,
        freq_hz=0.3,
        decay_per_s=0.05,
        chirp_hz_per_s=0.0,
        duration_s=20.0,
        source="eq. 9.22, sec. 9.3.1 / 10.3.2 trajectory 1 (figs. 9.4, 10.5)",
        note=(
            "A is not printed; A = 10 deg fits the ~18.5 deg range that table 11.1's "
            "RMSE/NRMSE implies. Duration not printed; 20 s."
        ),
    ),
    ChirpSpec(
        name="traj_down_chirp",
        kind="angle",
        amplitude=10.0,
        offset=8.0,
        freq_hz=0.5,
        decay_per_s=0.05,
        chirp_hz_per_s=-0.5 / (4.0 * 20.0),
        duration_s=20.0,
        source="eq. 9.23, sec. 9.3.1 / 10.3.2 trajectory 2 (figs. 9.6, 10.7)",
        note=(
            "c is not printed; used c = -f/(4T) = -0.00625 Hz/s with T = 20 s, so the "
            "frequency falls from 0.5 Hz to 0.25 Hz, as in model test 2."
        ),
    ),
    ChirpSpec(
        name="traj_up_chirp",
        kind="angle",
        amplitude=6.0,
        freq_hz=0.3,
        decay_per_s=-0.02,
        chirp_hz_per_s=0.005,
        duration_s=20.0,
        source="eq. 9.24, sec. 9.3.1 / 10.3.2 trajectory 3 (figs. 9.8, 10.9)",
        note="Duration not printed; 20 s.",
    ),
    ArbitrarySpec(
        name="traj_arbitrary_small_variations",
        kind="angle",
        seed=9310,
        level_min=0.0,
        level_max=25.0,
        max_ramp_rate=40.0,
        variation_amplitude=(0.5, 1.5),
        variation_freq_hz=(1.0, 2.0),
        variation_probability=0.5,
        duration_s=40.0,
        source="sec. 9.3.1 / 10.3.2 trajectory 4 (figs. 9.10, 10.11); no equation in the thesis",
        note=(
            "Designed: random levels in 0-25 deg, plateaus of 1-3 s, raised-cosine ramps of "
            "0.5-2 s capped at 40 deg/s (about the peak rate of trajectories 1-3); about half "
            "the plateaus carry +-0.5-1.5 deg variations at 1-2 Hz, like compensating a heart "
            "beat. Fixed seed."
        ),
    ),
)

_TRAINING: Final = _training_specs()
_CLSTM: Final = _clstm_specs()

PRESETS: Final[Mapping[str, SignalSpec]] = MappingProxyType(
    {s.name: s for s in (*_TRAINING, *_CLSTM, *_MODEL_TEST_SPECS, *_TRAJECTORY_SPECS)}
)
"""Every preset, by name."""

TEST_PRESSURE_SIGNALS: Final = tuple(s.name for s in _MODEL_TEST_SPECS)
"""The four modelling test signals of sec. 5.4.2, in the thesis's order."""
TEST_TRAJECTORIES: Final = tuple(s.name for s in _TRAJECTORY_SPECS)
"""The four control test trajectories of sec. 9.3 / 10.3.2, in the thesis's order."""


def get_preset(name: str) -> SignalSpec:
    """The preset called ``name``.

    Raises:
        SignalError: If there is no such preset; the message lists the valid names.
    """
    try:
        return PRESETS[name]
    except KeyError:
        valid = ", ".join(sorted(PRESETS))
        raise SignalError(f"unknown signal preset {name!r}; valid names: {valid}") from None


def training_set() -> tuple[SignalSpec, ...]:
    """The 8 DRDPI training signals (eqs. 4.1/4.2 x f in 0.2-0.8 Hz), zero baseline first."""
    return _TRAINING


def clstm_training_set() -> tuple[SignalSpec, ...]:
    """The 40 c-LSTM training pressure signals of sec. 10.3.1 (2 forms x 4 f x 5 tau)."""
    return _CLSTM


# --------------------------------------------------------------------------------------------
# Validation
# --------------------------------------------------------------------------------------------


def check_pressure_signal(values_pa: npt.ArrayLike, min_pa: float, max_pa: float) -> None:
    """Refuse a pressure signal with a non-finite or out-of-range sample.

    Args:
        values_pa: Gauge pressure samples [Pa].
        min_pa: Lowest allowed gauge pressure [Pa].
        max_pa: Highest allowed gauge pressure [Pa].

    Raises:
        SignalError: Naming the first offending sample, its value and the limit.
    """
    p = np.asarray(values_pa, dtype=np.float64).ravel()
    if p.size == 0:
        raise SignalError("pressure signal is empty; it needs at least one sample")
    if not min_pa <= max_pa:
        raise SignalError(f"pressure limits must satisfy min_pa <= max_pa, got {min_pa}, {max_pa}")
    finite = np.isfinite(p)
    bad = np.flatnonzero(~finite | (p < min_pa) | (p > max_pa))
    if bad.size == 0:
        return
    i = int(bad[0])
    value = p[i]
    if not finite[i]:
        raise SignalError(f"pressure sample {i} is {value}; every sample must be finite")
    limit_pa, side = (
        (min_pa, "below the minimum") if value < min_pa else (max_pa, "above the maximum")
    )
    raise SignalError(
        f"pressure sample {i} is {value:.6g} Pa ({pa_to_bar(value):.4g} bar), {side} "
        f"{limit_pa:.6g} Pa ({pa_to_bar(limit_pa):.4g} bar)"
    )


def check_trajectory(
    t_s: npt.ArrayLike,
    angle_rad: npt.ArrayLike,
    max_angle_rad: float,
    max_rate_rad_s: float,
    max_accel_rad_s2: float,
    *,
    min_angle_rad: float = 0.0,
) -> None:
    """Refuse a trajectory the catheter cannot or must not follow.

    Rates and accelerations are finite differences of the samples, so the limits apply to
    what a controller would be asked to do, sample by sample.

    Args:
        t_s: Sample times [s], strictly increasing.
        angle_rad: Desired bending angle [rad].
        max_angle_rad: Largest allowed angle [rad].
        max_rate_rad_s: Largest allowed |angular rate| [rad/s].
        max_accel_rad_s2: Largest allowed |angular acceleration| [rad/s^2].
        min_angle_rad: Smallest allowed angle [rad]; 0 (straight) by default.

    Raises:
        SignalError: Naming the first offending sample (index and time), its value and the
            limit: non-finite, out of range, time not increasing, too fast, or too abrupt.
    """
    t = np.asarray(t_s, dtype=np.float64).ravel()
    a = np.asarray(angle_rad, dtype=np.float64).ravel()
    if t.shape != a.shape:
        raise SignalError(
            f"trajectory t_s and angle_rad must have equal length, got {t.size} and {a.size}"
        )
    if t.size < 3:
        raise SignalError(f"a trajectory needs at least 3 samples to check rates, got {t.size}")
    for name, arr in (("t_s", t), ("angle_rad", a)):
        bad = np.flatnonzero(~np.isfinite(arr))
        if bad.size:
            i = int(bad[0])
            raise SignalError(f"trajectory {name}[{i}] is {arr[i]}; every sample must be finite")
    dt = np.diff(t)
    bad = np.flatnonzero(dt <= 0.0)
    if bad.size:
        i = int(bad[0]) + 1
        raise SignalError(
            f"trajectory time must increase strictly; t_s[{i}] = {t[i]} s follows "
            f"t_s[{i - 1}] = {t[i - 1]} s"
        )

    out_of_range = np.flatnonzero((a < min_angle_rad) | (a > max_angle_rad))
    if out_of_range.size:
        i = int(out_of_range[0])
        limit = min_angle_rad if a[i] < min_angle_rad else max_angle_rad
        raise SignalError(
            f"trajectory angle at sample {i} (t = {t[i]:.4f} s) is {rad_to_deg(a[i]):.4g} deg, "
            f"outside the allowed [{rad_to_deg(min_angle_rad):.4g}, "
            f"{rad_to_deg(max_angle_rad):.4g}] deg (limit {rad_to_deg(limit):.4g} deg)"
        )

    rate = np.diff(a) / dt
    too_fast = np.flatnonzero(np.abs(rate) > max_rate_rad_s)
    if too_fast.size:
        i = int(too_fast[0]) + 1
        raise SignalError(
            f"trajectory rate at sample {i} (t = {t[i]:.4f} s) is "
            f"{rad_to_deg(rate[i - 1]):.4g} deg/s, beyond the limit "
            f"{rad_to_deg(max_rate_rad_s):.4g} deg/s"
        )

    # Acceleration between consecutive rate estimates, which sit at the interval midpoints.
    accel = np.diff(rate) / (0.5 * (dt[1:] + dt[:-1]))
    too_abrupt = np.flatnonzero(np.abs(accel) > max_accel_rad_s2)
    if too_abrupt.size:
        i = int(too_abrupt[0]) + 1
        raise SignalError(
            f"trajectory acceleration at sample {i} (t = {t[i]:.4f} s) is "
            f"{rad_to_deg(accel[i - 1]):.4g} deg/s^2, beyond the limit "
            f"{rad_to_deg(max_accel_rad_s2):.4g} deg/s^2"
        )
