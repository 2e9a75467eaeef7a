"""``viscous_pi``: rate-independent plays with free weights, and one explicit viscous term.

The loops are learnt as ``free_pi``'s are: plays on a grid of thresholds and opening
pressures with free weights, thresholds that grow with the wire's tension (so minor loops at
different pressures differ: non-congruent loops, with the wiping-out property of a Preisach
law). But no threshold depends on how fast the pressure moves. The one thing that does is a
named term: the bend follows the plays' output through a first-order viscous lag of
``viscous_s``, a damper in parallel with the bending section's stiffness (loops that widen
with frequency, as a Bouc-Wen law with a viscous term has them), bounded by
:data:`MOST_VISCOUS_S`.

Why a core that can do less: a law whose thresholds widen with the pressure's rate is late
the way a tube's lag is, and it takes up part of a lag, a delay, a creep or a ringing tip
before any block is tried, so the block that would name the effect finds less to remove.
This law is rate-independent by construction but for a damper too quick to pass for any of
those (tubes lag 20-120 ms, dead times are 20-60 ms, creep takes seconds, a tip rings at a
few Hz). Fitted on the three foreign laws with nothing hidden (development seed 5), it
matches the rate-dependent ``free_pi`` held out: 0.082 against 0.085 deg (Maxwell-slip),
0.161 against 0.168 deg (Bouc-Wen), 0.193 against 0.193 deg (Duhem).
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Final

import numpy as np

from catheter_models.errors import ParameterError
from catheter_models.models.base import ModelError
from catheter_models.models.blocks.base import _lagged_columns, _lowpass1, _pole
from catheter_models.models.cores.base import TENSION_REF_BAR, FloatArray, StateStep
from catheter_models.models.cores.free_pi import (
    MAX_OFFSET_BAR,
    N_OFFSETS,
    RIDGE,
    TENSION_ONSETS_BAR,
    TENSION_SHARES,
    THRESHOLDS_BAR,
    FreePI,
    _free_pi_kernel,
)

MOST_VISCOUS_S: Final = 0.02
"""Longest viscous time constant the law may have [s]: a bending section's damping (the
foreign plants' dampers fit at 8-17 ms), half the shortest tube lag a rig shows (about
40 ms with the valve's), so that a lag of the tube stays a block's to find."""


class ViscousPI(FreePI):
    """Rate-independent free-weight plays and an explicit viscous lag (see module).

    Args:
        max_pressure_bar: Highest opening pressure of the grid [bar].
        n_offsets: Opening pressures from 0 to ``max_pressure_bar``.
        thresholds_bar: Play thresholds [bar] (0 is the plain shifted ramp).
        viscous_s: Viscous time constants tried [s], each in ``[0, MOST_VISCOUS_S]``; the
            best on training data is kept and polished within that range with the blocks.
        tension_shares: Shares of the thresholds that grow with the pressure.
        tension_onsets_bar: Pressures above which the thresholds grow [bar].
        ridge: Tikhonov weight relative to the design's mean square.

    The fitter's one free structure number (``beta_s`` of :class:`FreePI`, which the grey
    box's variable projection searches and polishes) is here the viscous time constant; the
    model file names it ``viscous_s``.
    """

    name = "viscous_pi"
    summary = (
        "free-weight plays whose thresholds never depend on the pressure's rate (loops "
        "learnt, non-congruent with the wire's tension), and one explicit viscous lag of at "
        f"most {MOST_VISCOUS_S * 1e3:.0f} ms: it cannot take up a lag, a delay, creep or a tip"
    )

    def __init__(
        self,
        *,
        max_pressure_bar: float = MAX_OFFSET_BAR,
        n_offsets: int = N_OFFSETS,
        thresholds_bar: Sequence[float] = THRESHOLDS_BAR,
        viscous_s: Sequence[float] = (0.0, 0.004, 0.008, 0.012, 0.016, 0.02),
        tension_shares: Sequence[float] = TENSION_SHARES,
        tension_onsets_bar: Sequence[float] = TENSION_ONSETS_BAR,
        ridge: float = RIDGE,
    ) -> None:
        if not viscous_s or not all(0.0 <= v <= MOST_VISCOUS_S for v in viscous_s):
            raise ParameterError(
                f"viscous_pi viscous_s must be a non-empty list of values in "
                f"[0, {MOST_VISCOUS_S}] s"
            )
        super().__init__(
            max_pressure_bar=max_pressure_bar,
            n_offsets=n_offsets,
            thresholds_bar=thresholds_bar,
            betas_s=viscous_s,
            tension_shares=tension_shares,
            tension_onsets_bar=tension_onsets_bar,
            ridge=ridge,
        )

    def settings(self) -> dict[str, Any]:
        """The grid, and the viscous time constants and tension shares tried."""
        out = super().settings()
        out["viscous_s"] = out.pop("betas_s")
        return out

    def design(self, x: FloatArray, rate_hz: float, beta_s: float) -> FloatArray:
        """The plays' design with no rate in their thresholds, through the viscous lag.

        ``beta_s`` is the viscous time constant [s] (the fitter's structure number). The lag
        is linear, so lagging every column is lagging the weighted sum; it starts at rest on
        the first sample, as :meth:`run` does, and leaves the constant column 1.
        """
        features = super().design(x, rate_hz, 0.0)
        if beta_s <= 0.0:
            return features
        return _lagged_columns(features, rate_hz, (beta_s,), 1.0)

    def beta_coordinate(self, beta_s: float, rate_hz: float) -> float:
        """The viscous lag's discrete pole ``exp(-1 / (rate * tau))``, which a polish moves.

        The exact discretisation is flat in the time constant below about a fifth of a
        sample (every derivative of the pole vanishes at 0), so a polish started at no
        viscosity could never leave it: with the Bouc-Wen plant's pneumatic lag
        (development seed 5) it stayed there at 0.40 deg on training data (0.49 held out),
        where the pole, on which each step of the lag depends linearly, leads it to 11 ms
        and 0.12 deg (0.23 held out).
        """
        return _pole(rate_hz, beta_s) if beta_s > 0.0 else 0.0

    def beta_from_coordinate(self, coordinate: float, rate_hz: float) -> float:
        """:meth:`beta_coordinate`'s inverse [s] (0 for a pole at or below 0)."""
        if coordinate <= 0.0:
            return 0.0
        return min(-1.0 / (rate_hz * math.log(min(coordinate, 1.0 - 1e-12))), MOST_VISCOUS_S)

    def _checked(self) -> tuple[FloatArray, float]:
        if self.weights is None or self.beta_s is None:
            raise ModelError("viscous_pi core is not fitted")
        return self.weights, self.beta_s

    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] from rest."""
        weights, viscous_s = self._checked()
        x = np.ascontiguousarray(x, dtype=np.float64)
        out = np.empty(x.size)
        args = self._kernel_args(rate_hz, 0.0)
        _free_pi_kernel(x, *args, self._state(), weights, np.empty((0, 0)), out)
        return _lowpass1(out, rate_hz, viscous_s) if viscous_s > 0.0 else out

    def stepper(
        self, rate_hz: float, *, lagged_rate: bool = False, rate_alpha: float | None = None
    ) -> tuple[FloatArray, StateStep]:
        """The plays' and the lag's state at rest, and the one-sample step.

        No threshold reads a rate, so ``lagged_rate`` and ``rate_alpha`` change nothing: the
        bend's next sample rises with this sample's pressure as it is.
        """
        weights, viscous_s = self._checked()
        args = self._kernel_args(rate_hz, 0.0)
        n_plays = self._state().size
        pole = math.exp(-1.0 / (rate_hz * viscous_s)) if viscous_s > 0.0 else 0.0
        sample, out, empty = np.zeros(1), np.zeros(1), np.empty((0, 0))

        def advance(x: float, state: FloatArray) -> float:
            sample[0] = x
            _free_pi_kernel(sample, *args, state[:n_plays], weights, empty, out)
            if state[n_plays + 1] == 0.0:  # the first sample: the lag starts at rest there
                state[n_plays], state[n_plays + 1] = out[0], 1.0
            else:
                state[n_plays] = pole * state[n_plays] + (1.0 - pole) * out[0]
            return float(state[n_plays])

        # The plays' state, then the lag's output and its started flag.
        return np.zeros(n_plays + 2), advance

    def rate_term(self, rate_hz: float) -> tuple[float, float]:
        """No threshold leans on the pressure's rate (the viscous lag inverts exactly)."""
        return 0.0, 1.0

    def values(self) -> dict[str, Any]:
        """Viscous time constant, tension share and onset, and weights (the last: constant)."""
        weights, viscous_s = self._checked()
        return {
            "viscous_s": viscous_s,
            "tension_share": self.tension_share,
            "tension_onset_bar": self.tension_onset_bar,
            "weights": [float(w) for w in weights],
        }

    def load_values(self, values: Mapping[str, Any]) -> None:
        """Weights, viscous time constant and tension from a model file."""
        try:
            weights = np.asarray(values["weights"], dtype=float)
            viscous_s = float(values["viscous_s"])
            share = float(values["tension_share"])
            onset = float(values["tension_onset_bar"])
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"viscous_pi core values are malformed: {exc}") from None
        if weights.shape != (self.n_columns,) or not np.all(np.isfinite(weights)):
            raise ModelError(
                f"viscous_pi core needs {self.n_columns} finite weights, got {weights.shape}"
            )
        if not 0.0 <= viscous_s <= MOST_VISCOUS_S:
            raise ModelError(
                f"viscous_pi viscous_s = {viscous_s!r} must be in [0, {MOST_VISCOUS_S}] s"
            )
        if not (0.0 <= share <= 1.0 and 0.0 <= onset < TENSION_REF_BAR):
            raise ModelError(
                f"viscous_pi tension_share = {share!r} must be in [0, 1] and tension_onset_bar "
                f"= {onset!r} in [0, {TENSION_REF_BAR}) bar"
            )
        self.weights, self.beta_s = weights, viscous_s
        self.tension_share, self.tension_onset_bar = share, onset
