"""``drdpi``: the thesis's DRDPI as a core, with its global search and 12 parameters.

The law and its runner are the DRDPI model's own (ch. 5, :mod:`catheter_models.models.drdpi`).
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from typing import Any

import numpy as np

from catheter_models.hysteresis import operators as op
from catheter_models.models.base import ModelError
from catheter_models.models.cores.base import (
    FloatArray,
    StateStep,
    _recordings,
    _ThesisCore,
)
from catheter_models.models.drdpi import (
    DRDPI,
    DRDPIParams,
    params_to_search,
    rate_alpha,
    run_chain,
    search_to_params,
)


class DRDPICore(_ThesisCore):
    """The thesis's DRDPI (``models.drdpi``) as a core: its global search, its 12 parameters.

    Args:
        n_play, n_deadband, rate_filter_s: The DRDPI's structure.
        budget: Effort of its global search.
        seed: Seed of the search.
    """

    name = "drdpi"
    summary = "the thesis's DRDPI: exponential play weights, rate-dependent thresholds, knee"

    def __init__(
        self,
        *,
        n_play: int = 10,
        n_deadband: int = 4,
        rate_filter_s: float = 0.02,
        budget: Mapping[str, Any] | None = None,
        seed: int = 0,
    ) -> None:

        self._model = DRDPI(
            n_play=n_play,
            n_deadband=n_deadband,
            rate_filter_s=rate_filter_s,
            budget=budget,
            seed=seed,
        )
        self.n_play, self.n_deadband, self.rate_filter_s = n_play, n_deadband, rate_filter_s
        self.seed = int(seed)
        self.params: Any = None  # DRDPIParams once fitted
        self._coef: dict[float, FloatArray] = {}

    def _params_type(self) -> Any:

        return DRDPIParams

    def settings(self) -> dict[str, Any]:
        """Structure and search effort."""
        return {
            "n_play": self.n_play,
            "n_deadband": self.n_deadband,
            "rate_filter_s": self.rate_filter_s,
            "budget": self._model.budget.to_dict(),
            "seed": self.seed,
        }

    def set_params(self, params: Any) -> None:
        """Adopt DRDPI parameters (e.g. a fitted DRDPI's); the cached coefficients go."""
        self.params = params
        self._coef = {}

    def coefficients(self, theta: FloatArray, rate_hz: float) -> FloatArray:
        """The chain's coefficients for Table 5.1 parameters ``theta``."""
        coef: FloatArray = op.drdpi_coefficients(
            theta, self.n_play, self.n_deadband, rate_hz, rate_alpha(self.rate_filter_s, rate_hz)
        )
        return coef

    def _coef_at(self, rate_hz: float) -> FloatArray:
        if self.params is None:
            raise ModelError("drdpi core is not fitted")
        if rate_hz not in self._coef:
            self._coef[rate_hz] = self.coefficients(self.params.as_array(), rate_hz)
        return self._coef[rate_hz]

    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """The DRDPI's global search, then its polish."""
        recs = _recordings(xs, ys, rate_hz)
        self.set_params(self._model.fit(recs, progress=bool(kw.get("progress"))).params_)

    @staticmethod
    def _run_coef(coef: FloatArray, x: FloatArray) -> FloatArray:

        return run_chain(coef, x)

    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] from rest."""
        return self._run_coef(self._coef_at(rate_hz), x)

    def stepper(
        self, rate_hz: float, *, lagged_rate: bool = False, rate_alpha: float | None = None
    ) -> tuple[FloatArray, StateStep]:
        """The chain's state at rest, and its one-sample step (see :meth:`Core.stepper`)."""
        coef = self._coef_at(rate_hz)
        if rate_alpha is not None:
            coef = coef.copy()
            coef[op.C_RATE_ALPHA] = rate_alpha
        sample, out = np.zeros(1), np.zeros(1)
        alpha = float(coef[op.C_RATE_ALPHA])

        def advance(x: float, state: FloatArray) -> float:
            sample[0] = x
            op.chain_run(sample, coef, state, out)
            return float(out[0])

        def advance_lagged(x: float, state: FloatArray) -> float:
            # The thesis's kernel, unchanged, reads the rate it updates with this sample. A
            # previous input set so that this sample's difference is the rate already held
            # makes it read that rate; the rate's true update is put back after. (The DRDPI's
            # input stage is the identity, so the PI stage's input is the pressure.)
            previous, rate = state[op.S_PREVIOUS_INPUT], state[op.S_RATE]
            state[op.S_PREVIOUS_INPUT] = x - rate / rate_hz
            sample[0] = x
            op.chain_run(sample, coef, state, out)
            state[op.S_RATE] = rate + alpha * ((x - previous) * rate_hz - rate)
            return float(out[0])

        return np.zeros(op.chain_state_size(coef)), advance_lagged if lagged_rate else advance

    def rate_term(self, rate_hz: float) -> tuple[float, float]:
        """The thresholds' rate factor [s] the inverse sees, and the rate filter's factor.

        ``beta`` (eq. 5.6) times the plays' share of the loading slope: the input weight
        ``a0`` does not lean on the rate.
        """
        if self.params is None:
            raise ModelError("drdpi core is not fitted")
        p = self.params.to_dict()
        plays = sum(p["alpha0"] * math.exp(-p["beta0"] * i) for i in range(1, self.n_play + 1))
        share = plays / (abs(p["a0"]) + plays) if plays > 0.0 else 0.0
        return float(p["beta"]) * share, rate_alpha(self.rate_filter_s, rate_hz)

    def vector(self) -> FloatArray:
        """The free search coordinates of the DRDPI's box."""
        search = params_to_search(self.params.as_array()[None, :])[0]
        return np.asarray(search[self._model.bounds.free], dtype=float)

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """The DRDPI's search box on its free coordinates."""
        b = self._model.bounds
        return np.asarray(b.lower)[b.free], np.asarray(b.upper)[b.free]

    def _theta(self, v: FloatArray) -> FloatArray:

        search = params_to_search(self.params.as_array()[None, :])[0]
        search[self._model.bounds.free] = v
        theta: FloatArray = search_to_params(search[None, :])[0]
        return theta

    def runner(self, v: FloatArray, rate_hz: float) -> Callable[[FloatArray], FloatArray] | None:
        """The chain with search coordinates ``v``; None where it is not increasing."""
        theta = self._theta(v)
        if not float(op.drdpi_monotone_margin(theta, self.n_play, self.n_deadband)) > 0.0:
            return None
        coef = self.coefficients(theta, rate_hz)
        return lambda x: self._run_coef(coef, x)

    def set_vector(self, v: FloatArray) -> None:
        """Adopt the polished coordinates."""
        self.set_params(DRDPIParams.from_array(self._theta(v)))
