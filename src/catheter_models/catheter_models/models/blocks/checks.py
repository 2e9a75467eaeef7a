"""Forms outside the catalogue, fitted only as a catalogue block's rival, never named.

``output_lag`` rivals the pneumatic lag from the core's other side (a lag on the sensor),
``slow_fill`` rivals creep from the input side.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import ClassVar

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
    _lowpass1,
    _Lowpass1Stream,
)


class OutputLag(Block):
    """A first-order lag on the bend, after the core: not in the catalogue.

    The sensor's own filter, or a bend that follows its muscle slowly, looks like this. The
    diagnosis fits it only as the rival of :class:`PneumaticLag` and :class:`TransportDelay`
    (which side of the hysteresis the lag is on); a person may add it to a chain by hand.
    """

    effect = "output_lag"
    side: ClassVar[Side] = "output"
    stands_for = "the sensor's own filter, or a bend that follows its muscle slowly"
    params = (
        BlockParam("time_constant_s", "s", 0.002, 0.5, 0.03, "lag of bend behind core", 1e3, "ms"),
    )
    primary = "time_constant_s"
    needs = "pressure changes of a few hundred ms or faster"

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The bend [deg] through a first-order lag."""
        return _lowpass1(x, rate_hz, values[0])

    def apply_columns(
        self, m: FloatArray, rate_hz: float, values: Sequence[float], reference: FloatArray
    ) -> FloatArray:
        """A lag is linear: every column at once."""
        return _lagged_columns(m, rate_hz, (values[0],), 1.0)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The lag, one sample at a time."""
        return _Lowpass1Stream(rate_hz, values[0]).step

    def inverse(self, rate_hz: float, values: Sequence[float]) -> Inverse:
        """The bend before the lag that gives the bend wanted now (exact, causal)."""
        return LagMixInverse(rate_hz, (values[0],), 1.0)


class SlowFill(Block):
    """A share of the pressure through a slow lag, before the core: not in the catalogue.

    A second chamber behind a small orifice, or a leak, fills for seconds after the muscle
    has: the bend keeps moving on a plateau as it does under creep, but the slow share
    passes through the hysteresis (its knee and saturation) rather than following the bend.
    The diagnosis fits it only as the rival of :class:`Creep` (which side of the core the
    slow part is on); a person may add it to a chain by hand.
    """

    effect = "slow_fill"
    side: ClassVar[Side] = "input"
    stands_for = "a second chamber behind a small orifice, or a leak"
    params = (
        BlockParam(
            "fraction", "1", 0.0, 0.5, 0.1, "share of the pressure that fills slowly", 100.0, "%"
        ),
        BlockParam("time_constant_s", "s", 0.1, 30.0, 1.5, "slow share's time constant"),
    )
    primary = "fraction"
    needs = "plateaus of at least a second after pressure steps"

    def apply(self, x: FloatArray, rate_hz: float, values: Sequence[float]) -> FloatArray:
        """The pressure [bar] with ``fraction`` of it through the slow lag."""
        fraction, tau = values
        return _lagged(x, rate_hz, (tau,), fraction)

    def streamer(self, rate_hz: float, values: Sequence[float]) -> Step:
        """The slow fill, one sample at a time."""
        fraction, tau = values
        lag = _Lowpass1Stream(rate_hz, tau).step
        return lambda x: (1.0 - fraction) * x + fraction * lag(x)

    def inverse(self, rate_hz: float, values: Sequence[float]) -> Inverse:
        """The pressure whose slow share fills to the pressure wanted now (exact, causal)."""
        fraction, tau = values
        return LagMixInverse(rate_hz, (tau,), fraction)
