"""``free_pi``: plays on a grid of thresholds and opening pressures, with free weights.

See :mod:`catheter_models.models.cores` for the law and where it sits in the chain.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from typing import Any, Final

import numpy as np
from numba import njit

from catheter_models.errors import ParameterError
from catheter_models.hysteresis.operators import play_step
from catheter_models.models.base import ModelError
from catheter_models.models.cores.base import (
    TENSION_REF_BAR,
    TENSION_SCALE_MAX,
    Core,
    FloatArray,
    StateStep,
    _alpha,
)

# The play grid and tension search every free-weight core starts from (free_pi, viscous_pi).
MAX_OFFSET_BAR: Final = 2.6
N_OFFSETS: Final = 14
THRESHOLDS_BAR: Final = (0.0, 0.03, 0.07, 0.12, 0.2, 0.3, 0.45, 0.65)
TENSION_SHARES: Final = (0.0, 0.5, 0.8, 0.95)
TENSION_ONSETS_BAR: Final = (0.0, 0.4, 0.8)
RIDGE: Final = 1e-6


@njit(cache=True)
def _free_pi_kernel(  # noqa: PLR0917 - numba compiles positional arguments only
    x: FloatArray,
    offsets: FloatArray,
    thresholds: FloatArray,
    beta_s: float,
    alpha: float,
    rate_hz: float,
    tension_share: float,
    tension_onset_bar: float,
    state: FloatArray,
    weights: FloatArray,
    features: FloatArray,
    out: FloatArray,
) -> None:  # pragma: no cover - compiled; exercised through FreePI
    """Plays on ``max(x - d_j, 0)`` with thresholds ``r_i g(x) + beta |rate_j|``.

    ``g(x) = 1 - share + share * min((x - onset)⁺ / (TENSION_REF_BAR - onset), TENSION_SCALE_MAX)``.

    ``state`` = (previous s_j, rate_j, started flag, plays j*I+i); ``features`` (n, J*I) is
    filled when it has rows, ``out`` (n,) with ``weights @ features + weights[-1]`` when
    ``weights`` is non-empty.
    """
    n_off = offsets.size
    n_thr = thresholds.size
    plays = 2 * n_off + 1
    keep = features.shape[0] > 0
    total = weights.size > 0
    for k in range(x.size):
        acc = 0.0
        tension = min(
            max(x[k] - tension_onset_bar, 0.0) / (TENSION_REF_BAR - tension_onset_bar),
            TENSION_SCALE_MAX,
        )
        scale = 1.0 - tension_share + tension_share * tension
        for j in range(n_off):
            s = x[k] - offsets[j]
            s = max(s, 0.0)
            if state[2 * n_off] == 0.0:
                state[j] = s
            rate = state[n_off + j] + alpha * ((s - state[j]) * rate_hz - state[n_off + j])
            state[j] = s
            state[n_off + j] = rate
            speed = abs(rate)
            for i in range(n_thr):
                at = plays + j * n_thr + i
                th = thresholds[i] * scale + beta_s * speed
                v = play_step(s, th, state[at])
                state[at] = v
                if keep:
                    features[k, j * n_thr + i] = v
                if total:
                    acc += weights[j * n_thr + i] * v
        state[2 * n_off] = 1.0
        if total:
            out[k] = acc + weights[n_off * n_thr]


class FreePI(Core):
    """Plays on a grid of thresholds and opening pressures with free weights (see module).

    Args:
        max_pressure_bar: Highest opening pressure of the grid [bar].
        n_offsets: Opening pressures from 0 to ``max_pressure_bar``.
        thresholds_bar: Play thresholds [bar] (0 is the plain shifted ramp).
        betas_s: Rate factors tried [s]; the best on training data is kept.
        tension_shares: Shares γ of the thresholds that grow with the pressure (the
            capstan effect; 0: fixed thresholds).
        tension_onsets_bar: Pressures p_0 above which the thresholds grow [bar] (below
            :data:`TENSION_REF_BAR`); with the shares, searched at the rate factor that is
            best with fixed thresholds, then the rate factor again.
        ridge: Tikhonov weight relative to the design's mean square (keeps weights of
            columns the data barely excites small).
    """

    name = "free_pi"
    summary = (
        "Prandtl-Ishlinskii plays with free weights on a grid of thresholds and opening "
        "pressures (knee, loop shape, saturation and asymmetry learnt; friction that grows "
        "with the wire's tension)"
    )
    linear = True

    def __init__(
        self,
        *,
        max_pressure_bar: float = MAX_OFFSET_BAR,
        n_offsets: int = N_OFFSETS,
        thresholds_bar: Sequence[float] = THRESHOLDS_BAR,
        betas_s: Sequence[float] = (0.0, 0.01, 0.02, 0.035, 0.05, 0.08),
        tension_shares: Sequence[float] = TENSION_SHARES,
        tension_onsets_bar: Sequence[float] = TENSION_ONSETS_BAR,
        ridge: float = RIDGE,
    ) -> None:
        if not (max_pressure_bar > 0.0 and 2 <= n_offsets <= 60):
            raise ParameterError("free_pi needs max_pressure_bar > 0 and 2-60 offsets")
        if not thresholds_bar or min(thresholds_bar) < 0.0:
            raise ParameterError("free_pi thresholds_bar must be a non-empty list of values >= 0")
        if not betas_s or min(betas_s) < 0.0:
            raise ParameterError("free_pi betas_s must be a non-empty list of values >= 0 [s]")
        if not tension_shares or not all(0.0 <= g <= 1.0 for g in tension_shares):
            raise ParameterError(
                "free_pi tension_shares must be a non-empty list of values in [0, 1]"
            )
        if not tension_onsets_bar or not all(
            0.0 <= p < TENSION_REF_BAR for p in tension_onsets_bar
        ):
            raise ParameterError(
                "free_pi tension_onsets_bar must be a non-empty list of pressures in "
                f"[0, {TENSION_REF_BAR}) bar"
            )
        self.max_pressure_bar = float(max_pressure_bar)
        self.n_offsets = int(n_offsets)
        self.thresholds_bar = tuple(float(r) for r in thresholds_bar)
        self.betas_s = tuple(float(b) for b in betas_s)
        self.tension_shares = tuple(float(g) for g in tension_shares)
        self.tension_onsets_bar = tuple(float(p) for p in tension_onsets_bar)
        self.ridge = float(ridge)
        self._offsets = np.linspace(0.0, self.max_pressure_bar, self.n_offsets)
        self._thresholds = np.asarray(self.thresholds_bar, dtype=float)
        self.beta_s: float | None = None
        self.tension_share = 0.0
        """γ of the fitted core; a design before the fit uses it too (0: fixed thresholds)."""
        self.tension_onset_bar = 0.0
        """p_0 of the fitted core [bar]."""
        self.weights: FloatArray | None = None

    def settings(self) -> dict[str, Any]:
        """The grid, and the rate factors and tension shares tried."""
        return {
            "max_pressure_bar": self.max_pressure_bar,
            "n_offsets": self.n_offsets,
            "thresholds_bar": list(self.thresholds_bar),
            "betas_s": list(self.betas_s),
            "tension_shares": list(self.tension_shares),
            "tension_onsets_bar": list(self.tension_onsets_bar),
            "ridge": self.ridge,
        }

    @property
    def n_columns(self) -> int:
        """Columns of the design: one per play, plus the constant."""
        return self.n_offsets * len(self.thresholds_bar) + 1

    def _state(self) -> FloatArray:
        return np.zeros(2 * self.n_offsets + 1 + self.n_offsets * len(self.thresholds_bar))

    def design(self, x: FloatArray, rate_hz: float, beta_s: float) -> FloatArray:
        """The design matrix (n, columns): every play's output and a constant.

        The plays' thresholds grow with the pressure by the core's :attr:`tension_share`
        above its :attr:`tension_onset_bar`.
        """
        x = np.ascontiguousarray(x, dtype=np.float64)
        features = np.empty((x.size, self.n_columns))
        features[:, -1] = 1.0
        _free_pi_kernel(
            x,
            *self._kernel_args(rate_hz, beta_s),
            self._state(),
            np.empty(0),
            features[:, :-1],
            np.empty(0),
        )
        return features

    def _kernel_args(
        self, rate_hz: float, beta_s: float
    ) -> tuple[FloatArray, FloatArray, float, float, float, float, float]:
        """The kernel's structure arguments, between the input and the state."""
        return (
            self._offsets,
            self._thresholds,
            beta_s,
            _alpha(rate_hz),
            rate_hz,
            self.tension_share,
            self.tension_onset_bar,
        )

    def beta_coordinate(self, beta_s: float, rate_hz: float) -> float:
        """The coordinate a polish moves the structure number in (here ``beta_s`` itself).

        A threshold's rate term is linear in ``beta_s``, so it acts from 0 on.
        """
        del rate_hz
        return beta_s

    def beta_from_coordinate(self, coordinate: float, rate_hz: float) -> float:
        """:meth:`beta_coordinate`'s inverse [s]."""
        del rate_hz
        return coordinate

    @property
    def fitted(self) -> bool:
        """Whether weights have been solved."""
        return self.weights is not None

    def solve(
        self, designs: Sequence[FloatArray], ys: Sequence[FloatArray]
    ) -> tuple[FloatArray, float]:
        """Ridge least squares over recordings (each weighted by 1/sqrt(length)).

        Returns:
            (weights, loss) with loss the sum over recordings of the mean squared error.
        """
        gram = np.zeros((designs[0].shape[1],) * 2)
        rhs = np.zeros(designs[0].shape[1])
        for a, y in zip(designs, ys, strict=True):
            gram += a.T @ a / y.size
            rhs += a.T @ y / y.size
        scale = float(np.trace(gram)) / gram.shape[0]
        gram[np.diag_indices_from(gram)] += self.ridge * scale
        try:
            w = np.asarray(np.linalg.solve(gram, rhs), dtype=np.float64)
        except np.linalg.LinAlgError:
            w = np.asarray(np.linalg.lstsq(gram, rhs, rcond=None)[0], dtype=np.float64)
        loss = float(sum(np.mean((a @ w - y) ** 2) for a, y in zip(designs, ys, strict=True)))
        return w, loss

    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """The rate factor, tension share and onset on their grids; weights by least squares.

        A coordinate search (about 20 solves; the full grid takes 60): the rate factor with
        fixed thresholds, then share and onset at that rate factor, then the rate factor
        again at the best share and onset.
        """
        fits: dict[tuple[float, float, float], tuple[float, FloatArray]] = {}

        def score(beta: float, share: float, onset: float) -> float:
            key = (beta, share, onset) if share > 0.0 else (beta, 0.0, 0.0)
            if key not in fits:
                self.tension_share, self.tension_onset_bar = key[1], key[2]
                w, loss = self.solve([self.design(x, rate_hz, beta) for x in xs], ys)
                fits[key] = (loss, w)
            return fits[key][0]

        beta = min(self.betas_s, key=lambda b: score(b, 0.0, 0.0))
        share, onset = min(
            ((g, p) for g in self.tension_shares for p in self.tension_onsets_bar),
            key=lambda gp: score(beta, *gp),
        )
        beta = min(self.betas_s, key=lambda b: score(b, share, onset))
        if share == 0.0:
            onset = 0.0
        self.beta_s, self.tension_share, self.tension_onset_bar = beta, share, onset
        self.weights = fits[(beta, share, onset)][1]

    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] from rest."""
        if self.weights is None or self.beta_s is None:
            raise ModelError("free_pi core is not fitted")
        x = np.ascontiguousarray(x, dtype=np.float64)
        out = np.empty(x.size)
        _free_pi_kernel(
            x,
            *self._kernel_args(rate_hz, self.beta_s),
            self._state(),
            self.weights,
            np.empty((0, 0)),
            out,
        )
        return out

    def stepper(
        self, rate_hz: float, *, lagged_rate: bool = False, rate_alpha: float | None = None
    ) -> tuple[FloatArray, StateStep]:
        """The plays' state at rest, and the kernel's one-sample step (:meth:`Core.stepper`)."""
        if self.weights is None or self.beta_s is None:
            raise ModelError("free_pi core is not fitted")
        sample, out = np.zeros(1), np.zeros(1)
        args = self._kernel_args(rate_hz, self.beta_s)
        if rate_alpha is not None:
            args = (*args[:3], rate_alpha, *args[4:])
        weights, empty = self.weights, np.empty((0, 0))
        offsets, n_off, alpha = self._offsets, self.n_offsets, args[3]

        def advance(x: float, state: FloatArray) -> float:
            sample[0] = x
            _free_pi_kernel(sample, *args, state, weights, empty, out)
            return float(out[0])

        def advance_lagged(x: float, state: FloatArray) -> float:
            if state[2 * n_off] == 0.0:  # the first sample: no rate yet either way
                return advance(x, state)
            # As the DRDPI core's: previous inputs set so the kernel reads the rates held,
            # their true update put back after.
            s = np.maximum(x - offsets, 0.0)
            previous, rates = state[:n_off].copy(), state[n_off : 2 * n_off].copy()
            state[:n_off] = s - rates / rate_hz
            y = advance(x, state)
            state[n_off : 2 * n_off] = rates + alpha * ((s - previous) * rate_hz - rates)
            return y

        return self._state(), advance_lagged if lagged_rate else advance

    def rate_term(self, rate_hz: float) -> tuple[float, float]:
        """The thresholds' rate factor [s] and the rate filter's factor."""
        return float(self.beta_s or 0.0), _alpha(rate_hz)

    def values(self) -> dict[str, Any]:
        """Rate factor, tension share and weights (the last weight is the constant)."""
        if self.weights is None:
            raise ModelError("free_pi core is not fitted")
        return {
            "beta_s": self.beta_s,
            "tension_share": self.tension_share,
            "tension_onset_bar": self.tension_onset_bar,
            "weights": [float(w) for w in self.weights],
        }

    def load_values(self, values: Mapping[str, Any]) -> None:
        """Weights and rate factor from a model file."""
        try:
            weights = np.asarray(values["weights"], dtype=float)
            beta = float(values["beta_s"])
            # Files written before the thresholds could grow with the pressure: fixed ones.
            share = float(values.get("tension_share", 0.0))
            onset = float(values.get("tension_onset_bar", 0.0))
        except (KeyError, TypeError, ValueError) as exc:
            raise ModelError(f"free_pi core values are malformed: {exc}") from None
        if weights.shape != (self.n_columns,) or not np.all(np.isfinite(weights)):
            raise ModelError(
                f"free_pi core needs {self.n_columns} finite weights, got {weights.shape}"
            )
        if not (math.isfinite(beta) and beta >= 0.0):
            raise ModelError(f"free_pi beta_s = {beta!r} must be >= 0")
        if not 0.0 <= share <= 1.0:
            raise ModelError(f"free_pi tension_share = {share!r} must be in [0, 1]")
        if not 0.0 <= onset < TENSION_REF_BAR:
            raise ModelError(
                f"free_pi tension_onset_bar = {onset!r} must be in [0, {TENSION_REF_BAR}) bar"
            )
        self.weights, self.beta_s = weights, beta
        self.tension_share, self.tension_onset_bar = share, onset
