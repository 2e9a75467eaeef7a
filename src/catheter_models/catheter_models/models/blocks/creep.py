"""``creep``: viscoelastic relaxation, a share of the bend that arrives late.

One effect, one file: its form, bounds, evidence, regimes, rival and plant counterpart.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import ClassVar

import numpy as np

from catheter_models.models.blocks.base import (
    Block,
    BlockParam,
    FloatArray,
    Inverse,
    LagMixInverse,
    Side,
    Step,
    _lagged,
    _lagged_columns,
    _Lowpass1Stream,
)


class Creep(Block):
    """Viscoelastic relaxation: a share of each bend change arrives through slow lags.

    A polymer relaxes over a spread of times, not at one: a step's creep is fast at first and
    still going long after. The block's two equal branches, ``spread`` apart around
    ``time_constant_s`` (their geometric mean), are the least form that has such a spread;
    ``spread`` = 1 is one lag, the block's earlier form.
    """

    effect = "creep"
    evidence_test = "autocorrelation"
    regimes = ("plateau",)
    plant_effect = "creep"
    side: ClassVar[Side] = "output"
    params = (
        BlockParam("fraction", "1", 0.0, 0.5, 0.05, "share of a step that creeps", 100.0, "%"),
        BlockParam("time_constant_s", "s", 0.1, 30.0, 1.5, "creep time constant"),
        BlockParam(
            "spread",
            "1",
            1.0,
            30.0,
            1.0,
            "slow branch's time constant over the fast one's",
            display_unit="x",
            absent=1.0,
        ),
    )
    # The share is what data pins down; the time constants are a compromise between the
    # real material's many.
    primary = "fraction"
    needs = "plateaus of at least a second after pressure steps"
    staged_search = True
    rival = "slow_fill"

    @staticmethod
    def _branches(values: Sequence[float]) -> tuple[float, float, float]:
        fraction, tau, spread = values
        root = math.sqrt(spread)
        return fraction, tau / root, tau * root

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The bend [deg] with ``fraction`` of every change delayed by the two slow lags."""
        fraction, fast, slow = self._branches(values)
        return _lagged(x, rate_hz, (fast, slow), fraction)

    def apply_columns(
        self, m: FloatArray, rate_hz: float, values: Sequence[float], reference: FloatArray
    ) -> FloatArray:
        """Creep is linear: every column at once."""
        fraction, fast, slow = self._branches(values)
        return _lagged_columns(m, rate_hz, (fast, slow), fraction)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """Creep, one sample at a time."""
        fraction, fast, slow = self._branches(values)
        lag_fast = _Lowpass1Stream(rate_hz, fast).step
        lag_slow = _Lowpass1Stream(rate_hz, slow).step
        return lambda x: (1.0 - fraction) * x + fraction * 0.5 * (lag_fast(x) + lag_slow(x))

    def inverse(self, rate_hz: float, values: Sequence[float]) -> Inverse:
        """The core's bend that, with its creep, is the bend wanted now (exact, causal)."""
        fraction, fast, slow = self._branches(values)
        return LagMixInverse(rate_hz, (fast, slow), fraction)

    def excitation_problem(self, inputs: Sequence[FloatArray], rate_hz: float) -> str:
        """Creep shows only where the pressure holds still after a change."""
        # A plateau: the pressure holds within 2 % of full scale for 1 s after moving.
        window = max(2, round(rate_hz))
        for x in inputs:
            if x.size <= window:
                continue
            spread = np.lib.stride_tricks.sliding_window_view(x, window)
            flat = (spread.max(axis=1) - spread.min(axis=1)) < 0.06
            if flat.any() and float(np.ptp(x)) > 0.5:
                return ""
        return "no plateau of 1 s or longer after a pressure change: creep cannot show"
