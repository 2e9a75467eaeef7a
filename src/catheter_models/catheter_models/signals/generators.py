"""The thesis's signal equations and the designed plateau signal, as plain functions of time.

Unit-agnostic: each returns values in the unit of its amplitude or levels, so the same code
makes a pressure in bar and an angle in degrees. Kept apart from the preset classes
(:mod:`.specs`) because the equations are what a reader checks against the thesis line by
line, and they need nothing but numpy.
"""

from __future__ import annotations

import math

import numpy as np
import numpy.typing as npt

from catheter_models.errors import SignalError

FloatArray = npt.NDArray[np.float64]


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
