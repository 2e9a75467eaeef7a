"""``transport_delay``: the valve's dead time and the pressure wave's travel.

One effect, one file: its form, bounds, evidence, regimes, rival and plant counterpart.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from catheter_models.models.blocks.base import (
    Block,
    BlockParam,
    FloatArray,
    Inverse,
    Side,
    Step,
    _valve_sized,
)


class TransportDelay(Block):
    """Valve dead time and pressure-wave travel as a pure delay (linear interpolation)."""

    effect = "transport_delay"
    evidence_test = "input_cross"
    regimes = ("fast_motion", "loading", "unloading")
    plant_effect = "transport_delay"
    side: ClassVar[Side] = "input"
    dead_time_param = "delay_s"
    params = (BlockParam("delay_s", "s", 0.0, 0.2, 0.01, "dead time", 1e3, "ms"),)
    primary = "delay_s"
    needs = "pressure changes faster than the delay"
    # A dead time also stands in for a smooth lag after the core (a sensor's filter).
    rival = "output_lag"

    def unlike_effect(self, values: Sequence[float]) -> list[str]:
        """A delay shorter than :data:`SHORTEST_TUBE_S` is the valve's own response."""
        return _valve_sized(values[0], "delay", "valve-to-tip dead time")

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The pressure ``delay_s`` ago (the first sample before the recording began)."""
        t = np.arange(x.size) / rate_hz
        out: FloatArray = np.interp(t - values[0], t, x, left=x[0])
        return out

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The delay, one sample at a time: the first sample and the last ``delay_s`` kept."""
        lag = values[0] * rate_hz  # in samples, fractional
        recent: deque[float] = deque(maxlen=math.ceil(lag) + 2)
        first: list[float] = []
        count = [0]

        def step(x: float) -> float:
            i = count[0]
            count[0] += 1
            recent.append(x)
            if not first:
                first.append(x)
            position = i - lag
            if position <= 0.0:
                return first[0]  # before the recording began: its first sample
            lo = math.floor(position)
            frac = position - lo
            oldest = i - len(recent) + 1  # sample index of recent[0]
            y = recent[lo - oldest]
            return y if frac == 0.0 else (1.0 - frac) * y + frac * recent[lo + 1 - oldest]

        return step

    def inverse(self, rate_hz: float, values: Sequence[float]) -> Inverse:
        """A delay is undone by reading the plan ``delay_s`` ahead: nothing to compute.

        The stages behind it then run on the plan's clock ``delay_s`` ahead, which is when
        the command sent now reaches the muscle.
        """
        ahead = Inverse()
        ahead.preview_s = float(values[0])
        return ahead
