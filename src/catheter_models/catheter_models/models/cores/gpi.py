"""``gpi``: the thesis's Generalized Prandtl-Ishlinskii as a core, rate-independent.

The law is the GPI model's own (ch. 9, :mod:`catheter_models.models.gpi`).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

import numpy as np

from catheter_models.errors import ParameterError
from catheter_models.hysteresis import gpi_kernels
from catheter_models.models.base import ModelError
from catheter_models.models.cores.base import (
    FloatArray,
    StateStep,
    _recordings,
    _ThesisCore,
)
from catheter_models.models.gpi import GPI, GPIParams, gpi_coefficients, run_gpi


class GPICore(_ThesisCore):
    """The thesis's GPI (``models.gpi``): a tanh envelope, exponentially weighted plays.

    Rate-independent: the thesis fits one per frequency; as a core it is fitted on all the
    data at once, so it shows how much of the error is the rate dependence it lacks.
    """

    name = "gpi"
    summary = "the thesis's GPI: tanh envelope, exponential play density, rate-independent"

    def __init__(self, *, n_play: int = 10, seed: int = 0) -> None:
        self.n_play, self.seed = int(n_play), int(seed)
        self.params: Any = None

    def _params_type(self) -> Any:

        return GPIParams

    def settings(self) -> dict[str, Any]:
        """Structure and seed of the search."""
        return {"n_play": self.n_play, "seed": self.seed}

    def _coef(self, params: Any) -> FloatArray:

        coef: FloatArray = gpi_coefficients(params, self.n_play)
        return coef

    def fit(
        self, xs: Sequence[FloatArray], ys: Sequence[FloatArray], rate_hz: float, **kw: Any
    ) -> None:
        """The GPI's own identification on all recordings together."""
        recs = _recordings(xs, ys, rate_hz)
        model = GPI(
            n_play=self.n_play, seed=self.seed, budget={"max_generations": 40, "wall_time_s": 20.0}
        )
        self.params = model.fit(recs, progress=bool(kw.get("progress"))).params_

    def run(self, x: FloatArray, rate_hz: float) -> FloatArray:
        """Bend [deg] from rest."""
        if self.params is None:
            raise ModelError("gpi core is not fitted")
        return run_gpi(self._coef(self.params), x)

    def stepper(
        self, rate_hz: float, *, lagged_rate: bool = False, rate_alpha: float | None = None
    ) -> tuple[FloatArray, StateStep]:
        """The GPI's state at rest, and its one-sample step (rate-independent: no lag)."""
        if self.params is None:
            raise ModelError("gpi core is not fitted")
        coef = self._coef(self.params)
        sample, out = np.zeros(1), np.zeros(1)

        def advance(x: float, state: FloatArray) -> float:
            sample[0] = x
            gpi_kernels.gpi_run(sample, coef, state, out)
            return float(out[0])

        return gpi_kernels.gpi_rest_state(coef), advance

    def vector(self) -> FloatArray:
        """Table 9.1's parameters."""
        return np.asarray(self.params.as_array(), dtype=float)

    def bounds(self) -> tuple[FloatArray, FloatArray]:
        """Each parameter within a factor of its value's neighbourhood (a local polish)."""
        v = self.vector()
        span = np.maximum(np.abs(v), 0.1)
        low, high = v - 2.0 * span, v + 2.0 * span
        # c0, c1, beta, q stay positive (the GPI's validity).
        for i in (0, 1, 4, 7):
            low[i] = max(low[i], 1e-3)
        low[5] = max(low[5], 0.0)
        return low, high

    def runner(self, v: FloatArray, rate_hz: float) -> Callable[[FloatArray], FloatArray] | None:
        """The GPI with parameters ``v``; None if they are not valid."""
        try:
            coef = self._coef(GPIParams.from_array(v))
        except (ParameterError, ValueError):
            return None
        return lambda x: run_gpi(coef, x)

    def set_vector(self, v: FloatArray) -> None:
        """Adopt ``v``."""
        self.params = GPIParams.from_array(v)
