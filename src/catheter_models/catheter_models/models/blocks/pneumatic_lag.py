"""``pneumatic_lag``: filling the tube and muscle, a lag on pressure limited by the valve's flow.

One effect, one file: its form, bounds, evidence, regimes, rival and plant counterpart.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar, Final

import numpy as np
from numba import njit

from catheter_models.models.blocks.base import (
    PLAIN_LAG_RATE_BAR_PER_S,
    Block,
    BlockParam,
    FloatArray,
    Inverse,
    Side,
    Step,
    _lowpass1,
    _valve_sized,
)
from catheter_models.units import AMBIENT_PRESSURE_PA, pa_to_bar

REFERENCE_GAUGE_BAR: Final = 1.5
"""Gauge pressure at which the time constants and flow limits hold [bar] (rigs quote 1.5 bar)."""
AMBIENT_BAR: Final = float(pa_to_bar(AMBIENT_PRESSURE_PA))
"""The atmosphere the gauge pressures are measured against [bar] (a float: numba freezes it)."""


@njit(cache=True)
def _speed(p: float, exponent: float) -> float:
    """How much faster than at the reference the muscle's pressure moves at gauge ``p`` [bar]."""
    if exponent == 0.0:
        return 1.0
    ratio: float = (max(p, 0.0) + AMBIENT_BAR) / (REFERENCE_GAUGE_BAR + AMBIENT_BAR)
    return math.pow(ratio, exponent)


@njit(cache=True)
def _gain_and_limit(
    p: float, rising: bool, dt_s: float, terms: tuple[float, float, float, float, float]
) -> tuple[float, float]:
    """A sample's share of the error it closes and its largest step [bar], from ``p``.

    Both depend on the muscle's pressure now and the direction only, never on this sample's
    command, so a sample's step is linear in the command below the limit: the inverse is
    exact (:class:`_LagInverse`).
    """
    fill_s, vent_s, fill_step, vent_step, exponent = terms
    speed = _speed(p, exponent)
    if rising:
        return 1.0 - math.exp(-speed * dt_s / fill_s), speed * fill_step
    return 1.0 - math.exp(-speed * dt_s / vent_s), speed * vent_step


@njit(cache=True)
def _lag_step(
    x: float, p: float, dt_s: float, terms: tuple[float, float, float, float, float]
) -> float:
    """The muscle's next pressure [bar] from ``p`` with the valve at ``x``."""
    err = x - p
    gain, limit = _gain_and_limit(p, err >= 0.0, dt_s, terms)
    return p + min(max(err * gain, -limit), limit)


@njit(cache=True)
def _fill_vent_kernel(
    x: FloatArray, dt_s: float, terms: tuple[float, float, float, float, float]
) -> FloatArray:
    """The lag over a signal, from rest at its first sample."""
    out = np.empty_like(x)
    p = x[0]
    for k in range(x.size):
        p = _lag_step(x[k], p, dt_s, terms)
        out[k] = p
    return out


class PneumaticLag(Block):
    """Filling the tube and muscle: a family of lags on pressure, by the signature they leave.

    Air fills the muscle through an orifice: near the set-point the flow is about linear in
    the pressure difference (a first-order lag), far from it the flow saturates and the
    pressure can rise no faster than the valve passes air (a slew limit). Venting to the
    atmosphere runs through another port and another pressure difference, so it has its own
    time and its own limit. Gas is denser at a higher absolute pressure, and a muscle's
    volume changes as it pulls, so how quickly it all happens depends on the pressure:
    a power law in the absolute pressure, ``pressure_exponent`` (0: none; ideal gas through
    a laminar restriction is near 1; a muscle whose volume grows as it fills, below 0).

    The family is defined by these signatures, not by any one plant's flow equation: the
    speed depends on the muscle's pressure now and the direction, never on the command, so
    that the lag stays exactly invertible a sample at a time. ``vent_ratio`` =
    ``vent_rate_ratio`` = 1, ``max_rate_pa_per_s`` at its top (no limit a step of the full
    range reaches) and ``pressure_exponent`` = 0 are the plain lag, the block's first form.
    """

    effect = "pneumatic_lag"
    evidence_test = "rate_cross"
    regimes = ("fast_motion", "loading", "unloading")
    plant_effect = "pneumatic_lag"
    side: ClassVar[Side] = "input"
    dead_time_param = "time_constant_s"
    params = (
        BlockParam(
            "time_constant_s",
            "s",
            0.002,
            0.5,
            0.03,
            "lag of muscle behind valve (filling)",
            1e3,
            "ms",
        ),
        BlockParam(
            "vent_ratio",
            "1",
            1.0 / 3.0,
            3.0,
            1.0,
            "venting time constant over filling's",
            display_unit="x",
            grid_points=3,
            absent=1.0,
        ),
        BlockParam(
            "max_rate_pa_per_s",
            "Pa/s",
            2e5,
            1e8,
            1e8,
            "fastest the valve's flow moves the muscle's pressure (top: no limit)",
            1e-5,
            "bar/s",
            grid_points=4,
            absent=1e8,
        ),
        BlockParam(
            "vent_rate_ratio",
            "1",
            0.25,
            4.0,
            1.0,
            "venting's flow limit over filling's",
            display_unit="x",
            grid_points=3,
            absent=1.0,
        ),
        BlockParam(
            "pressure_exponent",
            "1",
            -1.0,
            2.0,
            0.0,
            "how much faster the muscle fills and vents at a higher absolute pressure "
            "(speed ~ p_abs ** exponent)",
            grid_points=3,
            absent=0.0,
        ),
    )
    primary = "time_constant_s"
    needs = "pressure changes of a few hundred ms or faster"
    staged_search = True
    # Before a hysteresis a lag shifts each reversal; after it, it rounds the reversal's
    # corner. Both remove much of the same error, so only the better fit tells the side.
    rival = "output_lag"

    def unlike_effect(self, values: Sequence[float]) -> list[str]:
        """A lag shorter than :data:`SHORTEST_TUBE_S` both ways is the valve's own response."""
        # Filling or venting slower than a valve is the tube's: the other way may be quick
        # (a supply far above the muscle's pressure fills it fast).
        return _valve_sized(max(values[0], values[0] * values[1]), "lag", "tube and muscle fill")

    @staticmethod
    def _terms(
        rate_hz: float, values: Sequence[float]
    ) -> tuple[float, tuple[float, float, float, float, float]]:
        """The sample period [s] and the lag's terms at the reference pressure.

        The terms: filling's and venting's time constants [s], their largest steps a sample
        [bar], and the pressure exponent.
        """
        fill_s, vent_ratio, max_rate_pa_per_s, vent_rate_ratio, exponent = values
        dt_s = 1.0 / rate_hz
        fill_step = float(pa_to_bar(max_rate_pa_per_s)) * dt_s
        return dt_s, (fill_s, fill_s * vent_ratio, fill_step, fill_step * vent_rate_ratio, exponent)

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The muscle's pressure [bar]: the valve's through the lag."""
        dt_s, terms = self._terms(rate_hz, values)
        fill_s, vent_s, fill_step, vent_step, exponent = terms
        unlimited = min(fill_step, vent_step) * rate_hz >= PLAIN_LAG_RATE_BAR_PER_S
        if fill_s == vent_s and exponent == 0.0 and unlimited:
            return _lowpass1(x, rate_hz, fill_s)  # the plain lag: exact and vectorised
        return _fill_vent_kernel(np.ascontiguousarray(x, dtype=float), dt_s, terms)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The lag, one sample at a time."""
        dt_s, terms = self._terms(rate_hz, values)
        state: list[float] = []

        def step(x: float) -> float:
            if not state:
                state.append(x)
                return x
            state[0] = _lag_step(x, state[0], dt_s, terms)
            return state[0]

        return step

    def inverse(self, rate_hz: float, values: Sequence[float]) -> Inverse:
        """The valve command that fills (or vents) the muscle to the pressure wanted."""
        return _LagInverse(*self._terms(rate_hz, values))


class _LagInverse(Inverse):
    """:meth:`PneumaticLag.streamer` backwards: exact, one sample a tick, no preview.

    A sample's step ``a (u - p)`` is linear in the command ``u`` (``a`` and the flow limit
    depend on the muscle's pressure now and the direction, not on ``u``), so
    ``u = p + (want - p) / a`` gives the pressure wanted now. Where that step is beyond the
    valve's flow limit the command asks for the limit's step only (the least overdrive that
    gets there as fast), and the compensator's clamp bounds the rest: a step in the plan
    becomes the valve fully open for as long as filling takes, then the set-point, never an
    unbounded spike. The state follows the command really sent (:meth:`take`), so after a
    clamp the next sample asks for what is still missing.
    """

    fills = True

    def __init__(self, dt_s: float, terms: tuple[float, float, float, float, float]) -> None:
        self._dt_s = dt_s
        self._terms = terms
        self._p: float | None = None

    def want(self, target: float) -> float:
        """The command whose step reaches ``target`` (or the flow limit's step towards it)."""
        p = self._p
        if p is None:
            return target
        gain, limit = _gain_and_limit(p, target >= p, self._dt_s, self._terms)
        return p + min(max(target - p, -limit), limit) / gain

    def take(self, value: float) -> float:
        """The muscle's pressure after the command ``value``."""
        if self._p is None:
            self._p = value
            return value
        self._p = _lag_step(value, self._p, self._dt_s, self._terms)
        return self._p
