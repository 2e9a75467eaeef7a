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
SATURATED_SHARE: Final = 0.95
"""Where a gradual flow limit is approached only asymptotically, the inverse asks for at most
this share of it a sample: the rest would take an unbounded command."""
COMMAND_REACH_BAR: Final = 100.0
"""How far above the muscle's pressure the inverse looks for a filling command [bar]: far
past any valve's range, where the compensator's clamp takes over."""

LIMIT_SEEN_BAR_PER_S: Final = 100.0
"""A flow limit below this the fill reaches [bar/s]: a full 3 bar step in 30 ms, faster than
the valve of any rig the lab has seen (the plain lag's top, 1e3 bar/s, is no limit)."""

LagTerms = tuple[float, float, float, float, float, float, float]
"""Filling's and venting's time constants [s], their largest steps a sample [bar] at the
reference, the pressure exponent, the flow's knee and the limit's upstream share."""


@njit(cache=True)
def _speed(p: float, exponent: float) -> float:
    """How much faster than at the reference the muscle's pressure moves at gauge ``p`` [bar]."""
    if exponent == 0.0:
        return 1.0
    ratio: float = (max(p, 0.0) + AMBIENT_BAR) / (REFERENCE_GAUGE_BAR + AMBIENT_BAR)
    return math.pow(ratio, exponent)


@njit(cache=True)
def _gain_and_limit(
    p: float, x: float, rising: bool, dt_s: float, terms: LagTerms
) -> tuple[float, float]:
    """A sample's share of the error it closes and its largest step [bar].

    The share depends on the muscle's pressure ``p`` now and the direction only. The limit
    does too, and with an ``upstream_share`` it also grows with the absolute pressure
    upstream of the tube: the valve's ``x`` when filling, the muscle's when venting (a
    restriction chokes at a pressure ratio, so the most air it passes is proportional to
    the pressure pushing it).
    """
    fill_s, vent_s, fill_step, vent_step, exponent, _, upstream_share = terms
    speed = _speed(p, exponent)
    if rising:
        gain, limit = 1.0 - math.exp(-speed * dt_s / fill_s), speed * fill_step
    else:
        gain, limit = 1.0 - math.exp(-speed * dt_s / vent_s), speed * vent_step
    if upstream_share != 0.0:
        upstream: float = (max(x if rising else p, 0.0) + AMBIENT_BAR) / (
            REFERENCE_GAUGE_BAR + AMBIENT_BAR
        )
        limit *= 1.0 - upstream_share + upstream_share * upstream
    return gain, limit


@njit(cache=True)
def _saturated(step: float, limit: float, knee: float) -> float:
    """The step a flow limit lets through of the linear ``step``: at once or gradually.

    ``knee`` 0 is a hard limit; above it the step bends towards the limit as
    ``step / (1 + |step/limit| ** m) ** (1/m)`` with ``m = 1 / knee``, 1 the rational bend
    (the flow through a restriction grows ever more slowly with the pressure drop before it
    chokes).
    """
    if knee <= 0.0:
        return min(max(step, -limit), limit)
    m = 1.0 / knee
    ratio = abs(step) / limit
    if ratio <= 1.0:
        return step / math.pow(1.0 + math.pow(ratio, m), knee)
    # The same value, written so that a step far beyond the limit cannot overflow.
    return math.copysign(limit / math.pow(1.0 + math.pow(ratio, -m), knee), step)


@njit(cache=True)
def _unsaturated(step: float, limit: float, knee: float) -> float:
    """The linear step that :func:`_saturated` turns into ``step`` (or the most it can).

    A hard limit passes at most the limit; a gradual one at most :data:`SATURATED_SHARE` of
    it (the rest would take an unbounded command).
    """
    if knee <= 0.0:
        return min(max(step, -limit), limit)
    m = 1.0 / knee
    share = min(abs(step) / limit, SATURATED_SHARE)
    return math.copysign(limit * share / math.pow(1.0 - math.pow(share, m), knee), step)


@njit(cache=True)
def _lag_step(x: float, p: float, dt_s: float, terms: LagTerms) -> float:
    """The muscle's next pressure [bar] from ``p`` with the valve at ``x``."""
    err = x - p
    gain, limit = _gain_and_limit(p, x, err >= 0.0, dt_s, terms)
    return p + _saturated(err * gain, limit, terms[5])


@njit(cache=True)
def _fill_vent_kernel(x: FloatArray, dt_s: float, terms: LagTerms) -> FloatArray:
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

    A restriction does not choke at once: ``flow_knee`` above 0 bends the flow gradually from
    linear to the limit. And the most air a restriction passes grows with the pressure
    pushing it, the valve's when filling and the muscle's when venting: ``upstream_share``
    1 makes the limit proportional to that absolute pressure, so the flow saturates at a
    pressure ratio across the tube rather than at a pressure difference.

    The family is defined by these signatures, not by any one plant's flow equation. It
    stays exactly invertible a sample at a time: the speed depends on the muscle's pressure
    now and the direction, so a sample's step is monotone in the command and its inverse is
    closed-form, except where the filling limit grows with the command itself (an upstream
    share), where the inverse solves for it (:class:`_LagInverse`). ``vent_ratio`` =
    ``vent_rate_ratio`` = 1, ``max_rate_pa_per_s`` at its top (no limit a step of the full
    range reaches), ``pressure_exponent`` = ``flow_knee`` = ``upstream_share`` = 0 are the
    plain lag, the block's first form; the last two at 0 are the form before them.
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
        # The last two refine a flow limit the grid has found; a grid over them would
        # multiply every diagnosis's cost, so the polish alone moves them.
        # At most 1: a real tube's flow is laminar, linear, near equal pressures; a knee
        # beyond 1 would bend even the smallest step, and the time constant would no longer
        # be the small steps' own.
        BlockParam(
            "flow_knee",
            "1",
            0.0,
            1.0,
            0.0,
            "how gradually the flow bends from linear to its limit (0: at once; 1: as "
            "step / (1 + step / limit))",
            display_unit="x",
            absent=0.0,
            searched=False,
            plain_ends=True,
        ),
        BlockParam(
            "upstream_share",
            "1",
            0.0,
            1.0,
            0.0,
            "share of the flow limit that grows with the absolute pressure upstream of the "
            "tube (1: a restriction that chokes at a pressure ratio)",
            display_unit="x",
            absent=0.0,
            searched=False,
            plain_ends=True,
        ),
    )
    primary = "time_constant_s"
    needs = "pressure changes of a few hundred ms or faster"
    staged_search = True
    # Before a hysteresis a lag shifts each reversal; after it, it rounds the reversal's
    # corner. Both remove much of the same error, so only the better fit tells the side.
    rival = "output_lag"

    def refines(self, values: Sequence[float]) -> bool:
        """A flow limit the fill reaches: only then has its knee or its upstream share a shape.

        Without a limit in the data the two would shape nothing the fill shows, and freed they
        let the lag stand in for the core's own miss (on the simulated rig's plain 0.2 s lag
        behind a DRDPI core, the venting limit went to the end of its range).
        """
        return float(pa_to_bar(values[2])) < LIMIT_SEEN_BAR_PER_S

    def unlike_effect(self, values: Sequence[float]) -> list[str]:
        """A lag shorter than :data:`SHORTEST_TUBE_S` both ways is the valve's own response."""
        # Filling or venting slower than a valve is the tube's: the other way may be quick
        # (a supply far above the muscle's pressure fills it fast).
        return _valve_sized(max(values[0], values[0] * values[1]), "lag", "tube and muscle fill")

    @staticmethod
    def _terms(rate_hz: float, values: Sequence[float]) -> tuple[float, LagTerms]:
        """The sample period [s] and the lag's terms (:data:`LagTerms`)."""
        fill_s, vent_ratio, max_rate_pa_per_s, vent_rate_ratio, exponent, knee, upstream = values
        dt_s = 1.0 / rate_hz
        fill_step = float(pa_to_bar(max_rate_pa_per_s)) * dt_s
        vent_step = fill_step * vent_rate_ratio
        return dt_s, (fill_s, fill_s * vent_ratio, fill_step, vent_step, exponent, knee, upstream)

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The muscle's pressure [bar]: the valve's through the lag."""
        dt_s, terms = self._terms(rate_hz, values)
        fill_s, vent_s, fill_step, vent_step, exponent, knee, upstream = terms
        # A limit never reached whatever its shape: 1e3 bar/s passes a full step in 3 ms,
        # and at the reference the gradual bend takes under 1e-4 of a step that size.
        unlimited = min(fill_step, vent_step) * rate_hz >= PLAIN_LAG_RATE_BAR_PER_S
        plain = fill_s == vent_s and exponent == 0.0 and unlimited
        if plain and knee == 0.0 and upstream == 0.0:
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

    A sample's linear step ``a (u - p)`` is linear in the command ``u`` (``a`` depends on
    the muscle's pressure now and the direction, not on ``u``), and the flow limit bends it
    monotonically, so ``u = p + unsaturated(want - p) / a`` gives the pressure wanted now.
    Where the step is beyond the valve's flow limit the command asks for the limit's step
    only (the least overdrive that gets there as fast; a gradual limit's
    :data:`SATURATED_SHARE`), and the compensator's clamp bounds the rest: a step in the
    plan becomes the valve fully open for as long as filling takes, then the set-point,
    never an unbounded spike. When filling with an upstream share the limit grows with the
    command itself, so the command that reaches the pressure wanted is found by bisection
    (the clamp bounds it as well). The state follows the command
    really sent (:meth:`take`), so after a clamp the next sample asks for what is still
    missing.
    """

    fills = True

    def __init__(self, dt_s: float, terms: LagTerms) -> None:
        self._dt_s = dt_s
        self._terms = terms
        self._p: float | None = None

    def want(self, target: float) -> float:
        """The command whose step reaches ``target`` (or the flow limit's step towards it)."""
        p = self._p
        if p is None:
            return target
        rising = target >= p
        gain, limit = _gain_and_limit(p, target, rising, self._dt_s, self._terms)
        if not rising or self._terms[6] == 0.0:  # the limit does not move with the command
            return p + _unsaturated(target - p, limit, self._terms[5]) / gain
        return _command_for(p, target, gain, self._dt_s, self._terms)

    def take(self, value: float) -> float:
        """The muscle's pressure after the command ``value``."""
        if self._p is None:
            self._p = value
            return value
        self._p = _lag_step(value, self._p, self._dt_s, self._terms)
        return self._p


@njit(cache=True)
def _command_for(p: float, target: float, gain: float, dt_s: float, terms: LagTerms) -> float:
    """The filling command whose step reaches ``target`` when the limit grows with it.

    A higher command raises the limit too, so any step is reached by some command (none is
    "beyond the limit" as without an upstream share). The step grows monotonically with the
    command, so bisection finds it: never below the unlimited lag's command, the upper end
    doubling until the step reaches ``target`` or the command is :data:`COMMAND_REACH_BAR`
    beyond the muscle, far past any valve's range, where the compensator's clamp takes over.
    """
    low = p + (target - p) / gain
    span = max(target - p, 1e-9) / gain
    if _short_by(low, p, target, dt_s, terms) <= 0.0:
        return low
    high = low + span
    while _short_by(high, p, target, dt_s, terms) > 0.0:
        if high - p > COMMAND_REACH_BAR:
            return high
        span *= 2.0
        high = low + span
    for _ in range(60):
        mid = 0.5 * (low + high)
        if _short_by(mid, p, target, dt_s, terms) > 0.0:
            low = mid
        else:
            high = mid
    return high


@njit(cache=True)
def _short_by(u: float, p: float, target: float, dt_s: float, terms: LagTerms) -> float:
    """How far below ``target`` [bar] the filling command ``u`` leaves the muscle."""
    gain, limit = _gain_and_limit(p, u, True, dt_s, terms)
    return target - p - _saturated((u - p) * gain, limit, terms[5])
