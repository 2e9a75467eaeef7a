"""``pneumatic_lag``: filling the tube and muscle, a lag on pressure limited by the valve's flow.

One effect, one file: its form, bounds, evidence, regimes, rival and plant counterpart.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

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
from catheter_models.units import pa_to_bar


@njit(cache=True)
def _fill_vent_kernel(
    x: FloatArray, dt_s: float, fill_s: float, vent_s: float, max_step: float
) -> FloatArray:
    """A first-order lag that vents at its own rate and moves at most ``max_step`` a sample."""
    out = np.empty_like(x)
    p = x[0]
    a_fill = 1.0 - math.exp(-dt_s / fill_s)
    a_vent = 1.0 - math.exp(-dt_s / vent_s)
    for k in range(x.size):
        err = x[k] - p
        dp = err * a_fill if err >= 0.0 else err * a_vent
        dp = min(max(dp, -max_step), max_step)
        p += dp
        out[k] = p
    return out


class PneumaticLag(Block):
    """Filling the tube and muscle: a first-order lag on pressure, limited by the valve's flow.

    Air fills the muscle through an orifice: near the set-point the flow is about linear in
    the pressure difference (a first-order lag), far from it the flow chokes and the pressure
    can rise no faster than the valve passes air (a slew limit); venting to the atmosphere
    runs through another pressure difference than filling from the supply, so it has its own
    time. ``vent_ratio`` = 1 and ``max_rate_pa_per_s`` at its top (no limit a step of the
    full range reaches) are the plain lag, the block's earlier form.
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
    def _terms(rate_hz: float, values: Sequence[float]) -> tuple[float, float, float, float]:
        """(dt [s], fill and vent time constants [s], largest step a sample [bar])."""
        fill_s, vent_ratio, max_rate_pa_per_s = values
        dt_s = 1.0 / rate_hz
        return dt_s, fill_s, fill_s * vent_ratio, float(pa_to_bar(max_rate_pa_per_s)) * dt_s

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The muscle's pressure [bar]: the valve's through the lag."""
        dt_s, fill_s, vent_s, max_step = self._terms(rate_hz, values)
        if fill_s == vent_s and max_step * rate_hz >= PLAIN_LAG_RATE_BAR_PER_S:
            return _lowpass1(x, rate_hz, fill_s)  # the plain lag: exact and vectorised
        contiguous = np.ascontiguousarray(x, dtype=float)
        return _fill_vent_kernel(contiguous, dt_s, fill_s, vent_s, max_step)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The lag, one sample at a time."""
        dt_s, fill_s, vent_s, max_step = self._terms(rate_hz, values)
        a_fill = 1.0 - math.exp(-dt_s / fill_s)
        a_vent = 1.0 - math.exp(-dt_s / vent_s)
        state: list[float] = []

        def step(x: float) -> float:
            if not state:
                state.append(x)
                return x
            err = x - state[0]
            dp = err * a_fill if err >= 0.0 else err * a_vent
            state[0] += min(max(dp, -max_step), max_step)
            return state[0]

        return step

    def inverse(self, rate_hz: float, values: Sequence[float]) -> Inverse:
        """The valve command that fills (or vents) the muscle to the pressure wanted."""
        return _LagInverse(*self._terms(rate_hz, values))


class _LagInverse(Inverse):
    """:meth:`PneumaticLag.streamer` backwards: exact, one sample a tick, no preview.

    A sample's step ``a (u - p)`` is linear in the command ``u``, so ``u = p + (want - p) / a``
    gives the pressure wanted now. Where that step is beyond the valve's flow limit the
    command asks for the limit's step only (the least overdrive that gets there as fast),
    and the compensator's clamp bounds the rest: a step in the plan becomes the valve fully
    open for as long as filling takes, then the set-point, never an unbounded spike. The
    state follows the command really sent (:meth:`take`), so after a clamp the next sample
    asks for what is still missing.
    """

    fills = True

    def __init__(self, dt_s: float, fill_s: float, vent_s: float, max_step: float) -> None:
        self._a_fill = 1.0 - math.exp(-dt_s / fill_s)
        self._a_vent = 1.0 - math.exp(-dt_s / vent_s)
        self._max_step = max_step
        self._p: float | None = None

    def want(self, target: float) -> float:
        """The command whose step reaches ``target`` (or the flow limit's step towards it)."""
        p = self._p
        if p is None:
            return target
        step = min(max(target - p, -self._max_step), self._max_step)
        return p + step / (self._a_fill if step >= 0.0 else self._a_vent)

    def take(self, value: float) -> float:
        """The muscle's pressure after the command ``value``."""
        if self._p is None:
            self._p = value
            return value
        err = value - self._p
        dp = err * self._a_fill if err >= 0.0 else err * self._a_vent
        self._p += min(max(dp, -self._max_step), self._max_step)
        return self._p
