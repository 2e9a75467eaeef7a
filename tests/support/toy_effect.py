"""A toy effect, written as a user would add one: one class in one file, registered.

A latency of the bend's reading (the laser's, or its filter's), after the core: a plain dead
time on the output side. The simulated plant has no such effect (``plant_effect`` is '').
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from catheter_models.models.blocks import Block, BlockParam, Side, Step

TOY = "sensor_latency_toy"


class SensorLatency(Block):
    """The bend is read late: a dead time after the core."""

    effect = TOY
    side: ClassVar[Side] = "output"
    params = (BlockParam("delay_s", "s", 0.0, 0.2, 0.02, "latency of the reading", 1e3, "ms", 51),)
    primary = "delay_s"
    needs = "bends that change faster than the latency"
    evidence_test = "input_cross"
    regimes = ("fast_motion", "loading", "unloading")

    def apply(self, x: np.ndarray, rate_hz: float, values: Sequence[float]) -> np.ndarray:
        """The bend [deg] ``delay_s`` later, from rest (0 before the first sample arrives)."""
        n = min(round(values[0] * rate_hz), x.size)
        return np.concatenate([np.zeros(n), x[: x.size - n]])

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The same, one sample at a time."""
        n = round(values[0] * rate_hz)
        line: deque[float] = deque([0.0] * n)

        def step(x: float) -> float:
            line.append(x)
            return line.popleft()

        return step
